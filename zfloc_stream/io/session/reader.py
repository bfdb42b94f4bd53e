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
Messages are handed to the grouping in log-time order where the file has a chunk index
(ordering.py: another tool may write them grouped by topic or shuffled), else in file
order. Files from other tools on the same topics read the same way.

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

This module is the Session API and the assembly of a frame from its messages; the rest of
reading lives beside it: mcap_file.py (opening, checks, salvage scans), decoding.py (one
decoder per topic, message stamps), stamps.py (stamps read without decoding),
frame_grouping.py (messages -> frames by stamp), frame_index.py (the seek index).
"""

from __future__ import annotations

import copy
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.summary import Summary

from ...settings.loading import Settings, settings_from_dict
from ...settings.retired import drop_retired
from ...errors import FrameError, SessionLogError, ZflocError
from ...estimate import Estimate
from ...frames import CameraFrame, LaserFrame
from ...geometry.pose_interpolation import PoseTrack
from . import schemas as S
from .assemble import camera_frame_from_msgs, laser_frame_from_msgs
from .decoding import OUTPUT_TOPICS, messages
from .frame_grouping import FrameGrouper
from .frame_index import FrameIndex, build_index, records_indexed
from .mcap_file import check_path, check_topics, file_records, open_indexed, open_salvaged
from .ordering import OrderWatch, has_chunk_index, ordered_channel_messages

_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml: ~20x faster on the settings dump


# Settings added after a session may have been recorded, with the value that reproduces the
# runs made before they existed: a logged settings block without one of these keys gets that
# value, not today's default, so an older session replays as it ran.
PREDATED_SETTINGS = {("estimator", "correlative", "scales"): 1, ("localizer", "first_fix_preview"): False}


def as_recorded(data: dict) -> dict:
    """The logged settings with PREDATED_SETTINGS' values where their keys are missing
    (sections that are missing too stay missing: nothing was logged there)."""
    for path, value in PREDATED_SETTINGS.items():
        section = data
        for key in path[:-1]:
            section = section.get(key) if isinstance(section, dict) else None
        if isinstance(section, dict) and path[-1] not in section:
            section[path[-1]] = value
    return data


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
        self.summary = summary  # schemas, channels, chunk indexes (None: no summary; salvage: where the file's end survived)
        self.shared: dict = {}  # frame index and channel decoders, shared with fresh() copies
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
        self.read_settings: Settings | None = None  # the reader's limits, where the caller gives them

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
            # retired keys (now constants) dropped, with a warning where the log's value differs
            kept = drop_retired(as_recorded(data), f"{self.path} ({what})", logged=True)
            return settings_from_dict(kept, source=f"{self.path} ({what})")
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
        from ...plans.loading import load_floorplan  # the floorplan stage is only needed here

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
            yield from records_indexed(self, index, start, stop, outputs)
            return
        self.problems = []
        grouper = FrameGrouper(self)
        index = 0
        for stamp, parts in grouper.stamps(self._messages(() if outputs else OUTPUT_TOPICS)):
            rec = self.make_record(index, stamp, parts, grouper.odometry, outputs)
            if rec is None:
                continue
            if index >= start:
                if stop is not None and index >= stop:
                    return
                yield rec
            index += 1

    def _messages(self, stamp_only) -> Iterator[tuple[str, int, object, dict]]:
        """The session topics' messages in log-time order where the file has a chunk index
        (ordering.py; salvaging too, where its summary survived), else in file order."""
        if not has_chunk_index(self.summary):
            why = "the file has no chunk index" if not self.salvage else "the damaged file has no readable summary"
            watch = OrderWatch(self.problems, why)
            records = file_records(self.path, self.salvage, self.problems, watch.see)
            yield from messages(self, records, stamp_only)
            return
        counted = [0]
        with open(self.path, "rb") as f:
            for _, ch, stamp, msg in ordered_channel_messages(self, f, stamp_only, counted):
                yield ch.topic, stamp, msg, ch.metadata
        missing = self.summary.statistics.message_count - counted[0]
        if missing > 0 and not self.salvage:
            self.problems.append(f"{missing} message(s) outside the file's chunks skipped (the chunk index does not reach them)")

    def complete_frame(self, stamp: int, parts: dict, odometry: PoseTrack | None) -> bool:
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

    def make_record(self, index: int, stamp: int, parts: dict, odometry: PoseTrack | None = None, outputs: bool = True) -> FrameRecord | None:
        """The frame of one stamp's messages with its logged outputs, or None (dropped, the
        reason noted)."""
        if not self.complete_frame(stamp, parts, odometry):
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
                notes: list[str] = []
                frame = camera_frame_from_msgs(depth, labels, calib, odom, gt, axis, S.ns_to_seconds(stamp), image, notes)
                for note in notes:
                    self.note_once(note, where)
            else:
                scan, meta = parts[S.TOPIC_SCAN]
                # the caller's settings first (a dataset spec's, run --set), as for the
                # reorder limit: a foreign file logs none, so only the caller can set these
                cfg = (self.read_settings or self.settings or Settings()).logging
                rmin = _float_meta(meta, S.RANGE_MIN_KEY, cfg.foreign_scan_range_min, self.path)
                rmax = _float_meta(meta, S.RANGE_MAX_KEY, cfg.foreign_scan_range_max, self.path)
                axis = gt_meta.get(S.HEADING_AXIS_KEY, "x")
                frame = laser_frame_from_msgs(scan, rmin, rmax, odom, gt, axis, S.ns_to_seconds(stamp))
        except FrameError as err:  # a valid file may hold an unusable frame: skip it, say why
            self.problems.append(f"{where}: frame dropped: {err}")
            return None
        except SessionLogError as err:
            self.fail(f"frame at {where}: {err}")
            return None
        inputs = {t: parts[t] for t in S.INPUT_TOPICS if t in parts}
        return FrameRecord(index, stamp, frame, logged, inputs)

    def ground_truth_of(self, stamp: int, parts: dict):
        """(x, y, theta) of the frame's /groundtruth/pose as a read assembles it, or None."""
        gt, meta = parts.get(S.TOPIC_GROUND_TRUTH, (None, {}))
        if gt is None:
            return None
        has_camera = S.TOPIC_DEPTH in parts or S.TOPIC_IMAGE in parts
        try:
            return S.planar_pose_from_pose(gt.pose, meta.get(S.HEADING_AXIS_KEY, "z" if has_camera else "x"))
        except SessionLogError as err:
            self.fail(f"frame at t={S.ns_to_seconds(stamp):.9f}: {err}")
            return None

    # --- frame index and seeking ------------------------------------------------------------
    def frame_index(self) -> FrameIndex | None:
        """Where every frame's messages lie (built on first use, shared with fresh()
        copies); None in salvage mode and for files without a chunk index."""
        if "index" not in self.shared:
            self.shared["index"] = build_index(self)
        return self.shared["index"]

    # --- faults ---------------------------------------------------------------
    def note_once(self, note: str, where: str) -> None:
        """A change made to what the file holds (millimetres converted, distortion
        ignored), noted once per read at the first frame it concerns."""
        key = note.split(" (")[0]
        if not any(p.startswith(key) for p in self.problems):
            self.problems.append(f"{note} (first at {where})")

    def fail(self, what: str) -> None:
        """A fault in the file: raise, or in salvage mode note it and go on."""
        if not self.salvage:
            raise SessionLogError(f"{self.path}: {what}")
        self.problems.append(what)


def _float_meta(meta: dict, key: str, default: float, path: Path) -> float:
    if key not in meta:
        return float(default)
    try:
        return float(meta[key])
    except ValueError:
        raise SessionLogError(f"{path}: /scan channel metadata {key}={meta[key]!r} is not a number") from None


def read_session(path: str | Path, salvage: bool = False, settings: Settings | None = None) -> Session:
    """Open a session file. Raises SessionLogError when it is missing, not MCAP, truncated
    (unless salvage), damaged, or lacks the input topics. settings: the reader's limits
    (logging.reorder_max_mb, logging.foreign_scan_range_min / _max, datasets.ros2.max_odometry_gap);
    default the file's logged settings, else the defaults."""
    path = Path(path)
    check_path(path)
    problems: list[str] = []
    summary = topics = None
    if salvage:
        metadata, attachments, summary = open_salvaged(path)
    else:
        metadata, attachments, summary = open_indexed(path)
        if summary is not None:
            topics = {c.topic for c in summary.channels.values()}
            check_topics(path, topics)
    session = Session(path, salvage, metadata, attachments, topics, summary)
    session.problems = problems
    session.read_settings = settings
    return session
