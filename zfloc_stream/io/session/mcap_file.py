"""Opening a session file: the checks before reading (exists, MCAP magic, footer, input
topics), metadata and attachments through the summary or, salvaging, by a scan, and the
records of the whole file in order, chunks broken up, where faults raise or (salvage) end
the scan, skip a damaged chunk or a zeroed region."""

from __future__ import annotations

import io
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from mcap.reader import SeekingReader
from mcap.records import Attachment, Chunk, Footer, Metadata
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.summary import Summary

from ...errors import SessionLogError
from . import schemas as S

MAGIC = b"\x89MCAP0\r\n"


@dataclass
class Zeroed:
    """A record with opcode 0x00, which MCAP reserves as invalid: bytes overwritten with
    zeros (9 zero bytes parse as an empty record, so a zeroed region reads as a run of them)."""

    length: int


class DamageAwareReader(StreamReader):
    """StreamReader that reports opcode-0 records instead of skipping them as unknown."""

    def _read_record(self, opcode: int, length: int):
        if opcode == 0:
            self._stream.read(length)
            return Zeroed(length)
        return super()._read_record(opcode, length)


def file_records(path: Path, salvage: bool, problems: list[str], see=None) -> Iterator:
    """Records in file order, chunks broken up (each shown to `see` first). Faults raise
    (or, salvaging, end the scan at a damaged record and skip a damaged chunk or a zeroed
    region)."""
    size = path.stat().st_size
    zeroed_from = None  # start of the zeroed region being skipped (salvage)
    with open(path, "rb") as f:
        reader = DamageAwareReader(f, emit_chunks=True, validate_crcs=True, record_size_limit=size)
        records = reader.records
        while True:
            offset = f.tell()
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception as err:  # noqa: BLE001 - any parser fault on damaged bytes
                what = describe_fault(err, offset, size)
                if not salvage:
                    raise SessionLogError(f"{path}: {what}") from None
                problems.append(f"reading stopped: {what}")
                return
            if isinstance(record, Zeroed):
                if not salvage:
                    raise SessionLogError(f"{path}: damaged file: zeroed bytes at byte {offset} (a region overwritten with zeros); "
                                          "read around it with --salvage")
                zeroed_from = offset if zeroed_from is None else zeroed_from
                continue
            if zeroed_from is not None:
                problems.append(f"damaged file: zeroed bytes at bytes {zeroed_from}-{offset - 1} skipped (a region overwritten with zeros)")
                zeroed_from = None
            if isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except Exception as err:  # noqa: BLE001
                    what = f"damaged chunk near byte {offset} ({type(err).__name__}: {err})"
                    if not salvage:
                        raise SessionLogError(f"{path}: {what}") from None
                    problems.append(f"chunk skipped: {what}")
                    continue
                for r in inner:
                    if see is not None:
                        see(r)
                    yield r
            else:
                if see is not None:
                    see(record)
                yield record
            if isinstance(record, Footer):
                return


def describe_fault(err: Exception, offset: int, size: int) -> str:
    name = type(err).__name__
    if name == "EndOfFile" or "unpack requires" in str(err):
        if offset >= size:
            return f"file is truncated (it ends at byte {size} without an MCAP footer: a recording cut off?)"
        return f"file is truncated (it ends inside a record that starts at byte {offset} of {size})"
    if name == "InvalidMagic":
        return "not an MCAP file (bad magic bytes)"
    return f"damaged record near byte {offset} ({name}: {err})"


def check_path(path: Path) -> None:
    if not path.exists():
        raise SessionLogError(f"session file not found: {path}")
    if not path.is_file():
        raise SessionLogError(f"session path is not a file: {path}")
    try:
        with open(path, "rb") as f:
            head = f.read(len(MAGIC))
    except OSError as err:
        raise SessionLogError(f"cannot read session file {path}: {err.strerror or err}") from None
    if head != MAGIC:
        raise SessionLogError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")


def open_indexed(path: Path) -> tuple[dict, dict, Summary | None]:
    """Metadata, attachments and summary of a complete file, through its summary."""
    try:
        with open(path, "rb") as f:
            f.seek(-len(MAGIC), io.SEEK_END)
            if f.read(len(MAGIC)) != MAGIC:
                raise SessionLogError(
                    f"{path}: file is truncated (no MCAP footer at its end; a crashed recording?): "
                    "read what it holds with --salvage / read_session(..., salvage=True)"
                )
            f.seek(0)
            reader = SeekingReader(f, validate_crcs=True, record_size_limit=path.stat().st_size)
            summary = reader.get_summary()
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            attachments = {a.name: a.data for a in reader.iter_attachments()}
    except SessionLogError:
        raise
    except Exception as err:  # noqa: BLE001 - damaged footer / summary / index
        raise SessionLogError(
            f"{path}: damaged MCAP summary or index ({type(err).__name__}: {err}); try --salvage".replace("\n", " ")
        ) from None
    return metadata, attachments, summary


def open_salvaged(path: Path) -> tuple[dict, dict, Summary | None]:
    """Metadata and attachments found by a scan of top-level records, and the summary
    where the file's end survived (its chunk index then reaches the chunks after a
    damaged one, and its channels those whose definitions the damage took)."""
    metadata, attachments = open_scanning(path)
    summary = None
    try:
        with open(path, "rb") as f:
            reader = SeekingReader(f, validate_crcs=True, record_size_limit=path.stat().st_size)
            summary = reader.get_summary()
            if summary is not None:
                size = path.stat().st_size
                summary.chunk_indexes = [c for c in summary.chunk_indexes if 0 < c.chunk_start_offset < size]
                for m in reader.iter_metadata():
                    metadata.setdefault(m.name, dict(m.metadata))
    except Exception:  # noqa: BLE001 - no usable summary: the scan is all there is
        pass
    if summary is not None and not summary.chunk_indexes:
        summary = None
    return metadata, attachments, summary


def open_scanning(path: Path) -> tuple[dict, dict]:
    """Metadata and attachments found by a scan of top-level records (salvage)."""
    metadata: dict = {}
    attachments: dict = {}
    size = path.stat().st_size
    with open(path, "rb") as f:
        records = DamageAwareReader(f, emit_chunks=True, validate_crcs=True, record_size_limit=size).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except Exception:  # noqa: BLE001 - the frames pass reports where it stops
                break
            if isinstance(record, Metadata):
                metadata[record.name] = dict(record.metadata)
            elif isinstance(record, Attachment):
                attachments[record.name] = record.data
            elif isinstance(record, Footer):
                break
    return metadata, attachments


def check_topics(path: Path, topics: set[str]) -> None:
    if not topics & {S.TOPIC_DEPTH, S.TOPIC_IMAGE, S.TOPIC_SCAN}:
        raise SessionLogError(f"{path}: no input frames: none of {S.TOPIC_DEPTH}, {S.TOPIC_IMAGE}, {S.TOPIC_SCAN} is in the file")
    if S.TOPIC_ODOMETRY not in topics:
        raise SessionLogError(f"{path}: topic {S.TOPIC_ODOMETRY} is missing (every frame needs its relative pose)")
    if topics & {S.TOPIC_DEPTH, S.TOPIC_IMAGE} and S.TOPIC_CALIBRATION not in topics:
        raise SessionLogError(f"{path}: topic {S.TOPIC_CALIBRATION} is missing (camera frames need intrinsics)")
