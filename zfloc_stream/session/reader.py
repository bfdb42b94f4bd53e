"""MCAP sessions as an input source: settings, floorplan, input frames and logged outputs.

    session = read_session("session.mcap")            # or salvage=True for a cut-off file
    for rec in session.records():                     # FrameRecord: index, frame, outputs
        est = localizer.push(rec.frame)

Frames are grouped by the timestamp in each message's header (log time where a header
has none): one /camera/depth (or /scan) message plus the /odometry message of the same
timestamp make a frame (odometry at its own rate and stamps is interpolated at the
frame's timestamp instead: pose_interpolation.py); /camera/labels and /groundtruth/pose of that timestamp are added
when present; the calibration is the latest one at or before it. A frame is complete once
every input topic has moved past its timestamp, so only a few frames are ever buffered.
Files from other tools on the same topics read the same way.

Every fault ends as a SessionLogError naming the file and what is wrong. With
salvage=True a truncated or damaged file yields what its intact chunks hold, and the
reasons anything was dropped are listed in `Session.problems`.

Long sessions: `Session.frame_index()` runs the same grouping once over the file without
decoding images, depth, scans or outputs (only their header stamps are read) and notes,
per frame, where each of its messages lies (chunk, position). `records(start, stop)` on a
complete file then reads only the chunks that hold frames start..stop-1, and
`outputs=False` (the localizer input path: `frames()`) never decodes the logged outputs.
Frames, stamps, outputs and frame numbers are the ones a sequential read gives; salvage
and files without a chunk index are always read sequentially.
"""

from __future__ import annotations

import copy
import io
import tempfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from google.protobuf.descriptor_pb2 import FileDescriptorSet
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Chunk, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.summary import Summary
from mcap_protobuf.decoder import DecoderFactory

from ..config import Settings, settings_from_dict
from ..errors import FrameError, SessionLogError, ZflocError
from ..estimate import Estimate
from ..frames import CameraFrame, LaserFrame
from ..pose_interpolation import PoseTrack
from . import schemas as S
from .assemble import camera_frame_from_msgs, laser_frame_from_msgs

MAGIC = b"\x89MCAP0\r\n"
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
# Topics whose progress decides that a timestamp is complete (calibration is a state:
# often published once, so it must not hold frames back).
_PROGRESS_TOPICS = (S.TOPIC_IMAGE, S.TOPIC_DEPTH, S.TOPIC_SCAN, S.TOPIC_LABELS, S.TOPIC_ODOMETRY, S.TOPIC_GROUND_TRUTH, S.TOPIC_STATUS)
# A topic that stops early would otherwise hold every later frame in memory.
_MAX_PENDING_STAMPS = 16
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: ~20x faster on the settings dump
# Topics the frame index never decodes (only their header stamp is read): large payloads
# that do not decide whether a frame exists, and the logged outputs.
_BULKY_TOPICS = frozenset({S.TOPIC_IMAGE, S.TOPIC_DEPTH, S.TOPIC_LABELS, S.TOPIC_SCAN})
_OUTPUT_TOPICS = frozenset(S.OUTPUT_TOPICS)
_SLOTS = tuple(EXPECTED_SCHEMAS)  # FrameIndex.refs: one slot per session topic, in this order


@dataclass
class LoggedOutputs:
    """What the localizer logged for one frame (None where nothing was logged)."""

    status: dict | None = None  # /zfloc/status JSON
    pose: object | None = None  # foxglove.PoseInFrame message
    hypotheses: object | None = None  # foxglove.PosesInFrame message
    bev: object | None = None  # foxglove.Grid message

    @property
    def estimate(self) -> Estimate | None:
        return None if self.status is None else S.estimate_from_status(self.status)

    @property
    def bev_grid(self) -> S.BevGrid | None:
        return None if self.bev is None else S.grid_from_msg(self.bev)


@dataclass
class FrameRecord:
    index: int  # position in the session's frame sequence (0-based)
    stamp_ns: int
    frame: CameraFrame | LaserFrame
    outputs: LoggedOutputs
    inputs: dict = field(default_factory=dict)  # input topic -> (decoded message, channel metadata)


@dataclass
class FrameIndex:
    """Per frame, in frame order: its stamp, where each of its messages lies in the file,
    its ground truth and kind. Built once per Session (`Session.frame_index()`) by the same
    grouping as a sequential read, without decoding images, depth, scans or outputs."""

    stamps: np.ndarray  # (n,) int64 ns
    refs: np.ndarray  # (n, len(_SLOTS), 2) int64: (chunk ordinal, message ordinal in it); -1 = none
    odometry: dict[int, object]  # frame -> its /odometry pose interpolated at its stamp (no own message)
    ground_truth: np.ndarray  # (n, 3), NaN rows where the frame has none
    kinds: list[str]  # "depth", "rgb" (camera frame without depth) or "laser"
    problems: list[str]  # what the grouping dropped, as a sequential read reports it

    def __len__(self) -> int:
        return len(self.stamps)


@dataclass
class _Channel:
    topic: str
    decode: object  # bytes -> message
    metadata: dict
    stamp_field: int | None = None  # protobuf field number of `timestamp` (read without decoding)


@dataclass
class _Ref:
    """A message by its place in the file (chunk ordinal, ordinal among the chunk's
    messages); `msg` is the decoded message, None where only its stamp was read."""

    where: tuple[int, int]
    msg: object | None

    @property
    def pose(self):  # the grouper reads odometry poses
        return self.msg.pose


class Session:
    """A session file opened for reading. Iterate `records()` or `frames()` (each call
    reads the file again: from its start, or from the chunk holding `start` where the
    file has a chunk index)."""

    def __init__(
        self,
        path: Path,
        salvage: bool,
        metadata: dict[str, dict[str, str]],
        attachments: dict[str, bytes],
        topics: set[str] | None,
        summary: Summary | None = None,
    ):
        self.path = path
        self._summary = summary  # schemas, channels, chunk indexes (None: salvage or no summary)
        self._shared: dict = {}  # frame index and channel decoders, shared with fresh() copies
        self.salvage = salvage
        self.metadata = metadata
        self.attachments = attachments  # name -> bytes
        self.topics = topics  # from the summary; None when unknown (salvage, no summary)
        self.problems: list[str] = []  # why anything was dropped while reading
        self.settings_yaml: str | None = metadata.get(S.METADATA_SETTINGS, {}).get("yaml")
        self.settings: Settings | None = self._parse_settings(S.METADATA_SETTINGS, "logged settings")
        # the settings the floorplan was built with, logged only where they differ
        self.floorplan_settings: Settings | None = self._parse_settings(S.METADATA_FLOORPLAN_SETTINGS, "logged floorplan settings")
        self._floorplan = None

    # --- contents -------------------------------------------------------------------------
    def _parse_settings(self, record: str, what: str) -> Settings | None:
        text = self.metadata.get(record, {}).get("yaml")
        if text is None:
            return None
        crc = self.metadata[record].get(S.CRC_KEY)
        if crc is not None and crc != S.crc32_hex(text.encode("utf-8", "surrogateescape")):
            raise SessionLogError(f"{self.path}: {what} are damaged (checksum mismatch)")
        try:
            data = yaml.load(text, Loader=_YAML_LOADER)
        except yaml.YAMLError:
            raise SessionLogError(f"{self.path}: {what} are not valid YAML") from None
        if not isinstance(data, dict):
            raise SessionLogError(f"{self.path}: {what} are not a mapping")
        try:
            return settings_from_dict(data, source=f"{self.path} ({what})")
        except ZflocError as err:
            raise SessionLogError(str(err)) from None

    @property
    def info(self) -> dict[str, str]:
        return self.metadata.get(S.METADATA_SESSION, {})

    @property
    def environment(self) -> dict[str, str] | None:
        """Where the session was recorded (session/environment.py); None if not logged."""
        return self.metadata.get(S.METADATA_ENVIRONMENT)

    @property
    def floorplan_files(self) -> dict[str, bytes]:
        n = len(S.ATTACHMENT_FLOORPLAN_PREFIX)
        return {k[n:]: v for k, v in self.attachments.items() if k.startswith(S.ATTACHMENT_FLOORPLAN_PREFIX)}

    @property
    def floorplan(self):
        """The embedded floorplan built as in the recorded run (None when the file
        carries none)."""
        if self._floorplan is None and self.floorplan_files:
            self._floorplan = self.load_floorplan(self.floorplan_settings or self.settings)
        return self._floorplan

    def load_floorplan(self, settings: Settings | None = None):
        """The embedded floorplan built with the given settings, or None."""
        from ..plan_loading import load_floorplan  # the floorplan stage is only needed here

        files = self.floorplan_files
        if not files:
            return None
        checksums = self.metadata.get(S.METADATA_CHECKSUMS, {})
        for name, data in files.items():
            crc = checksums.get(S.ATTACHMENT_FLOORPLAN_PREFIX + name)
            if crc is not None and crc != S.crc32_hex(data):
                raise SessionLogError(f"{self.path}: embedded floorplan file {name} is damaged (checksum mismatch)")
        yamls = [n for n in files if n.endswith((".yaml", ".yml"))]
        if len(yamls) != 1 or any("/" in n or "\\" in n or n.startswith(".") for n in files):
            raise SessionLogError(f"{self.path}: floorplan attachments {sorted(files)} must hold one YAML and plain file names")
        with tempfile.TemporaryDirectory(prefix="zfloc-session-") as tmp:
            try:
                for name, data in files.items():
                    (Path(tmp) / name).write_bytes(data)
                return load_floorplan(Path(tmp) / yamls[0], settings=settings)
            except ZflocError as err:
                raise SessionLogError(f"{self.path}: embedded floorplan is unusable: {err}") from None
            except (OSError, ValueError) as err:  # names or bytes damaged in the file
                raise SessionLogError(f"{self.path}: embedded floorplan cannot be extracted ({err})") from None

    # --- frames -----------------------------------------------------------------------------
    def fresh(self) -> Session:
        """Another reader of the same file sharing the parsed contents and the frame index,
        with its own `problems` (one per concurrent iteration)."""
        other = copy.copy(self)
        other.problems = []
        return other

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[CameraFrame | LaserFrame]:
        for rec in self.records(start, stop, outputs=False):  # a frame needs no logged output
            yield rec.frame

    def records(self, start: int = 0, stop: int | None = None, outputs: bool = True, seek: bool = True) -> Iterator[FrameRecord]:
        """Frames start <= index < stop with their logged outputs, in timestamp order.

        outputs=False: the logged outputs are not decoded (empty LoggedOutputs). From start
        > 0 a file with a chunk index is read from the chunk holding that frame on (see
        frame_index; `problems` then lists what the whole file drops); seek=False, salvage
        and files without a chunk index read from the start."""
        index = self.frame_index() if seek and start > 0 else None
        if index is not None:
            yield from self._records_indexed(index, start, stop, outputs)
            return
        self.problems = []
        grouper = _FrameGrouper(self)
        records = _records(self.path, self.salvage, self.problems)
        index = 0
        for stamp, parts in grouper.stamps(self._messages(records, () if outputs else _OUTPUT_TOPICS)):
            rec = self._record(index, stamp, parts, grouper.odometry, outputs)
            if rec is None:
                continue
            if index >= start:
                if stop is not None and index >= stop:
                    return
                yield rec
            index += 1

    def _complete(self, stamp: int, parts: dict, odometry: PoseTrack | None) -> bool:
        """Whether the messages of a stamp make a frame (else the reason is noted); adds
        the odometry pose interpolated at the stamp where the frame has no message of its own."""
        where = f"t={S.ns_to_seconds(stamp):.9f}"
        has_camera = S.TOPIC_DEPTH in parts or S.TOPIC_IMAGE in parts
        if not (has_camera or S.TOPIC_SCAN in parts):
            orphans = sorted(t for t in parts if t not in (S.TOPIC_CALIBRATION, S.TOPIC_ODOMETRY))  # odometry may run at its own rate
            if orphans:
                self.problems.append(
                    f"{where}: {', '.join(orphans)} without a {S.TOPIC_DEPTH}, {S.TOPIC_IMAGE} or {S.TOPIC_SCAN} message of the same timestamp dropped"
                )
            return False
        if S.TOPIC_ODOMETRY not in parts:  # odometry at its own rate: the pose interpolated at this stamp
            T, reason = (None, f"no {S.TOPIC_ODOMETRY} message") if odometry is None else odometry.at(stamp)
            if T is None:
                self.problems.append(f"{where}: frame dropped: no {S.TOPIC_ODOMETRY} pose ({reason})")
                return False
            parts[S.TOPIC_ODOMETRY] = (S.pose_to_msg(T, stamp, S.FRAME_ODOM), {})
        if has_camera and parts.get(S.TOPIC_CALIBRATION, (None,))[0] is None:
            self.problems.append(f"{where}: frame dropped: no {S.TOPIC_CALIBRATION} at or before it")
            return False
        return True

    def _record(self, index: int, stamp: int, parts: dict, odometry: PoseTrack | None = None, outputs: bool = True) -> FrameRecord | None:
        if not self._complete(stamp, parts, odometry):
            return None
        logged = LoggedOutputs()
        if outputs:
            logged = LoggedOutputs(
                status=parts.get(S.TOPIC_STATUS, (None,))[0],
                pose=parts.get(S.TOPIC_POSE, (None,))[0],
                hypotheses=parts.get(S.TOPIC_HYPOTHESES, (None,))[0],
                bev=parts.get(S.TOPIC_BEV, (None,))[0],
            )
        where = f"t={S.ns_to_seconds(stamp):.9f}"
        has_camera = S.TOPIC_DEPTH in parts or S.TOPIC_IMAGE in parts
        odom, odom_meta = parts[S.TOPIC_ODOMETRY]
        gt, gt_meta = parts.get(S.TOPIC_GROUND_TRUTH, (None, {}))
        try:
            if has_camera:
                calib = parts[S.TOPIC_CALIBRATION][0]
                axis = gt_meta.get(S.HEADING_AXIS_KEY, "z")
                labels = parts.get(S.TOPIC_LABELS, (None,))[0]
                depth = parts.get(S.TOPIC_DEPTH, (None,))[0]
                image = parts.get(S.TOPIC_IMAGE, (None,))[0]
                frame = camera_frame_from_msgs(depth, labels, calib, odom, gt, axis, S.ns_to_seconds(stamp), image)
            else:
                scan, meta = parts[S.TOPIC_SCAN]
                cfg = (self.settings or Settings()).logging
                rmin = _float_meta(meta, S.RANGE_MIN_KEY, cfg.foreign_scan_range_min, self.path)
                rmax = _float_meta(meta, S.RANGE_MAX_KEY, cfg.foreign_scan_range_max, self.path)
                axis = gt_meta.get(S.HEADING_AXIS_KEY, "x")
                frame = laser_frame_from_msgs(scan, rmin, rmax, odom, gt, axis, S.ns_to_seconds(stamp))
        except FrameError as err:  # a valid file may hold an unusable frame: skip it, say why
            self.problems.append(f"{where}: frame dropped: {err}")
            return None
        except SessionLogError as err:
            self._fail(f"frame at {where}: {err}")
            return None
        inputs = {t: parts[t] for t in S.INPUT_TOPICS if t in parts}
        return FrameRecord(index, stamp, frame, logged, inputs)

    # --- frame index and seeking ------------------------------------------------------------
    def frame_index(self) -> FrameIndex | None:
        """Where every frame's messages lie (built on first use, shared with fresh()
        copies); None in salvage mode and for files without a chunk index."""
        if "index" not in self._shared:
            self._shared["index"] = self._build_index()
        return self._shared["index"]

    def _chunk_indexes(self) -> list:
        return sorted(self._summary.chunk_indexes, key=lambda c: c.chunk_start_offset)  # file order

    def _build_index(self) -> FrameIndex | None:
        summary = self._summary
        if self.salvage or summary is None or not summary.chunk_indexes or summary.statistics is None:
            return None
        # Our writer logs only frames that passed validation, so for its files the grouping
        # alone decides which frames a read yields and bulky payloads are never decoded.
        # Another tool's frames are built once here (their payload may be unusable: a read
        # drops such a frame, and the numbering must match).
        ours = self.info.get("writer", "").startswith("zfloc-stream/")
        stamp_only = _BULKY_TOPICS | _OUTPUT_TOPICS if ours else _OUTPUT_TOPICS
        saved, self.problems = self.problems, []
        counted = [0]
        stamps, refs, truth, kinds, odometry = [], [], [], [], {}
        try:
            grouper = _FrameGrouper(self)
            with open(self.path, "rb") as f:
                for stamp, parts in grouper.stamps(self._indexed_messages(f, stamp_only, counted)):
                    where = {t: ref.where for t, (ref, _) in parts.items()}
                    parts = {t: (ref.msg, meta) for t, (ref, meta) in parts.items()}
                    own_odometry = S.TOPIC_ODOMETRY in parts
                    if ours:
                        ok = self._complete(stamp, parts, grouper.odometry)
                        gt = self._ground_truth(stamp, parts) if ok else None
                    else:
                        rec = self._record(len(stamps), stamp, parts, grouper.odometry, outputs=False)
                        ok, gt = rec is not None, None if rec is None else rec.frame.ground_truth
                    if not ok:
                        continue
                    if not own_odometry:
                        odometry[len(stamps)] = parts[S.TOPIC_ODOMETRY][0]
                    row = np.full((len(_SLOTS), 2), -1, dtype=np.int64)
                    for t, w in where.items():
                        row[_SLOTS.index(t)] = w
                    stamps.append(stamp)
                    refs.append(row)
                    truth.append(np.full(3, np.nan) if gt is None else np.asarray(gt, dtype=float)[:3])
                    has_camera = S.TOPIC_DEPTH in parts or S.TOPIC_IMAGE in parts
                    kinds.append("laser" if not has_camera else "depth" if S.TOPIC_DEPTH in parts else "rgb")
            problems = self.problems
        finally:
            self.problems = saved
        if counted[0] != summary.statistics.message_count:
            return None  # messages outside chunks: only a sequential read sees them all
        return FrameIndex(
            np.array(stamps, dtype=np.int64),
            np.array(refs, dtype=np.int64).reshape(-1, len(_SLOTS), 2),
            odometry,
            np.array(truth, dtype=float).reshape(-1, 3),
            kinds,
            problems,
        )

    def _ground_truth(self, stamp: int, parts: dict):
        """(x, y, theta) of the frame's /groundtruth/pose as a read assembles it, or None."""
        gt, meta = parts.get(S.TOPIC_GROUND_TRUTH, (None, {}))
        if gt is None:
            return None
        has_camera = S.TOPIC_DEPTH in parts or S.TOPIC_IMAGE in parts
        try:
            return S.planar_pose_from_pose(gt.pose, meta.get(S.HEADING_AXIS_KEY, "z" if has_camera else "x"))
        except SessionLogError as err:
            self._fail(f"frame at t={S.ns_to_seconds(stamp):.9f}: {err}")
            return None

    def _indexed_messages(self, f, stamp_only, counted: list[int]) -> Iterator[tuple[str, int, _Ref, dict]]:
        """As _messages, over the chunks in file order; each message a _Ref to its place."""
        channels = self._summary_channels()
        for c, chunk in enumerate(self._chunk_indexes()):
            for pos, record in enumerate(self._chunk_messages(f, chunk)):
                counted[0] += 1
                got = self._channel_message(channels, record, stamp_only)
                if got is not None:
                    ch, stamp, msg = got
                    yield ch.topic, stamp, _Ref((c, pos), msg), ch.metadata

    def _summary_channels(self) -> dict[int, _Channel | None]:
        if "channels" not in self._shared:
            factory = DecoderFactory()
            self._shared["channels"] = {
                cid: self._channel(ch, self._summary.schemas, factory) for cid, ch in sorted(self._summary.channels.items())
            }
        return self._shared["channels"]

    def _chunk_messages(self, f, chunk) -> list[Message]:
        """The messages of one chunk (found by its index), in their order in the chunk."""
        try:
            f.seek(chunk.chunk_start_offset)
            record = next(StreamReader(f, skip_magic=True, emit_chunks=True, record_size_limit=self.path.stat().st_size).records)
            if not isinstance(record, Chunk):
                raise ValueError(f"a {type(record).__name__} record where the index puts a chunk")
            return [r for r in breakup_chunk(record, validate_crc=True) if isinstance(r, Message)]
        except Exception as err:  # noqa: BLE001 - any parser fault on damaged bytes
            what = f"{type(err).__name__}: {err}".replace("\n", " ")
            raise SessionLogError(f"{self.path}: damaged chunk at byte {chunk.chunk_start_offset} ({what}); try --salvage") from None

    def _records_indexed(self, index: FrameIndex, start: int, stop: int | None, outputs: bool) -> Iterator[FrameRecord]:
        """Frames start..stop-1 assembled from the messages the index names: only the
        chunks holding them are read, each released once no later frame needs it."""
        self.problems = list(index.problems)
        stop = len(index) if stop is None else min(stop, len(index))
        if start >= stop:
            return
        slots = [k for k, t in enumerate(_SLOTS) if outputs or t not in _OUTPUT_TOPICS]
        used = index.refs[start:stop][:, slots, 0]
        last_use: dict[int, int] = {}
        rows, cols = np.nonzero(used >= 0)
        for r, c in zip(rows.tolist(), used[rows, cols].tolist(), strict=True):  # rows ascending: the last use wins
            last_use[c] = start + r
        chunks = self._chunk_indexes()
        channels = self._summary_channels()
        loaded: dict[int, list[Message]] = {}
        with open(self.path, "rb") as f:
            for i in range(start, stop):
                stamp = int(index.stamps[i])
                parts = {}
                for k in slots:
                    c, pos = (int(v) for v in index.refs[i, k])
                    if c < 0:
                        continue
                    if c not in loaded:
                        loaded[c] = self._chunk_messages(f, chunks[c])
                    record = loaded[c][pos]
                    ch = channels[record.channel_id]
                    got = self._decode(ch, record, stamp_only=False)
                    if got is not None:  # as the grouper hands it over: calibration without metadata
                        parts[ch.topic] = (got[1], {} if ch.topic == S.TOPIC_CALIBRATION else ch.metadata)
                if i in index.odometry:
                    parts[S.TOPIC_ODOMETRY] = (index.odometry[i], {})
                rec = self._record(i, stamp, parts, None, outputs)
                for c in [c for c, last in last_use.items() if last <= i]:
                    del last_use[c]
                    loaded.pop(c, None)
                if rec is not None:
                    yield rec

    # --- records and messages ---------------------------------------------------------------
    def _fail(self, what: str) -> None:
        """A fault in the file: raise, or in salvage mode note it and go on."""
        if not self.salvage:
            raise SessionLogError(f"{self.path}: {what}")
        self.problems.append(what)

    def _messages(self, records: Iterable, stamp_only: Iterable[str] = ()) -> Iterator[tuple[str, int, object, dict]]:
        """(topic, stamp_ns, decoded message, channel metadata) of the session topics, from
        records in file order; messages of `stamp_only` topics are not decoded (None)."""
        schemas: dict[int, Schema] = {}
        channels: dict[int, _Channel | None] = {}
        factory = DecoderFactory()
        for record in records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                if record.id not in channels:
                    channels[record.id] = self._channel(record, schemas, factory)
            elif isinstance(record, Message):
                got = self._channel_message(channels, record, stamp_only)
                if got is not None:
                    ch, stamp, msg = got
                    yield ch.topic, stamp, msg, ch.metadata

    def _channel_message(self, channels: dict, record: Message, stamp_only) -> tuple[_Channel, int, object | None] | None:
        """(channel, stamp, message) of a message on a session topic; None for topics this
        package does not read, unknown channels (a fault) and undecodable messages."""
        ch = channels.get(record.channel_id)
        if ch is None:
            if record.channel_id not in channels:
                self._fail(f"message on unknown channel {record.channel_id}")
            return None
        got = self._decode(ch, record, ch.topic in stamp_only)
        return None if got is None else (ch, got[0], got[1])

    def _decode(self, ch: _Channel, record: Message, stamp_only: bool) -> tuple[int, object | None] | None:
        """(stamp, message) of a message record; the message is None with stamp_only (only
        its header stamp is read, where its bytes allow); None when it cannot be decoded."""
        if stamp_only:
            stamp = _stamp_only(ch, record)
            if stamp is not None:
                return stamp, None
        try:
            msg = ch.decode(record.data)
            stamp = record.log_time  # JSON status has no header stamp
            if ch.topic != S.TOPIC_STATUS and msg.HasField("timestamp") and S.from_stamp(msg.timestamp) > 0:
                stamp = S.from_stamp(msg.timestamp)
        except SessionLogError as err:
            self._fail_message(ch, record, stamp_only, str(err))
            return None
        except Exception as err:  # noqa: BLE001 - protobuf on damaged bytes
            self._fail_message(ch, record, stamp_only, f"cannot be decoded ({type(err).__name__})")
            return None
        return stamp, None if stamp_only else msg

    def _fail_message(self, ch: _Channel, record: Message, stamp_only: bool, why: str) -> None:
        """An undecodable message refuses the file, unless localizing does not need its
        topic (ground truth; logged outputs when they are not being read): then it is
        skipped and noted (the run warns once per cause)."""
        if ch.topic == S.TOPIC_GROUND_TRUTH or (stamp_only and ch.topic in _OUTPUT_TOPICS):
            self.problems.append(f"{ch.topic} message skipped: {why}; localizing does not need it (log time {record.log_time})")
            return
        self._fail(f"{ch.topic} message at log time {record.log_time}: {why}")

    def _channel(self, channel: Channel, schemas: dict, factory: DecoderFactory) -> _Channel | None:
        """A decoder for a session topic; None for topics this package does not read."""
        expected = EXPECTED_SCHEMAS.get(channel.topic)
        if expected is None:
            return None
        schema = schemas.get(channel.schema_id)
        name = None if schema is None else schema.name
        allowed = expected if isinstance(expected, tuple) else (expected,)
        if name not in allowed:
            self._fail(f"topic {channel.topic} has schema {name!r}, expected {' or '.join(map(repr, allowed))}")
            return None
        if channel.topic == S.TOPIC_STATUS:
            if channel.message_encoding != "json":
                self._fail(f"topic {channel.topic} has message encoding {channel.message_encoding!r}, expected 'json'")
                return None
            return _Channel(channel.topic, S.decode_status, dict(channel.metadata))
        try:
            decoder = factory.decoder_for(channel.message_encoding, schema)
        except Exception as err:  # noqa: BLE001 - a damaged schema record
            self._fail(f"schema {name} of topic {channel.topic} cannot be loaded ({type(err).__name__}: {err})")
            return None
        if decoder is None:
            self._fail(f"topic {channel.topic} is not protobuf-encoded (message encoding {channel.message_encoding!r})")
            return None
        return _Channel(channel.topic, decoder, dict(channel.metadata), _timestamp_field(schema))


# --- header stamps without decoding -------------------------------------------------------------
def _timestamp_field(schema: Schema) -> int | None:
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


def _scan_stamp(data: bytes, number: int) -> tuple[bool, int]:
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


def _stamp_only(ch: _Channel, record: Message) -> int | None:
    """A message's stamp as _decode gives it, read without decoding the message; None where
    the bytes do not scan (the decoder then says what is wrong)."""
    if ch.topic == S.TOPIC_STATUS:
        return record.log_time  # JSON status has no header stamp
    if ch.stamp_field is None:
        return None
    try:
        found, ns = _scan_stamp(record.data, ch.stamp_field)
    except (ValueError, IndexError):
        return None
    return ns if found and ns > 0 else record.log_time


def _float_meta(meta: dict, key: str, default: float, path: Path) -> float:
    if key not in meta:
        return float(default)
    try:
        return float(meta[key])
    except ValueError:
        raise SessionLogError(f"{path}: /scan channel metadata {key}={meta[key]!r} is not a number") from None


class _FrameGrouper:
    """Collects messages per timestamp; a timestamp is released once every input topic
    seen so far has moved past it (or at the end of the file)."""

    def __init__(self, session: Session):
        self.session = session
        # Frames are keyed (stamp, occurrence): real logs repeat stamps (printed with few
        # digits), so the n-th message of each topic at one stamp belongs to the n-th frame.
        self.pending: dict[tuple[int, int], dict] = {}
        self.progress: dict[str, tuple[int, int]] = {}
        self.seen: dict[tuple[str, int], int] = {}  # (topic, stamp) -> messages so far
        self.calibrations: list[tuple[int, object]] = []  # (stamp, message), in file order
        self.released_up_to = (-1, 0)
        self.session_warned_repeats = False
        gap = (session.settings or Settings()).datasets.ros2.max_odometry_gap
        self.odometry = PoseTrack(S.TOPIC_ODOMETRY, gap)  # every odometry pose, for frames between its stamps

    def stamps(self, messages) -> Iterator[tuple[int, dict]]:
        for topic, stamp, msg, meta in messages:
            if topic == S.TOPIC_CALIBRATION:
                self.calibrations.append((stamp, msg))
                continue
            if topic == S.TOPIC_ODOMETRY:
                try:
                    self.odometry.add(stamp, S.matrix_from_pose(msg.pose))
                except SessionLogError:
                    pass  # a broken pose: reported when a frame of that stamp is assembled
            occurrence = self.seen.get((topic, stamp), 0)
            self.seen[(topic, stamp)] = occurrence + 1
            key = (stamp, occurrence)
            if key <= self.released_up_to:
                self.session.problems.append(f"{topic} message at t={S.ns_to_seconds(stamp):.9f} arrived after its frame and was dropped")
                continue
            if occurrence == 1 and not self.session_warned_repeats:
                self.session.problems.append(f"repeated timestamps (first at t={S.ns_to_seconds(stamp):.9f}): frames kept in file order")
                self.session_warned_repeats = True
            self.pending.setdefault(key, {})[topic] = (msg, meta)
            if topic in _PROGRESS_TOPICS:
                self.progress[topic] = max(key, self.progress.get(topic, (-1, 0)))
            yield from self._release(min(self.progress.values()) if self.progress else (-1, 0))
        yield from self._release(None)

    def _release(self, before: int | None) -> Iterator[tuple[int, dict]]:
        """Release stamps < before (all when None), oldest first; and the oldest ones
        beyond the pending bound."""
        for key in sorted(self.pending):
            if before is not None and key >= before and len(self.pending) <= _MAX_PENDING_STAMPS:
                break
            parts = self.pending.pop(key)
            stamp = key[0]
            self.released_up_to = key
            self.seen = {k: n for k, n in self.seen.items() if k[1] >= stamp}
            self.odometry.drop_before(stamp)  # later frames have later stamps
            calib = self._calibration_at(stamp)
            if calib is not None:
                parts[S.TOPIC_CALIBRATION] = (calib, {})
            yield stamp, parts

    def _calibration_at(self, stamp: int):
        """Latest calibration at or before the stamp (else the first one: published late)."""
        best = None
        for s, msg in self.calibrations:
            if s <= stamp and (best is None or s >= best[0]):
                best = (s, msg)
        if best is None:
            return self.calibrations[0][1] if self.calibrations else None
        # older calibrations can no longer be the latest for a later stamp
        self.calibrations = [(s, m) for s, m in self.calibrations if s >= best[0]]
        return best[1]


# --- opening -----------------------------------------------------------------------------------
@dataclass
class _Zeroed:
    """A record with opcode 0x00, which MCAP reserves as invalid: bytes overwritten with
    zeros (9 zero bytes parse as an empty record, so a zeroed region reads as a run of them)."""

    length: int


class _DamageAwareReader(StreamReader):
    """StreamReader that reports opcode-0 records instead of skipping them as unknown."""

    def _read_record(self, opcode: int, length: int):
        if opcode == 0:
            self._stream.read(length)
            return _Zeroed(length)
        return super()._read_record(opcode, length)


def _records(path: Path, salvage: bool, problems: list[str]) -> Iterator:
    """Records in file order, chunks broken up. Faults raise (or, salvaging, end the scan
    at a damaged record and skip a damaged chunk or a zeroed region)."""
    size = path.stat().st_size
    zeroed_from = None  # start of the zeroed region being skipped (salvage)
    with open(path, "rb") as f:
        reader = _DamageAwareReader(f, emit_chunks=True, validate_crcs=True, record_size_limit=size)
        records = reader.records
        while True:
            offset = f.tell()
            try:
                record = next(records)
            except StopIteration:
                return
            except Exception as err:  # noqa: BLE001 - any parser fault on damaged bytes
                what = _describe(err, offset, size)
                if not salvage:
                    raise SessionLogError(f"{path}: {what}") from None
                problems.append(f"reading stopped: {what}")
                return
            if isinstance(record, _Zeroed):
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
                yield from inner
            else:
                yield record
            if isinstance(record, Footer):
                return


def _describe(err: Exception, offset: int, size: int) -> str:
    name = type(err).__name__
    if name == "EndOfFile" or "unpack requires" in str(err):
        if offset >= size:
            return f"file is truncated (it ends at byte {size} without an MCAP footer: a recording cut off?)"
        return f"file is truncated (it ends inside a record that starts at byte {offset} of {size})"
    if name == "InvalidMagic":
        return "not an MCAP file (bad magic bytes)"
    return f"damaged record near byte {offset} ({name}: {err})"


def _check_path(path: Path) -> None:
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


def _open_indexed(path: Path) -> tuple[dict, dict, Summary | None]:
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


def _open_scanning(path: Path, problems: list[str]) -> tuple[dict, dict]:
    """Metadata and attachments found by a scan of top-level records (salvage)."""
    metadata: dict = {}
    attachments: dict = {}
    size = path.stat().st_size
    with open(path, "rb") as f:
        records = _DamageAwareReader(f, emit_chunks=True, validate_crcs=True, record_size_limit=size).records
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


def _check_topics(path: Path, topics: set[str]) -> None:
    if not topics & {S.TOPIC_DEPTH, S.TOPIC_IMAGE, S.TOPIC_SCAN}:
        raise SessionLogError(f"{path}: no input frames: none of {S.TOPIC_DEPTH}, {S.TOPIC_IMAGE}, {S.TOPIC_SCAN} is in the file")
    if S.TOPIC_ODOMETRY not in topics:
        raise SessionLogError(f"{path}: topic {S.TOPIC_ODOMETRY} is missing (every frame needs its relative pose)")
    if topics & {S.TOPIC_DEPTH, S.TOPIC_IMAGE} and S.TOPIC_CALIBRATION not in topics:
        raise SessionLogError(f"{path}: topic {S.TOPIC_CALIBRATION} is missing (camera frames need intrinsics)")


def read_session(path: str | Path, salvage: bool = False) -> Session:
    """Open a session file. Raises SessionLogError when it is missing, not MCAP, truncated
    (unless salvage), damaged, or lacks the input topics."""
    path = Path(path)
    _check_path(path)
    problems: list[str] = []
    summary = topics = None
    if salvage:
        metadata, attachments = _open_scanning(path, problems)
    else:
        metadata, attachments, summary = _open_indexed(path)
        if summary is not None:
            topics = {c.topic for c in summary.channels.values()}
            _check_topics(path, topics)
    session = Session(path, salvage, metadata, attachments, topics, summary)
    session.problems = problems
    return session
