"""A session file's messages in log-time order, through its chunk index.

MCAP does not require a file to hold its messages in time order: another tool may write
them grouped by topic, or in any order. Frames are grouped as messages arrive
(frame_grouping.py), so a file read in file order could lose nearly every frame; read here
in log-time order (ties in file order), a file already in order reads exactly as in file
order. Chunks are opened when the merge reaches their first log time and released once
their last message is handed on, so a file in order holds one chunk at a time and one
grouped by topic one per topic; a file whose chunks all overlap in time would hold them
all, so the bytes held at once are bounded beforehand (`logging.reorder_max_mb`).

Files without a chunk index (and salvaged files without a readable summary) can only be
read in file order: `OrderWatch` notes once where their log times run backwards.
"""

from __future__ import annotations

import heapq
from collections.abc import Iterator
from pathlib import Path

from mcap.records import Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap_protobuf.decoder import DecoderFactory

from ...settings.loading import Settings
from ...errors import SessionLogError
from .decoding import Channel, channel_message, make_channel

MIB = 1 << 20


def has_chunk_index(summary) -> bool:
    """Whether a file's summary lets it be read through its chunk index (in log-time
    order, messages counted against its statistics)."""
    return summary is not None and bool(summary.chunk_indexes) and summary.statistics is not None


def chunk_indexes(summary) -> list:
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)  # file order


def summary_channels(session) -> dict[int, Channel | None]:
    """The decoders of the file's channels, from its summary (shared with fresh() copies)."""
    if "channels" not in session.shared:
        factory = DecoderFactory()
        session.shared["channels"] = {
            cid: make_channel(session, ch, session.summary.schemas, factory) for cid, ch in sorted(session.summary.channels.items())
        }
    return session.shared["channels"]


class ZeroedChunk(SessionLogError):
    """Where the index puts a chunk, bytes overwritten with zeros (`zeros` of them)."""

    def __init__(self, message: str, zeros: int):
        super().__init__(message)
        self.zeros = zeros


def chunk_messages(path, f, chunk) -> list[Message]:
    """The messages of one chunk (found by its index), in their order in the chunk."""
    zeros = zeroed_run(f, chunk.chunk_start_offset, 9 + chunk.chunk_length)
    if zeros:
        raise ZeroedChunk(f"{path}: damaged file: zeroed bytes at byte {chunk.chunk_start_offset} (a region overwritten "
                          f"with zeros, {zeros} bytes where the index puts a chunk); read around it with --salvage", zeros)
    try:
        f.seek(chunk.chunk_start_offset)
        record = next(StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=Path(path).stat().st_size).records)
        if not isinstance(record, Chunk):
            raise ValueError(f"a {type(record).__name__} record where the index puts a chunk")
        return [r for r in breakup_chunk(record, validate_crc=True) if isinstance(r, Message)]
    except Exception as err:  # noqa: BLE001 - any parser fault on damaged bytes
        what = f"{type(err).__name__}: {err}".replace("\n", " ")
        raise SessionLogError(f"{path}: damaged chunk at byte {chunk.chunk_start_offset} ({what}); try --salvage") from None


def zeroed_run(f, offset: int, length: int) -> int:
    """Zero bytes from offset on (within length) where the record's opcode is 0 (reserved:
    bytes overwritten with zeros); 0 where it is not."""
    if not 0 <= offset < 1 << 62 or length < 0:
        return 0  # a damaged index: the read itself reports it
    f.seek(offset)
    if f.read(1) != b"\0":  # (one byte read: a sound chunk costs nothing more)
        return 0
    f.seek(offset)
    data = f.read(min(length, 1 << 30))
    return len(data) - len(data.lstrip(b"\0"))


def held_at_once(chunks) -> int:
    """Most uncompressed chunk bytes a log-time merge holds at once: a chunk is held from
    its first log time to its last (an upper bound: its messages leave one by one)."""
    events = sorted([(c.message_start_time, 0, c.uncompressed_size) for c in chunks]
                    + [(c.message_end_time, 1, -c.uncompressed_size) for c in chunks])
    held = peak = 0
    for _, _, size in events:  # at equal times chunks open before others close
        held += size
        peak = max(peak, held)
    return peak


def check_budget(session, chunks) -> None:
    """Refuse, before reading, a merge that would hold more than the budget."""
    limit = reorder_limit_mb(session)
    need = held_at_once(chunks)
    if need > limit * MIB:
        raise SessionLogError(
            f"{session.path}: its messages are far out of log-time order: reading them in order holds "
            f"{need / MIB:.0f} MiB of chunks at once, over the limit of {limit} MiB (logging.reorder_max_mb; "
            "raise it, or rewrite the file in log-time order, e.g. `mcap sort`)"
        )


def reorder_limit_mb(session) -> int:
    settings = session.read_settings or session.settings or Settings()
    return int(settings.logging.reorder_max_mb)


def ordered_messages(session, f, counted: list[int] | None = None) -> Iterator[tuple[tuple[int, int], Message]]:
    """((chunk ordinal, position in chunk), message) of every chunk, in log-time order (ties
    in file order). Salvaging, a damaged chunk is skipped and noted; else it raises."""
    chunks = chunk_indexes(session.summary)
    check_budget(session, chunks)
    heap: list = [(c.message_start_time, c.chunk_start_offset, -1, k) for k, c in enumerate(chunks)]
    heapq.heapify(heap)  # a chunk opens before its own first message (position -1)
    while heap:
        _, offset, pos, item = heapq.heappop(heap)
        if pos >= 0:
            yield (item[0], pos), item[1]
            continue
        try:
            inner = chunk_messages(session.path, f, chunks[item])
        except SessionLogError as err:
            if not session.salvage:
                raise
            zeros = err.zeros if isinstance(err, ZeroedChunk) else 0
            start = chunks[item].chunk_start_offset
            session.problems.append(f"damaged file: zeroed bytes at bytes {start}-{start + zeros - 1} skipped (a region overwritten "
                                    "with zeros)" if zeros else
                                    f"chunk skipped: {str(err).removeprefix(f'{session.path}: ').removesuffix('; try --salvage')}")
            continue
        if counted is not None:
            counted[0] += len(inner)
        for p, record in enumerate(inner):
            heapq.heappush(heap, (record.log_time, offset, p, (item, record)))


def ordered_channel_messages(session, f, stamp_only, counted: list[int] | None = None) -> Iterator[tuple]:
    """(place, Channel, stamp, message) of the session topics' messages, decoded
    (decoding.channel_message) in ordered_messages' order."""
    channels = summary_channels(session)
    for where, record in ordered_messages(session, f, counted):
        got = channel_message(session, channels, record, stamp_only)
        if got is not None:
            yield where, *got


class OrderWatch:
    """Notes once where a file read in file order has log times running backwards (its
    frames may then be dropped: there is no chunk index to read it in order)."""

    def __init__(self, problems: list[str], why: str):
        self.problems = problems
        self.why = why
        self.latest = -1
        self.noted = False

    def see(self, record) -> None:
        if self.noted or not isinstance(record, Message):
            return
        if record.log_time < self.latest:
            self.problems.append(
                f"messages are not in log-time order (log time {record.log_time} after {self.latest}) and {self.why}: "
                "they are read in file order, so frames may be dropped"
            )
            self.noted = True
        self.latest = max(self.latest, record.log_time)
