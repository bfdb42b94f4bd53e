"""Header stamps read without decoding a message: a frame index over a session of large
images and depth maps needs every message's stamp, and decoding a 1 MB image for it costs
milliseconds where stepping over its protobuf fields by their tags costs microseconds.
The stamp is the top-level `timestamp` (google.protobuf.Timestamp) field, whose number
comes from the file's own schema descriptors."""

from __future__ import annotations

from google.protobuf.descriptor_pb2 import FileDescriptorSet
from mcap.records import Message, Schema

from . import schemas as S


def timestamp_field_number(schema: Schema) -> int | None:
    """The field number of the top-level `timestamp` (google.protobuf.Timestamp) of the
    schema's message, from the file's own descriptors; None where there is none."""
    try:
        files = FileDescriptorSet.FromString(schema.data).file
    except Exception:  # noqa: BLE001 - the decoder reports damaged schemas
        return None
    package, _, name = schema.name.rpartition(".")
    for fd in files:
        for msg in fd.message_type if fd.package == package else ():
            if msg.name == name:
                for fld in msg.field:
                    if fld.name == "timestamp" and fld.type_name.lstrip(".") == "google.protobuf.Timestamp" and fld.label != fld.LABEL_REPEATED:
                        return fld.number
    return None


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        b = data[i]  # IndexError past the end: malformed
        i += 1
        value |= (b & 0x7F) << shift
        if b < 0x80:
            return value, i
        shift += 7
        if shift > 63:
            raise ValueError("varint longer than 10 bytes")


def _skip(data: bytes, i: int, wire: int) -> int:
    if wire == 0:
        return _varint(data, i)[1]
    if wire == 1:
        return i + 8
    if wire == 5:
        return i + 4
    if wire == 2:
        length, i = _varint(data, i)
        return i + length
    raise ValueError(f"protobuf wire type {wire}")


def scan_stamp(data: bytes, number: int) -> tuple[bool, int]:
    """(present, ns) of the Timestamp field `number` of a protobuf message, stepping over
    the other fields by their tags and lengths (a 1 MB image costs a few steps). Protobuf
    semantics: occurrences of a message field merge, the last value of a scalar wins.
    ValueError / IndexError on malformed bytes."""
    seconds = nanos = 0
    found = False
    i, n = 0, len(data)
    while i < n:
        key, i = _varint(data, i)
        if key >> 3 == 0:
            raise ValueError("protobuf field number 0")
        if key >> 3 == number and key & 7 == 2:
            length, i = _varint(data, i)
            end, found = i + length, True
            while i < end:
                k, i = _varint(data, i)
                if k in (8, 16):  # seconds (1) / nanos (2), varints
                    v, i = _varint(data, i)
                    seconds, nanos = (v, nanos) if k == 8 else (seconds, v)
                else:
                    i = _skip(data, i, k & 7)
            if i != end:
                raise ValueError("timestamp overruns its length")
        else:
            i = _skip(data, i, key & 7)
    if i != n:
        raise ValueError("message overruns its bytes")
    seconds = seconds - (1 << 64) if seconds >= 1 << 63 else seconds  # int64
    nanos &= 0xFFFFFFFF
    nanos = nanos - (1 << 32) if nanos >= 1 << 31 else nanos  # int32
    return found, seconds * 1_000_000_000 + nanos


def stamp_without_decoding(topic: str, stamp_field: int | None, record: Message) -> int | None:
    """A message's stamp as decoding it gives it (decoding.decode), read without decoding
    the message (stamp_field: timestamp_field_number of its schema); None where the bytes
    do not scan (the decoder then says what is wrong)."""
    if topic == S.TOPIC_STATUS:
        return record.log_time  # JSON status has no header stamp
    if stamp_field is None:
        return None
    try:
        found, ns = scan_stamp(record.data, stamp_field)
    except (ValueError, IndexError):
        return None
    return ns if found and ns > 0 else record.log_time
