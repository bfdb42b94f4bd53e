"""The frame index of a session file: per frame, where each of its messages lies (chunk,
position), found by the same grouping as a sequential read but without decoding images,
depth, scans or outputs (their stamps are read from the bytes: stamps.py). With it a read
can start at any frame, loading only the chunks that frame needs and releasing each once
no later frame needs it. Built once per Session and shared with its fresh() copies."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from mcap.records import Message

from . import schemas as S
from .decoding import EXPECTED_SCHEMAS, OUTPUT_TOPICS, Ref, decode
from .frame_grouping import FrameGrouper
from .ordering import chunk_indexes, chunk_messages, has_chunk_index, ordered_channel_messages, summary_channels

SLOTS = tuple(EXPECTED_SCHEMAS)  # FrameIndex.refs: one slot per session topic, in this order
# payloads a frame index never decodes in our own files (their stamps are read from the bytes)
BULKY_TOPICS = frozenset({S.TOPIC_IMAGE, S.TOPIC_DEPTH, S.TOPIC_LABELS, S.TOPIC_SCAN})


@dataclass
class FrameIndex:
    """Per frame, in frame order: its stamp, where each of its messages lies in the file,
    its ground truth and kind. Built once per Session (`Session.frame_index()`) by the same
    grouping as a sequential read, without decoding images, depth, scans or outputs."""

    stamps: np.ndarray  # (n,) int64 ns
    refs: np.ndarray  # (n, len(SLOTS), 2) int64: (chunk ordinal, message ordinal in it); -1 = none
    odometry: dict[int, object]  # frame -> its /odometry pose interpolated at its stamp (no own message)
    ground_truth: np.ndarray  # (n, 3), NaN rows where the frame has none
    kinds: list[str]  # "depth", "rgb" (camera frame without depth) or "laser"
    problems: list[str]  # what the grouping dropped, as a sequential read reports it

    def __len__(self) -> int:
        return len(self.stamps)


def build_index(session) -> FrameIndex | None:
    """The frame index of a session file (see FrameIndex); None in salvage mode and for
    files without a chunk index or with messages outside chunks."""
    summary = session.summary
    if session.salvage or not has_chunk_index(summary):
        return None
    # Our writer logs only frames that passed validation, so for its files the grouping
    # alone decides which frames a read yields and bulky payloads are never decoded.
    # Another tool's frames are built once here (their payload may be unusable: a read
    # drops such a frame, and the numbering must match).
    ours = session.info.get("writer", "").startswith("zfloc-stream/")
    stamp_only = BULKY_TOPICS | OUTPUT_TOPICS if ours else OUTPUT_TOPICS
    saved, session.problems = session.problems, []
    counted = [0]
    stamps, refs, truth, kinds, odometry = [], [], [], [], {}
    try:
        grouper = FrameGrouper(session)
        with open(session.path, "rb") as f:
            for stamp, parts in grouper.stamps(indexed_messages(session, f, stamp_only, counted)):
                where = {t: ref.where for t, (ref, _) in parts.items()}
                parts = {t: (ref.msg, meta) for t, (ref, meta) in parts.items()}
                own_odometry = S.TOPIC_ODOMETRY in parts
                if ours:
                    ok = session.complete_frame(stamp, parts, grouper.odometry)
                    gt = session.ground_truth_of(stamp, parts) if ok else None
                else:
                    rec = session.make_record(len(stamps), stamp, parts, grouper.odometry, outputs=False)
                    ok, gt = rec is not None, None if rec is None else rec.frame.ground_truth
                if not ok:
                    continue
                if not own_odometry:
                    odometry[len(stamps)] = parts[S.TOPIC_ODOMETRY][0]
                row = np.full((len(SLOTS), 2), -1, dtype=np.int64)
                for t, w in where.items():
                    row[SLOTS.index(t)] = w
                stamps.append(stamp)
                refs.append(row)
                truth.append(np.full(3, np.nan) if gt is None else np.asarray(gt, dtype=float)[:3])
                has_camera = S.TOPIC_DEPTH in parts or S.TOPIC_IMAGE in parts
                kinds.append("laser" if not has_camera else "depth" if S.TOPIC_DEPTH in parts else "rgb")
        problems = session.problems
    finally:
        session.problems = saved
    if counted[0] != summary.statistics.message_count:
        return None  # messages outside chunks: only a sequential read sees them all
    return FrameIndex(
        np.array(stamps, dtype=np.int64),
        np.array(refs, dtype=np.int64).reshape(-1, len(SLOTS), 2),
        odometry,
        np.array(truth, dtype=float).reshape(-1, 3),
        kinds,
        problems,
    )


def indexed_messages(session, f, stamp_only, counted: list[int]) -> Iterator[tuple[str, int, Ref, dict]]:
    """As decoding.messages, in log-time order (ordering.py); each message a Ref to its place."""
    for where, ch, stamp, msg in ordered_channel_messages(session, f, stamp_only, counted):
        yield ch.topic, stamp, Ref(where, msg), ch.metadata


def records_indexed(session, index: FrameIndex, start: int, stop: int | None, outputs: bool) -> Iterator:
    """Frames start..stop-1 assembled from the messages the index names: only the
    chunks holding them are read, each released once no later frame needs it."""
    session.problems = list(index.problems)
    stop = len(index) if stop is None else min(stop, len(index))
    if start >= stop:
        return
    slots = [k for k, t in enumerate(SLOTS) if outputs or t not in OUTPUT_TOPICS]
    used = index.refs[start:stop][:, slots, 0]
    last_use: dict[int, int] = {}
    rows, cols = np.nonzero(used >= 0)
    for r, c in zip(rows.tolist(), used[rows, cols].tolist(), strict=True):  # rows ascending: the last use wins
        last_use[c] = start + r
    chunks = chunk_indexes(session.summary)
    channels = summary_channels(session)
    loaded: dict[int, list[Message]] = {}
    with open(session.path, "rb") as f:
        for i in range(start, stop):
            stamp = int(index.stamps[i])
            parts = {}
            for k in slots:
                c, pos = (int(v) for v in index.refs[i, k])
                if c < 0:
                    continue
                if c not in loaded:
                    loaded[c] = chunk_messages(session.path, f, chunks[c])
                record = loaded[c][pos]
                ch = channels[record.channel_id]
                got = decode(session, ch, record, stamp_only=False)
                if got is not None:  # as the grouper hands it over: calibration without metadata
                    parts[ch.topic] = (got[1], {} if ch.topic == S.TOPIC_CALIBRATION else ch.metadata)
            if i in index.odometry:
                parts[S.TOPIC_ODOMETRY] = (index.odometry[i], {})
            rec = session.make_record(i, stamp, parts, None, outputs)
            for c in [c for c, last in last_use.items() if last <= i]:
                del last_use[c]
                loaded.pop(c, None)
            if rec is not None:
                yield rec
