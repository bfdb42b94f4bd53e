"""Decoding a session file's messages: one decoder per session topic from the file's own
schemas (protobuf via mcap-protobuf-support; the JSON status), the stamp of each message
(its header `timestamp`, else its log time), and what an undecodable message costs: the
file, or (ground truth, logged outputs not being read) only that message, noted. `faults`
is the reading Session: its fail() raises or, salvaging, notes; its problems list."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass

from mcap.records import Channel as McapChannel
from mcap.records import Message, Schema
from mcap_protobuf.decoder import DecoderFactory

from ...errors import SessionLogError
from . import schemas as S
from .stamps import stamp_without_decoding, timestamp_field_number

EXPECTED_SCHEMAS = {
    S.TOPIC_IMAGE: ("foxglove.RawImage", "foxglove.CompressedImage"),
    S.TOPIC_DEPTH: "foxglove.RawImage",
    S.TOPIC_LABELS: "foxglove.RawImage",
    S.TOPIC_CALIBRATION: "foxglove.CameraCalibration",
    S.TOPIC_SCAN: "foxglove.LaserScan",
    S.TOPIC_ODOMETRY: "foxglove.PoseInFrame",
    S.TOPIC_GROUND_TRUTH: "foxglove.PoseInFrame",
    S.TOPIC_POSE: "foxglove.PoseInFrame",
    S.TOPIC_HYPOTHESES: "foxglove.PosesInFrame",
    S.TOPIC_BEV: "foxglove.Grid",
    S.TOPIC_STATUS: S.STATUS_SCHEMA_NAME,
}

OUTPUT_TOPICS = frozenset(S.OUTPUT_TOPICS)


@dataclass
class Channel:
    topic: str
    decode: object  # bytes -> message
    metadata: dict
    stamp_field: int | None = None  # protobuf field number of `timestamp` (read without decoding)


@dataclass
class Ref:
    """A message by its place in the file (chunk ordinal, ordinal among the chunk's
    messages); `msg` is the decoded message, None where only its stamp was read."""

    where: tuple[int, int]
    msg: object | None

    @property
    def pose(self):  # the grouper reads odometry poses
        return self.msg.pose


def messages(faults, records: Iterable, stamp_only: Iterable[str] = ()) -> Iterator[tuple[str, int, object, dict]]:
    """(topic, stamp_ns, decoded message, channel metadata) of the session topics, from
    records in file order; messages of `stamp_only` topics are not decoded (None)."""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel | None] = {}
    factory = DecoderFactory()
    for record in records:
        if isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, McapChannel):
            if record.id not in channels:
                channels[record.id] = make_channel(faults, record, schemas, factory)
        elif isinstance(record, Message):
            got = channel_message(faults, channels, record, stamp_only)
            if got is not None:
                ch, stamp, msg = got
                yield ch.topic, stamp, msg, ch.metadata


def channel_message(faults, channels: dict, record: Message, stamp_only) -> tuple[Channel, int, object | None] | None:
    """(channel, stamp, message) of a message on a session topic; None for topics this
    package does not read, unknown channels (a fault) and undecodable messages."""
    ch = channels.get(record.channel_id)
    if ch is None:
        if record.channel_id not in channels:
            faults.fail(f"message on unknown channel {record.channel_id}")
        return None
    got = decode(faults, ch, record, ch.topic in stamp_only)
    return None if got is None else (ch, got[0], got[1])


def decode(faults, ch: Channel, record: Message, stamp_only: bool) -> tuple[int, object | None] | None:
    """(stamp, message) of a message record; the message is None with stamp_only (only
    its header stamp is read, where its bytes allow); None when it cannot be decoded."""
    if stamp_only:
        stamp = stamp_without_decoding(ch.topic, ch.stamp_field, record)
        if stamp is not None and stamp < S.MAX_NS:
            return stamp, None
    try:
        msg = ch.decode(record.data)
        stamp = record.log_time  # JSON status has no header stamp
        if ch.topic != S.TOPIC_STATUS and msg.HasField("timestamp") and S.from_stamp(msg.timestamp) > 0:
            stamp = S.from_stamp(msg.timestamp)
        if stamp >= S.MAX_NS:  # numpy's int64 stamps (and the year 2262) end there
            raise SessionLogError(f"its time {stamp} ns is beyond 2^63 ns (the year 2262)")
    except SessionLogError as err:
        fail_message(faults, ch, record, stamp_only, str(err))
        return None
    except Exception as err:  # noqa: BLE001 - protobuf on damaged bytes
        fail_message(faults, ch, record, stamp_only, f"cannot be decoded ({type(err).__name__})")
        return None
    return stamp, None if stamp_only else msg


def fail_message(faults, ch: Channel, record: Message, stamp_only: bool, why: str) -> None:
    """An undecodable message refuses the file, unless localizing does not need its
    topic (ground truth; logged outputs when they are not being read): then it is
    skipped and noted (the run warns once per cause)."""
    if ch.topic == S.TOPIC_GROUND_TRUTH or (stamp_only and ch.topic in OUTPUT_TOPICS):
        faults.problems.append(f"{ch.topic} message skipped: {why}; localizing does not need it (log time {record.log_time})")
        return
    faults.fail(f"{ch.topic} message at log time {record.log_time}: {why}")


def make_channel(faults, channel: McapChannel, schemas: dict, factory: DecoderFactory) -> Channel | None:
    """A decoder for a session topic; None for topics this package does not read."""
    expected = EXPECTED_SCHEMAS.get(channel.topic)
    if expected is None:
        return None
    schema = schemas.get(channel.schema_id)
    name = None if schema is None else schema.name
    allowed = expected if isinstance(expected, tuple) else (expected,)
    if name not in allowed:
        faults.fail(f"topic {channel.topic} has schema {name!r}, expected {' or '.join(map(repr, allowed))}")
        return None
    if channel.topic == S.TOPIC_STATUS:
        if channel.message_encoding != "json":
            faults.fail(f"topic {channel.topic} has message encoding {channel.message_encoding!r}, expected 'json'")
            return None
        return Channel(channel.topic, S.decode_status, dict(channel.metadata))
    try:
        decoder = factory.decoder_for(channel.message_encoding, schema)
    except Exception as err:  # noqa: BLE001 - a damaged schema record
        faults.fail(f"schema {name} of topic {channel.topic} cannot be loaded ({type(err).__name__}: {err})")
        return None
    if decoder is None:
        faults.fail(f"topic {channel.topic} is not protobuf-encoded (message encoding {channel.message_encoding!r})")
        return None
    return Channel(channel.topic, decoder, dict(channel.metadata), timestamp_field_number(schema))
