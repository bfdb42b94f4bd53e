"""Reading long sessions: the frame index, records(start, stop) from the chunk holding
`start`, outputs=False, and mcap Sequences built from the index. Every read must equal the
matching slice of a sequential read from the file's start (frames bit for bit, stamps,
frame numbers, logged outputs)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from mcap.writer import Writer
from mcap_protobuf.schema import build_file_descriptor_set
from benchmarks.inputs.session_frames import camera_frames, laser_frames
from session_helpers import write_fake_session

from benchmarks.shared_data import SHARED_DATA

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.io.datasets.mcap import session_sequence
from zfloc_stream.errors import SessionLogError
from zfloc_stream.io.session import read_session
from zfloc_stream.io.session import frame_index
from zfloc_stream.io.session import stamps
from zfloc_stream.io.session import reader as R
from zfloc_stream.io.session import schemas as S

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = sorted((ROOT / "replay").glob("*.mcap"))
SHARED = sorted((SHARED_DATA / "sessions").glob("*/session.mcap"))  # other tools' files, when mounted


def _same_message(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return a == b if isinstance(a, dict) else a.SerializeToString() == b.SerializeToString()


def _same_array(a, b) -> bool:
    if a is None or b is None:
        return a is b
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def assert_same_records(got, want):
    assert [r.index for r in got] == [r.index for r in want]
    assert [r.stamp_ns for r in got] == [r.stamp_ns for r in want]
    for a, b in zip(got, want, strict=True):
        assert type(a.frame) is type(b.frame)
        for name, value in vars(a.frame).items():
            other = getattr(b.frame, name)
            if isinstance(value, np.ndarray) or isinstance(other, np.ndarray):
                assert _same_array(value, other), (a.index, name)
            else:
                assert value == other, (a.index, name)
        for name in ("status", "pose", "hypotheses", "bev"):
            assert _same_message(getattr(a.outputs, name), getattr(b.outputs, name)), (a.index, name)
        assert a.inputs.keys() == b.inputs.keys()
        for topic, (msg, meta) in a.inputs.items():
            assert meta == b.inputs[topic][1] and _same_message(msg, b.inputs[topic][0]), (a.index, topic)


def _slices(n: int):
    return [(0, None), (1, None), (n // 2, n // 2 + 3), (n - 1, n), (n // 3, 2 * n // 3), (n - 5, n + 10)]


def _foreign_multichunk(path, n: int = 24, ours: bool = False):
    """Another tool's file in small chunks: calibration once, odometry every other frame
    (interpolated for the rest), a repeated stamp, header stamps earlier than log times,
    and one frame whose depth has no valid reading (a read drops it). ours=True: the same
    marked as written by zfloc-stream (whose files hold only valid frames: no bad frame),
    with a /zfloc/pose output per frame; its bulky topics are never decoded by the index."""
    frames = camera_frames(n, seed=11, labels=False)
    frames[7] = dataclasses.replace(frames[7], timestamp=frames[6].timestamp)  # repeated stamp
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=2000)
        w.start()
        if ours:
            w.add_metadata(S.METADATA_SESSION, {"writer": "zfloc-stream/test"})
        ids = {}
        for topic, cls in ((S.TOPIC_ODOMETRY, PoseInFrame), (S.TOPIC_GROUND_TRUTH, PoseInFrame), (S.TOPIC_POSE, PoseInFrame),
                           (S.TOPIC_CALIBRATION, CameraCalibration), (S.TOPIC_DEPTH, RawImage)):
            sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
            ids[topic] = w.register_channel(topic, "protobuf", sid)
        for i, fr in enumerate(frames):
            ns = S.seconds_to_ns(fr.timestamp)
            depth = np.zeros_like(fr.depth) if i == 12 and not ours else fr.depth
            msgs = [(S.TOPIC_DEPTH, S.depth_to_msg(depth, ns))]
            if i == 0:
                msgs.append((S.TOPIC_CALIBRATION, S.calibration_to_msg(fr.K, fr.depth.shape[1], fr.depth.shape[0], ns)))
            if i % 2 == 0 or i in (7, n - 1):
                msgs.append((S.TOPIC_ODOMETRY, S.pose_to_msg(fr.T_odom_cam, ns, "odom")))
            msgs.append((S.TOPIC_GROUND_TRUTH, PoseInFrame(timestamp=S.to_stamp(ns), frame_id="floorplan",
                                                           pose=S.planar_pose_to_pose(fr.ground_truth, "z"))))
            if ours:
                msgs.append((S.TOPIC_POSE, S.pose_to_msg(fr.T_odom_cam, ns, "floorplan")))
            for topic, m in msgs:
                w.add_message(ids[topic], log_time=ns + 5_000_000 + i, data=m.SerializeToString(), publish_time=ns)
        w.finish()


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, Path]:
    """Sessions in many chunks: ours (camera, laser, repeated stamps) and a foreign one."""
    tmp = tmp_path_factory.mktemp("seek")
    small = load_settings(overrides=["logging.chunk_max_frames=3", "logging.bev_every_n_frames=2"])
    out = {"camera": tmp / "camera.mcap", "laser": tmp / "laser.mcap", "repeated": tmp / "repeated.mcap", "foreign": tmp / "foreign.mcap",
           "ours-like": tmp / "ours-like.mcap"}
    write_fake_session(out["camera"], camera_frames(31, seed=4), small)
    write_fake_session(out["laser"], laser_frames(29, seed=5), small)
    # stamps printed with few digits: runs of equal stamps, some across chunk boundaries
    frames = [dataclasses.replace(f, timestamp=1.0 + 0.1 * (i // 4)) for i, f in enumerate(camera_frames(22, seed=6))]
    with pytest.warns(UserWarning, match="kept in arrival order"):
        write_fake_session(out["repeated"], frames, small)
    _foreign_multichunk(out["foreign"])
    _foreign_multichunk(out["ours-like"], ours=True)
    return out


def _paths(written):
    return [*SAMPLES, *SHARED, *written.values()]


def test_every_written_session_has_many_chunks(written):
    for path in written.values():
        assert len(read_session(path).summary.chunk_indexes) >= 5, path


def test_records_slices_equal_a_sequential_read(written):
    for path in _paths(written):
        session = read_session(path)
        full = list(session.records(seek=False))
        assert session.frame_index() is not None and len(session.frame_index()) == len(full), path
        for start, stop in _slices(len(full)):
            got = list(session.records(start, stop))
            assert_same_records(got, full[start:stop])


def test_frames_without_outputs_equal_the_frames_of_a_full_read(written):
    for path in _paths(written):
        session = read_session(path)
        full = list(session.records(seek=False))
        for start, stop in ((0, None), (len(full) // 2, None)):
            for seek in (True, False):
                light = list(session.records(start, stop, outputs=False, seek=seek))
                assert all(r.outputs == R.LoggedOutputs() for r in light)
                assert_same_records([dataclasses.replace(r, outputs=R.LoggedOutputs()) for r in full[start:stop]], light)


def test_foreign_file_drops_and_numbering_match(written):
    session = read_session(written["foreign"])
    full = list(session.records(seek=False))
    assert len(full) == 23  # frame 12 (no valid depth reading) dropped
    assert any("no valid reading" in p for p in session.problems)
    assert any("no valid reading" in p for p in session.frame_index().problems)
    assert_same_records(list(session.records(12, 15)), full[12:15])


def test_sequence_from_the_index_equals_a_full_decode(written):
    for path in _paths(written):
        full = list(read_session(path).records(seek=False, outputs=False))
        truth = np.array([np.full(3, np.nan) if r.frame.ground_truth is None else r.frame.ground_truth for r in full])
        seq = session_sequence(path, Settings(), floorplan=object())
        assert seq.n_frames == len(full), path
        assert seq.ground_truth.tobytes() == truth.astype(float).tobytes(), path
        laser = any(r.frame.__class__.__name__ == "LaserFrame" for r in full)
        assert seq.settings_overrides == ({"estimator": {"scale_mode": "fixed"}} if laser else {})
        assert seq.needs_depth_network is False
        n = len(full)
        got = list(seq.frames(n - 4, n))
        assert [f.timestamp for f in got] == [r.frame.timestamp for r in full[n - 4 :]]
        assert all(_same_array(a.T_odom_cam if hasattr(a, "T_odom_cam") else a.T_odom_sensor,
                               b.frame.T_odom_cam if hasattr(b.frame, "T_odom_cam") else b.frame.T_odom_sensor)
                   for a, b in zip(got, full[n - 4 :], strict=True))


def test_rgb_only_session_sequence_flags_the_depth_network(tmp_path):
    rng = np.random.default_rng(0)
    frames = [dataclasses.replace(f, depth=None, labels=None, rgb=rng.integers(0, 255, (24, 32, 3), dtype=np.uint8))
              for f in camera_frames(5, seed=8)]
    write_fake_session(tmp_path / "rgb.mcap", frames)
    seq = session_sequence(tmp_path / "rgb.mcap", Settings(), floorplan=object())
    assert seq.n_frames == 5 and seq.needs_depth_network
    assert seq.settings_overrides == {"estimator": {"scale_mode": "prior"}}


def test_a_deep_slice_reads_only_the_chunks_that_hold_it(written, monkeypatch):
    session = read_session(written["camera"])
    index = session.frame_index()
    n_chunks = len(session.summary.chunk_indexes)
    read = []
    original = frame_index.chunk_messages
    monkeypatch.setattr(frame_index, "chunk_messages", lambda path, f, chunk: read.append(chunk.chunk_start_offset) or original(path, f, chunk))
    got = list(session.records(len(index) - 2, len(index)))
    assert len(got) == 2 and 1 <= len(read) <= 2 < n_chunks  # the last chunk (and the one before, at most)
    read.clear()
    list(session.fresh().frames(len(index) - 2))  # fresh() shares the index: no second pass
    assert 1 <= len(read) <= 2


def test_files_without_a_chunk_index_read_sequentially(tmp_path):
    frames = camera_frames(6, seed=9)
    with open(tmp_path / "flat.mcap", "wb") as f:  # messages outside chunks: no chunk index
        w = Writer(f, use_chunking=False)
        w.start()
        ids = {}
        for topic, cls in ((S.TOPIC_ODOMETRY, PoseInFrame), (S.TOPIC_CALIBRATION, CameraCalibration), (S.TOPIC_DEPTH, RawImage)):
            sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
            ids[topic] = w.register_channel(topic, "protobuf", sid)
        for fr in frames:
            ns = S.seconds_to_ns(fr.timestamp)
            for topic, m in ((S.TOPIC_DEPTH, S.depth_to_msg(fr.depth, ns)), (S.TOPIC_ODOMETRY, S.pose_to_msg(fr.T_odom_cam, ns, "odom")),
                             (S.TOPIC_CALIBRATION, S.calibration_to_msg(fr.K, 32, 24, ns))):
                w.add_message(ids[topic], log_time=ns, data=m.SerializeToString(), publish_time=ns)
        w.finish()
    session = read_session(tmp_path / "flat.mcap")
    assert session.frame_index() is None
    assert_same_records(list(session.records(3, 5)), list(session.records(seek=False))[3:5])
    assert session_sequence(tmp_path / "flat.mcap", Settings(), floorplan=object()).n_frames == 6


def test_salvage_never_seeks(written, tmp_path):
    data = written["camera"].read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: int(len(data) * 0.7)])
    session = read_session(tmp_path / "cut.mcap", salvage=True)
    assert session.frame_index() is None
    full = list(session.records())
    assert len(full) > 5 and [r.index for r in session.records(3, 5)] == [3, 4]


def test_header_stamps_read_from_the_bytes_match_the_decoder():
    msg = S.depth_to_msg(np.ones((3, 4), np.float32), 1_234_567_890_123)
    field = stamps.timestamp_field_number(dataclasses.make_dataclass("Sch", ["name", "data"])("foxglove.RawImage", build_file_descriptor_set(RawImage).SerializeToString()))
    assert field == 1
    cases = [
        msg.SerializeToString(),
        RawImage(width=3, data=b"\x01" * 300).SerializeToString(),  # no timestamp
        # fields out of order and the timestamp twice: protobuf merges the occurrences
        RawImage(width=4, encoding="32FC1").SerializeToString() + RawImage(timestamp=S.to_stamp(5)).SerializeToString()
        + RawImage(data=b"xy").SerializeToString() + b"\x0a\x02\x10\x07",
        RawImage(timestamp=S.Timestamp(seconds=-3, nanos=5)).SerializeToString(),
    ]
    for data in cases:
        decoded = RawImage.FromString(data)
        assert stamps.scan_stamp(data, 1) == (decoded.HasField("timestamp"), S.from_stamp(decoded.timestamp))
    for bad in (msg.SerializeToString()[:-3], b"\x0a\xff"):
        with pytest.raises((ValueError, IndexError)):
            stamps.scan_stamp(bad, 1)


def test_a_damaged_chunk_is_one_line_error_in_every_path(written, tmp_path):
    data = bytearray(written["camera"].read_bytes())
    chunk = sorted(read_session(written["camera"]).summary.chunk_indexes, key=lambda c: c.chunk_start_offset)[-2]
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle : middle + 8] = bytes(255 - b for b in data[middle : middle + 8])
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    for read in (lambda s: list(s.records(seek=False)), lambda s: list(s.records(20)), lambda s: s.frame_index(),
                 lambda s: session_sequence(s.path, Settings(), floorplan=object())):
        with pytest.raises(SessionLogError, match=r"bad\.mcap: .*(damaged|cannot)") as err:
            read(read_session(tmp_path / "bad.mcap"))
        assert "\n" not in str(err.value)
