"""Session files written the way another tool (or an attacker) might: messages grouped by
topic or shuffled in the file, depth in millimetres as float32 or mislabelled, lens
distortion, huge log times and poses. Used by tests/test_session_hostile.py, the
session fuzz test (tests/test_session_fuzz.py) and benchmarks/bench_session_order.py."""

from __future__ import annotations

import dataclasses

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.writer import CompressionType, Writer
from mcap_protobuf.schema import build_file_descriptor_set

from zfloc_stream.io.session import schemas as S

CLASSES = {S.TOPIC_ODOMETRY: PoseInFrame, S.TOPIC_GROUND_TRUTH: PoseInFrame, S.TOPIC_CALIBRATION: CameraCalibration,
           S.TOPIC_DEPTH: RawImage, S.TOPIC_LABELS: RawImage, S.TOPIC_SCAN: LaserScan}
ORDERS = ("time", "topic", "reversed-topic", "shuffled")


def frame_messages(frames, depth_scale: float = 1.0, depth_encoding: str = "32FC1", distortion=None,
                   model: str = "plumb_bob", pose_edit=None, labels: bool = True) -> list[tuple[str, int, object]]:
    """(topic, log time ns, message) of camera or laser frames, in recording order; log
    time = header stamp + 5 ms. depth_scale multiplies depth (1000: millimetres) before it is
    stored as `depth_encoding` ('32FC1', '16UC1', or '16UC1-over-float': float32 bytes
    declared 16UC1). distortion: the calibration's D. pose_edit(i, T) -> T edits odometry."""
    out = []
    for i, fr in enumerate(frames):
        ns = int(round(fr.timestamp * 1e9))  # (not seconds_to_ns: hostile times are written too)
        T = fr.T_odom_cam if hasattr(fr, "T_odom_cam") else fr.T_odom_sensor
        T = T if pose_edit is None else pose_edit(i, T)
        msgs = [(S.TOPIC_ODOMETRY, S.pose_to_msg(T, ns, "odom"))]
        if fr.ground_truth is not None:
            axis = "z" if hasattr(fr, "T_odom_cam") else "x"
            msgs.append((S.TOPIC_GROUND_TRUTH, PoseInFrame(timestamp=S.to_stamp(ns), frame_id="floorplan",
                                                           pose=S.planar_pose_to_pose(fr.ground_truth, axis))))
        if hasattr(fr, "ranges"):
            msgs.append((S.TOPIC_SCAN, S.scan_to_msg(fr.ranges, fr.angle_min, fr.angle_increment, ns)))
        else:
            h, w = fr.depth.shape
            calib = S.calibration_to_msg(fr.K, w, h, ns)
            if distortion is not None:
                del calib.D[:]
                calib.D.extend(float(v) for v in distortion)
                calib.distortion_model = model
            msgs.append((S.TOPIC_CALIBRATION, calib))
            with np.errstate(all="ignore"):  # hostile scales overflow on purpose
                d = np.nan_to_num(fr.depth, nan=0.0) * depth_scale
                u16 = np.round(d).astype("<u2")
            if depth_encoding == "32FC1":
                msgs.append((S.TOPIC_DEPTH, S.depth_to_msg(d, ns)))
            elif depth_encoding == "16UC1":
                data = u16.tobytes()
                msgs.append((S.TOPIC_DEPTH, RawImage(timestamp=S.to_stamp(ns), frame_id="camera", width=w, height=h,
                                                     encoding="16UC1", step=2 * w, data=data)))
            else:  # float32 bytes declared 16UC1 (rows as the floats need them)
                msgs.append((S.TOPIC_DEPTH, RawImage(timestamp=S.to_stamp(ns), frame_id="camera", width=w, height=h,
                                                     encoding="16UC1", step=4 * w, data=d.astype("<f4").tobytes())))
            if labels and fr.labels is not None:
                msgs.append((S.TOPIC_LABELS, S.labels_to_msg(fr.labels, ns)))
        out += [(topic, ns + 5_000_000, m) for topic, m in msgs]
    return out


def ordered(msgs, order: str, rng: np.random.Generator | None = None) -> list:
    """The messages as a file holds them: 'time' (as recorded), 'topic' (all of one topic,
    then the next), 'reversed-topic' (topics in reverse order of first appearance),
    'shuffled' (any order)."""
    if order == "time":
        return list(msgs)
    if order in ("topic", "reversed-topic"):
        topics = list(dict.fromkeys(t for t, _, _ in msgs))
        topics = topics[::-1] if order == "reversed-topic" else topics
        return [m for t in topics for m in msgs if m[0] == t]
    if order == "shuffled":
        rng = rng or np.random.default_rng(0)
        return [msgs[i] for i in rng.permutation(len(msgs))]
    raise ValueError(order)


def write_messages(path, msgs, chunk_size: int = 4000, compression: str = "zstd", metadata: dict | None = None,
                   log_time=None) -> None:
    """An MCAP file of (topic, log time, message) in the given order; log_time(i, t)
    replaces message i's log time."""
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=chunk_size, compression=CompressionType[compression.upper()])
        w.start()
        for name, data in (metadata or {}).items():
            w.add_metadata(name, data)
        ids = {}
        for i, (topic, t, m) in enumerate(msgs):
            if topic not in ids:
                cls = CLASSES[topic]
                sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
                ids[topic] = w.register_channel(topic, "protobuf", sid)
            t = t if log_time is None else log_time(i, t)
            w.add_message(ids[topic], log_time=t, data=m.SerializeToString(), publish_time=t)
        w.finish()


def with_timestamps(frames, t0: float = 0.5, dt: float = 0.1):
    return [dataclasses.replace(f, timestamp=t0 + dt * i) for i, f in enumerate(frames)]


def rewrite(src, dst, order: str, rng: np.random.Generator | None = None, chunk_size: int = 4000) -> None:
    """Any MCAP file (a session, a ROS 2 bag) with its messages rewritten in another order
    (see `ordered`; topics are the channels' topics), schemas and channels as they were."""
    from mcap.reader import make_reader

    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        items = [(ch.topic, m.log_time, (ch, m)) for _, ch, m in reader.iter_messages(log_time_order=False)]
        metadata = list(reader.iter_metadata())
        profile = reader.get_header().profile
    with open(dst, "wb") as f:
        w = Writer(f, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        w.start(profile=profile)
        schema_ids = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
        channel_ids = {cid: w.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0), dict(c.metadata))
                       for cid, c in summary.channels.items()}
        for m in metadata:
            w.add_metadata(m.name, dict(m.metadata))
        for _, _, (ch, m) in ordered(items, order, rng):
            w.add_message(channel_ids[ch.id], log_time=m.log_time, data=m.data, publish_time=m.publish_time, sequence=m.sequence)
        w.finish()


def hostile_session(rng: np.random.Generator, path, small: bool = True) -> str:
    """One seeded session of the issue-44 families, written to path; returns what it is.
    Families: message order, depth units and encodings, lens distortion, huge or
    non-finite poses, times near and beyond 2^63 ns, a damaged chunk; mixed at random."""
    from benchmarks.inputs.session_frames import camera_frames, laser_frames

    n = int(rng.integers(3, 12))
    laser = rng.random() < 0.3
    seed = int(rng.integers(1 << 30))
    frames = laser_frames(n, seed=seed, beams=int(rng.integers(5, 40))) if laser else \
        camera_frames(n, seed=seed, shape=(int(rng.integers(4, 16)), int(rng.integers(8, 24))))
    what = []
    kw = {}
    if not laser:
        scale = float(rng.choice([1.0, 1.0, 10.0, 100.0, 1000.0, 1e6, -1.0, 1e40]))
        kw["depth_scale"] = scale
        kw["depth_encoding"] = str(rng.choice(["32FC1", "32FC1", "16UC1", "16UC1-over-float"]))
        if rng.random() < 0.4:
            k = int(rng.choice([2, 4, 5, 8, 14]))
            kw["distortion"] = rng.normal(scale=float(rng.choice([0.05, 1.0, 1e6])), size=k)
            kw["model"] = str(rng.choice(["plumb_bob", "rational_polynomial", "equidistant", "kannala_brandt", "mei", ""]))
        what.append(f"depth x{scale:g} as {kw['depth_encoding']}, D={kw.get('model', '-')}")
    if rng.random() < 0.3:
        bad = float(rng.choice([1e300, -1e300, 1e20, 1e9, 2e9, np.inf, np.nan]))
        at = int(rng.integers(n))
        axis = int(rng.integers(3))

        def pose_edit(i, T, at=at, bad=bad, axis=axis):
            if i < at:
                return T
            T = T.copy()
            T[axis, 3] = bad
            return T

        kw["pose_edit"] = pose_edit
        what.append(f"pose[{axis}]={bad:g} from frame {at}")
    t0 = float(rng.choice([0.5, 0.5, 9.2e9, 9.3e9, 1.8e10]))
    if t0 != 0.5:
        frames = with_timestamps(frames, t0=t0, dt=float(rng.choice([0.1, 1e-9, 0.0])))
        what.append(f"t0={t0:g}")
    msgs = frame_messages(frames, **kw)
    order = str(rng.choice(ORDERS))
    msgs = ordered(msgs, order, rng)
    log_time = None
    if rng.random() < 0.15:
        log_time = lambda i, t: min(t + (1 << 63), (1 << 64) - 1)  # noqa: E731
        what.append("log times beyond 2^63")
    write_messages(path, msgs, chunk_size=int(rng.choice([500, 4000, 100_000])), log_time=lambda i, t: min(
        (t if log_time is None else log_time(i, t)), (1 << 64) - 1))
    what.append(order)
    if rng.random() < 0.2:  # damage one chunk (the first, or any)
        from mcap.reader import make_reader

        with open(path, "rb") as f:
            chunks = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
        c = chunks[0] if rng.random() < 0.5 else chunks[int(rng.integers(len(chunks)))]
        data = bytearray(open(path, "rb").read())
        pos = c.chunk_start_offset + int(rng.integers(c.chunk_length))
        data[pos] ^= int(rng.integers(1, 256))
        open(path, "wb").write(bytes(data))
        what.append(f"byte {pos} of a chunk flipped")
    return "; ".join(what)
