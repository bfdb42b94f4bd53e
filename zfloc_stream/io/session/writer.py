"""The session sink: every input and output of a run, in one Foxglove-compatible MCAP file.

    with SessionWriter("session.mcap", settings, floorplan) as log:
        for index, frame in enumerate(frames):
            frame = log.write_frame(index, frame)   # push the frame *as logged*
            est = localizer.push(frame)
            log.write_estimate(est, localizer)      # BEV published every n frames

write_frame returns the frame rebuilt from the messages it wrote (quaternion, time and
scan angles round-tripped). Pushing that frame makes the live run and a later replay see
the same bits, which is what `zfloc-replay --check` verifies.

Crash safety: settings and floorplan are written first, outside chunks; chunks are closed
every `logging.chunk_max_frames` frames (or `chunk_size` bytes) and handed to the OS after
every frame, so a process killed at any point leaves the finished chunks readable with
`read_session(path, salvage=True)`. With `logging.background` (default) compression and
file writes run on one worker thread (sink.py); at most `logging.max_pending_batches`
batches (two per frame) wait there, and a crash loses those too.
"""

from __future__ import annotations

import contextlib
import tempfile
import warnings
from pathlib import Path

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap.writer import CompressionType, Writer

from ... import __version__
from ...settings.loading import Settings, dump_settings
from ...errors import SessionLogError
from ...estimate import Estimate
from ...geometry.frame_tree import LEGACY_MAP
from ...frames import CameraFrame, LaserFrame
from . import environment
from . import schemas as S
from .assemble import laser_frame_from_msgs
from .sink import Record, RecordSink
from .transforms import frame_transforms_msg

_OUR_CLASSES = {c.DESCRIPTOR.full_name: c for c in (S.RawImage, S.CompressedImage, S.CameraCalibration, S.LaserScan, S.PoseInFrame)}
_COMPRESSION = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
_MEDIA_TYPES = {".yaml": "application/yaml", ".yml": "application/yaml", ".png": "image/png", ".pgm": "image/x-portable-graymap"}


def bev_grid_of(source) -> S.BevGrid | None:
    """The BEV layer to publish, cropped to its observed cells, from a BevGrid, a
    RollingBEV or a Localizer (its `.bev`). A BEV exposes `log_odds_grid() -> (values,
    origin, resolution)`, or else its scrolling `grid` (logodds, ix0, iy0, res) is read."""
    if source is None:
        return None
    bev = getattr(source, "bev", source)
    getter = getattr(bev, "log_odds_grid", None)
    if isinstance(source, S.BevGrid):
        values, origin, resolution = source.values, source.origin, source.resolution
    elif getter is not None:
        out = getter()
        if out is None:
            return None
        values, origin, resolution = out
    else:
        g = getattr(bev, "grid", None)
        if g is None or getattr(g, "ix0", None) is None:
            return None
        values, origin, resolution = g.logodds, (g.ix0 * g.res, g.iy0 * g.res), g.res
    values = np.asarray(values, dtype=np.float32)
    rows, cols = np.nonzero((values != 0).any(axis=1))[0], np.nonzero((values != 0).any(axis=0))[0]
    if rows.size == 0:
        return None
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    origin = np.asarray(origin, dtype=float) + np.array([c0, r0]) * float(resolution)
    return S.BevGrid(values[r0:r1, c0:c1], origin, float(resolution))


def _truth_msg(index: int, truth, ns: int, heading_axis: str):
    """/groundtruth/pose of a frame; None where the truth is unknown (None or NaN)."""
    if truth is None:
        return None
    t = np.asarray(truth, dtype=float).ravel()
    if t.size != 3:
        raise SessionLogError(f"frame {index}: ground_truth must be (x, y, theta), got {t.size} values")
    if not np.isfinite(t).all():
        return None
    return S.PoseInFrame(timestamp=S.to_stamp(ns), frame_id=S.FRAME_FLOORPLAN, pose=S.planar_pose_to_pose(t, heading_axis))


class SessionWriter:
    """Writes one session file. Use as a context manager (or call close())."""

    def __init__(self, path: str | Path, settings: Settings, floorplan=None, metadata: dict[str, str] | None = None,
                 listeners=()):
        """listeners: callables given each batch of records as it is written (the live view)."""
        self.path = Path(path)
        self._listeners = tuple(listeners)
        self.settings = settings
        self._cfg = settings.logging
        try:
            self._file = open(self.path, "wb")  # noqa: SIM115 - owned until close()
        except OSError as err:
            raise SessionLogError(f"cannot create session file {self.path}: {err.strerror or err}") from None
        self._mcap = Writer(self._file, chunk_size=self._cfg.chunk_size, compression=_COMPRESSION[self._cfg.compression])
        self._batch: list[Record] = []  # the messages of the call in progress
        self._close_chunk_first = False
        self._frames_in_chunk = 0
        self._last_frame: tuple[float, int] | None = None  # (timestamp as logged, ns)
        self._warned_time = False  # a repeated / backwards timestamp was reported
        self._closed = False
        self._failed = False  # a write failed (reported once); close() only releases the file
        self.frames_written = 0
        self._sensor: tuple[str, str, np.ndarray] | None = None  # (frame id, heading axis, T_odom_sensor) of the last frame, for /tf
        try:
            self._start(settings, floorplan, metadata)
        except OSError as err:
            with contextlib.suppress(OSError):
                self._file.close()
            raise SessionLogError(f"{self.path}: writing the session failed: {err.strerror or err}") from None
        self._sink = RecordSink(self._mcap, self._file, self._cfg.background, self._cfg.max_pending_batches)

    def _start(self, settings: Settings, floorplan, metadata) -> None:
        """Header, then settings and floorplan, outside chunks: a truncated file keeps them."""
        self._mcap.start(profile="", library=f"zfloc-stream/{__version__}")
        text = dump_settings(settings)
        self._mcap.add_metadata(S.METADATA_SETTINGS, {"yaml": text, S.CRC_KEY: S.crc32_hex(text.encode())})
        info = {"format": S.SESSION_FORMAT, "writer": f"zfloc-stream/{__version__}"}
        info.update({str(k): str(v) for k, v in (metadata or {}).items()})
        self._mcap.add_metadata(S.METADATA_SESSION, info)
        self._mcap.add_metadata(S.METADATA_ENVIRONMENT, environment.current())  # replays elsewhere say so
        self._floorplan_to_draw = floorplan  # published as a Grid with the first frame
        if floorplan is not None:
            self._attach_floorplan(floorplan)
            # A floorplan built with other settings (seed, primitive parameters) has other
            # primitives: log its settings so a replay rebuilds the same one.
            own = getattr(floorplan, "settings", None)
            if isinstance(own, Settings) and own != settings:
                text = dump_settings(own)
                self._mcap.add_metadata(S.METADATA_FLOORPLAN_SETTINGS, {"yaml": text, S.CRC_KEY: S.crc32_hex(text.encode())})
        self._file.flush()

    # --- context manager ---------------------------------------------------------------
    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()  # even after an error: a finished file with everything written so far

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        if self._failed:  # already reported: the file ends where the disk refused it
            self._sink.abandon()
            with contextlib.suppress(OSError):
                self._file.close()
            return
        try:
            self._sink.finish()
            self._file.close()
        except OSError as err:
            with contextlib.suppress(OSError):
                self._file.close()
            raise SessionLogError(f"{self.path}: writing the session failed: {err.strerror or err}") from None

    # --- inputs -------------------------------------------------------------------------
    def write_frame(self, index: int, frame: CameraFrame | LaserFrame) -> CameraFrame | LaserFrame:
        """Log one input frame; returns it as a reader will rebuild it (push that one)."""
        if not isinstance(frame, CameraFrame | LaserFrame):
            raise SessionLogError(f"cannot log a {type(frame).__name__}: expected CameraFrame or LaserFrame")
        ns = self._begin_frame(index, frame.timestamp)
        if isinstance(frame, CameraFrame):
            logged = self._write_camera(index, frame, ns)
        else:
            logged = self._write_laser(index, frame, ns)
        self._note_sensor(logged)
        self._end_frame(logged.timestamp, ns)
        return logged

    def _note_sensor(self, frame) -> None:
        if isinstance(frame, CameraFrame):
            self._sensor = (S.FRAME_CAMERA, "z", frame.T_odom_cam)
        else:
            self._sensor = (S.FRAME_LASER, "x", frame.T_odom_sensor)

    def copy_frame(self, record) -> None:
        """Log a frame read from a session (a reader FrameRecord) by copying its input
        messages as they are, so the new file replays exactly like the old one."""
        frame = record.frame
        ns = self._begin_frame(record.index, frame.timestamp, record.stamp_ns)
        axis = "z" if isinstance(frame, CameraFrame) else "x"
        defaults = {
            S.TOPIC_ODOMETRY: {S.HEADING_AXIS_KEY: axis},
            S.TOPIC_GROUND_TRUTH: {S.HEADING_AXIS_KEY: axis},
        }
        if isinstance(frame, LaserFrame):
            defaults[S.TOPIC_SCAN] = {S.RANGE_MIN_KEY: repr(float(frame.range_min)), S.RANGE_MAX_KEY: repr(float(frame.range_max))}
        for topic in S.INPUT_TOPICS:
            if topic in record.inputs:
                msg, meta = record.inputs[topic]
                ours = _OUR_CLASSES[msg.DESCRIPTOR.full_name].FromString(msg.SerializeToString())
                if topic == S.TOPIC_GROUND_TRUTH and ours.frame_id == LEGACY_MAP:
                    ours.frame_id = S.FRAME_MAP  # an older log's name for the map frame: one naming in the new file
                self._write(topic, ours, ns, record.index, {**meta, **defaults.get(topic, {})})
        self._note_sensor(frame)
        self._end_frame(frame.timestamp, ns)

    def _begin_frame(self, index: int, timestamp: float, ns: int | None = None) -> int:
        self._check_open()
        ns = S.seconds_to_ns(timestamp) if ns is None else ns
        if self._last_frame is not None and ns <= self._last_frame[1]:
            # Real logs repeat stamps (printed with few digits) or run backwards a little:
            # the frame keeps its own timestamp, its log time moves 1 ns past the previous
            # frame's so the file stays in arrival order and every frame stays its own.
            if not self._warned_time:
                warnings.warn(
                    f"{self.path}: frame {index} timestamp {timestamp} is not after the previous frame's "
                    f"({self._last_frame[0]}); kept in arrival order (warned once per session)",
                    stacklevel=3,
                )
                self._warned_time = True
            ns = self._last_frame[1] + 1
        self._batch = []
        self._close_chunk_first = self._frames_in_chunk >= self._cfg.chunk_max_frames  # bounds a crash's loss
        if self._close_chunk_first:
            self._frames_in_chunk = 0
        if self._floorplan_to_draw is not None:
            plan, self._floorplan_to_draw = self._floorplan_to_draw, None
            if all(hasattr(plan, a) for a in ("occupied", "origin", "resolution")):
                self._write(S.TOPIC_FLOORPLAN, S.occupancy_grid_msg(plan.occupied, plan.origin, plan.resolution, ns), ns, index)
        return ns

    def _end_frame(self, timestamp: float, ns: int) -> None:
        self._submit()
        self._last_frame = (timestamp, ns)
        self._frames_in_chunk += 1
        self.frames_written += 1

    def _submit(self, close_after: bool = False, then=None) -> None:
        batch, self._batch = self._batch, []
        close, self._close_chunk_first = self._close_chunk_first, False
        for listener in self._listeners:
            listener(batch)
        try:
            self._sink.submit(batch, close, close_after, then)
        except OSError as err:
            self._failed = True
            raise SessionLogError(f"{self.path}: writing the session failed: {err.strerror or err}") from None

    def _write_camera(self, index: int, frame: CameraFrame, ns: int) -> CameraFrame:
        h, w = frame.shape
        calib = S.calibration_to_msg(frame.K, w, h, ns)
        odom = S.pose_to_msg(frame.T_odom_cam, ns, S.FRAME_ODOM)
        gt = _truth_msg(index, frame.ground_truth, ns, "z")
        axis = {S.HEADING_AXIS_KEY: "z"}
        self._write(S.TOPIC_CALIBRATION, calib, ns, index)
        if frame.rgb is not None:
            self._write(S.TOPIC_IMAGE, S.image_to_msg(frame.rgb, ns), ns, index)
        if frame.depth is not None:
            self._write(S.TOPIC_DEPTH, S.depth_to_msg(frame.depth, ns), ns, index)
        if frame.labels is not None:
            self._write(S.TOPIC_LABELS, S.labels_to_msg(frame.labels, ns), ns, index)
        self._write(S.TOPIC_ODOMETRY, odom, ns, index, axis)
        if gt is not None:
            self._write(S.TOPIC_GROUND_TRUTH, gt, ns, index, axis)
        # Images and K are stored exactly (rgb8 / 32FC1 / mono8 bytes, K as doubles): only the
        # pose, the time and the ground truth change in the round trip, so the arrays are
        # reused instead of decoded again (a 640x480 frame saves a copy and a validation pass).
        T = S.matrix_from_pose(odom.pose)
        truth = None if gt is None else S.planar_pose_from_pose(gt.pose, "z")
        return CameraFrame(frame.depth, frame.labels, frame.K, T, S.ns_to_seconds(ns), ground_truth=truth, rgb=frame.rgb)

    def _write_laser(self, index: int, frame: LaserFrame, ns: int) -> LaserFrame:
        scan = S.scan_to_msg(frame.ranges, frame.angle_min, frame.angle_increment, ns)
        odom = S.pose_to_msg(frame.T_odom_sensor, ns, S.FRAME_ODOM)
        gt = _truth_msg(index, frame.ground_truth, ns, "x")
        limits = {S.RANGE_MIN_KEY: repr(float(frame.range_min)), S.RANGE_MAX_KEY: repr(float(frame.range_max))}
        axis = {S.HEADING_AXIS_KEY: "x"}
        self._write(S.TOPIC_SCAN, scan, ns, index, limits)
        self._write(S.TOPIC_ODOMETRY, odom, ns, index, axis)
        if gt is not None:
            self._write(S.TOPIC_GROUND_TRUTH, gt, ns, index, axis)
        return laser_frame_from_msgs(scan, float(frame.range_min), float(frame.range_max), odom, gt, "x", S.ns_to_seconds(ns))

    # --- outputs ------------------------------------------------------------------------
    def write_estimate(self, estimate: Estimate, bev=None, then=None) -> None:
        """Log the localizer's output for the frame just written. `bev`: a Localizer, a
        RollingBEV or a BevGrid; published every `logging.bev_every_n_frames` frames.
        then: called once these records are handed to the OS (on the writing thread with
        `logging.background`): a per-frame output written there is never ahead of the log."""
        self._check_open()
        ns = self._estimate_ns(estimate)
        seq = int(estimate.frame)
        self._batch = []
        tf = frame_transforms_msg(estimate, self._sensor, ns)
        if tf is not None:  # first: the frames exist when the pose and the BEV arrive
            self._write(S.TOPIC_TF, tf, ns, seq)
        if estimate.pose is not None:
            self._write(S.TOPIC_POSE, S.estimate_pose_to_msg(estimate, ns), ns, seq, {S.HEADING_AXIS_KEY: "x"})
        self._write(S.TOPIC_HYPOTHESES, S.hypotheses_to_msg(estimate, ns), ns, seq, {S.HEADING_AXIS_KEY: "x"})
        n = self._cfg.bev_every_n_frames
        if bev is not None and n > 0 and estimate.frame % n == 0:
            grid = bev_grid_of(bev)
            if grid is not None:
                self._write(S.TOPIC_BEV, S.grid_to_msg(grid, ns), ns, seq)
        self._write_json(S.TOPIC_STATUS, S.status_to_json(estimate), ns, seq)
        # The frame is complete: once chunk_max_frames frames are in the chunk it ends
        # here, not when the next frame begins, so a kill loses only frames in flight.
        full = self._frames_in_chunk >= self._cfg.chunk_max_frames
        if full:
            self._frames_in_chunk = 0
        self._submit(close_after=full, then=then)

    def _estimate_ns(self, estimate: Estimate) -> int:
        # Same log time as its frame's messages, even where float seconds cannot hold ns.
        if self._last_frame is not None and estimate.timestamp == self._last_frame[0]:
            return self._last_frame[1]
        return S.seconds_to_ns(estimate.timestamp)

    # --- records ------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise SessionLogError(f"session file {self.path} is already closed")

    def _write(self, topic: str, msg, ns: int, sequence: int, metadata: dict | None = None) -> None:
        cls = type(msg)
        meta = tuple(sorted((metadata or {}).items()))
        self._batch.append(Record(topic, cls.DESCRIPTOR.full_name, SchemaEncoding.Protobuf, cls, MessageEncoding.Protobuf, meta, ns, sequence, msg.SerializeToString()))

    def _write_json(self, topic: str, payload: dict, ns: int, sequence: int) -> None:
        self._batch.append(Record(topic, S.STATUS_SCHEMA_NAME, SchemaEncoding.JSONSchema, S.STATUS_JSON_SCHEMA_BYTES, MessageEncoding.JSON, (), ns, sequence, S.encode_status(payload)))

    def _attach_floorplan(self, floorplan) -> None:
        with tempfile.TemporaryDirectory(prefix="zfloc-floorplan-") as tmp:
            floorplan.write_ros(tmp, "floorplan")
            files = sorted(p for p in Path(tmp).iterdir() if p.is_file())
            if not any(p.suffix in (".yaml", ".yml") for p in files):
                raise SessionLogError("floorplan.write_ros wrote no YAML file: cannot embed the floorplan")
            checksums = {}
            for p in files:
                name, data = S.ATTACHMENT_FLOORPLAN_PREFIX + p.name, p.read_bytes()
                media_type = _MEDIA_TYPES.get(p.suffix, "application/octet-stream")
                self._mcap.add_attachment(create_time=0, log_time=0, name=name, media_type=media_type, data=data)
                checksums[name] = S.crc32_hex(data)
        # MCAP readers skip attachment CRCs: ours let read_session detect a damaged floorplan
        self._mcap.add_metadata(S.METADATA_CHECKSUMS, checksums)
