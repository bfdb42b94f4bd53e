"""Valid but unusual session files read right, or refused in one line (issue 44):
messages out of log-time order, a damaged first chunk under --salvage, depth in
millimetres, lens distortion, huge log times and poses."""

import warnings

import numpy as np
import pytest
from mcap.writer import Writer
from benchmarks.inputs.session_frames import camera_frames, laser_frames
from session_helpers import write_fake_session
from benchmarks.inputs.hostile_sessions import ORDERS, frame_messages, ordered, write_messages

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.errors import SessionLogError
from zfloc_stream.io.session import read_session


def _same_frames(got, frames):
    assert len(got) == len(frames)
    for rec, fr in zip(got, frames, strict=True):
        assert rec.frame.timestamp == pytest.approx(fr.timestamp)
        if hasattr(fr, "depth"):
            assert np.array_equal(np.nan_to_num(rec.frame.depth), np.nan_to_num(fr.depth))
            assert np.array_equal(rec.frame.labels, fr.labels)
            np.testing.assert_allclose(rec.frame.T_odom_cam, fr.T_odom_cam, atol=1e-9)
        else:
            np.testing.assert_allclose(rec.frame.ranges, fr.ranges)
        d = np.asarray(rec.frame.ground_truth) - fr.ground_truth
        d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
        np.testing.assert_allclose(d, 0, atol=1e-9)


# --- message order ----------------------------------------------------------------------------
@pytest.mark.parametrize("order", ORDERS)
def test_messages_out_of_log_time_order_lose_no_frame(tmp_path, order):
    """Issue 44: grouped by topic or shuffled, 49 of 50 frames were lost (read in file order)."""
    frames = camera_frames(50, seed=3, shape=(12, 16))
    path = tmp_path / f"{order}.mcap"
    write_messages(path, ordered(frame_messages(frames), order, np.random.default_rng(1)))
    session = read_session(path)
    got = list(session.records())
    _same_frames(got, frames)
    assert session.problems == []
    index = session.frame_index()  # the seek index groups the same way
    assert len(index) == 50 and index.problems == []
    _same_frames(list(session.records(17, 20)), frames[17:20])


def test_laser_topics_grouped_read_every_frame(tmp_path):
    frames = laser_frames(30, seed=2, beams=40)
    write_messages(tmp_path / "l.mcap", ordered(frame_messages(frames), "reversed-topic"))
    _same_frames(list(read_session(tmp_path / "l.mcap").records()), frames)


def test_our_own_files_read_exactly_as_in_file_order(tmp_path):
    """A file in log-time order reads message for message as before (ties in file order)."""
    from zfloc_stream.io.session.decoding import messages
    from zfloc_stream.io.session.mcap_file import file_records

    path = tmp_path / "ours.mcap"
    write_fake_session(path, camera_frames(12, seed=4, shape=(6, 8)), load_settings(overrides=["logging.chunk_max_frames=2"]))
    session = read_session(path)
    in_order = [(t, s) for t, s, _, _ in session._messages(())]
    in_file = [(t, s) for t, s, _, _ in messages(session, file_records(path, False, []))]
    assert in_order == in_file and len(in_order) > 12 * 4


def test_a_merge_beyond_the_memory_limit_is_refused_naming_the_setting(tmp_path):
    frames = camera_frames(30, seed=3, shape=(120, 160))  # 3 MB
    path = tmp_path / "shuffled.mcap"
    write_messages(path, ordered(frame_messages(frames), "shuffled", np.random.default_rng(2)), chunk_size=200_000)
    tight = load_settings(overrides=["logging.reorder_max_mb=1"])
    with pytest.raises(SessionLogError, match=r"shuffled\.mcap: .*out of log-time order.*logging\.reorder_max_mb") as err:
        list(read_session(path, settings=tight).records())
    assert "\n" not in str(err.value)
    assert len(list(read_session(path).records())) == 30  # the default limit (2 GiB) reads it


def test_a_file_without_chunk_index_out_of_order_warns(tmp_path):
    frames = camera_frames(10, seed=3, shape=(6, 8))
    msgs = ordered(frame_messages(frames), "topic")
    path = tmp_path / "flat.mcap"
    with open(path, "wb") as f:  # messages outside chunks: no index to read them in order by
        w = Writer(f, use_chunking=False)
        w.start()
        from benchmarks.inputs.hostile_sessions import CLASSES
        from mcap_protobuf.schema import build_file_descriptor_set

        ids = {}
        for topic, t, m in msgs:
            if topic not in ids:
                cls = CLASSES[topic]
                sid = w.register_schema(cls.DESCRIPTOR.full_name, "protobuf", build_file_descriptor_set(cls).SerializeToString())
                ids[topic] = w.register_channel(topic, "protobuf", sid)
            w.add_message(ids[topic], log_time=t, data=m.SerializeToString(), publish_time=t)
        w.finish()
    session = read_session(path)
    list(session.records())
    notes = [p for p in session.problems if "not in log-time order" in p]
    assert len(notes) == 1 and "no chunk index" in notes[0] and "dropped" in notes[0]


# --- salvage -----------------------------------------------------------------------------------
def _damage_first_chunk(path, how: str) -> None:
    session = read_session(path)
    c0 = min(session.summary.chunk_indexes, key=lambda c: c.chunk_start_offset)
    data = bytearray(path.read_bytes())
    if how == "all":
        for i in range(c0.chunk_start_offset, c0.chunk_start_offset + c0.chunk_length):
            data[i] = (data[i] * 7 + 13) & 255
    else:
        data[c0.chunk_start_offset + {"opcode": 0, "length": 3, "middle": c0.chunk_length // 2}[how]] ^= 0x5A
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["opcode", "length", "middle", "all"])
def test_salvage_reads_the_chunks_after_a_damaged_first_one(tmp_path, how):
    """Issue 44: a damaged first chunk (4 intact ones and the summary remain) salvaged
    nothing: the scan stopped there, or the channels defined in it were unknown after it."""
    frames = camera_frames(15, seed=2, shape=(12, 16))
    path = tmp_path / "five.mcap"
    write_fake_session(path, frames, load_settings(overrides=["logging.chunk_max_frames=3"]))
    _damage_first_chunk(path, how)
    with pytest.raises(SessionLogError, match="five.mcap"):
        list(read_session(path).records())
    session = read_session(path, salvage=True)
    got = list(session.records())
    assert [r.index for r in got] == list(range(12))
    _same_frames(got, [f for f in write_fake_session(tmp_path / "again.mcap", frames)][3:])
    assert len(session.problems) == 1 and session.problems[0].startswith("chunk skipped: damaged chunk at byte")
    assert session.settings is not None and session.info["source"] == "test"


# --- depth units -------------------------------------------------------------------------------
def test_float_depth_in_millimetres_is_converted_with_one_note(tmp_path):
    """Issue 44: float32 millimetres gave every frame 'initializing', exit 0, no warning."""
    frames = camera_frames(6, seed=3, shape=(12, 16))
    write_messages(tmp_path / "mm.mcap", frame_messages(frames, depth_scale=1000.0))
    session = read_session(tmp_path / "mm.mcap")
    got = list(session.records())
    assert len(got) == 6
    for rec, fr in zip(got, frames):
        np.testing.assert_allclose(rec.frame.depth, np.nan_to_num(fr.depth), rtol=1e-6)
    assert len(session.problems) == 1 and "millimetres" in session.problems[0] and "converted" in session.problems[0]


def test_depth_neither_metres_nor_millimetres_drops_frames_with_the_reason(tmp_path):
    frames = camera_frames(3, seed=3, shape=(12, 16))
    write_messages(tmp_path / "km.mcap", frame_messages(frames, depth_scale=1e6))  # 300 m .. 8 km medians
    session = read_session(tmp_path / "km.mcap")
    assert list(session.records()) == []
    assert all("implausible for an indoor camera" in p for p in session.problems) and len(session.problems) == 3


def test_16uc1_declared_over_float_data_is_one_error_line(tmp_path):
    frames = camera_frames(3, seed=3, shape=(12, 16))
    write_messages(tmp_path / "mislabelled.mcap", frame_messages(frames, depth_scale=1000.0, depth_encoding="16UC1-over-float"))
    with pytest.raises(SessionLogError, match=r"mislabelled\.mcap: .*declared 16UC1 but holds 4 bytes per pixel") as err:
        list(read_session(tmp_path / "mislabelled.mcap").records())
    assert "\n" not in str(err.value)


def test_camera_frames_refuse_float_millimetres_said_to_be_metres():
    from zfloc_stream.errors import FrameError
    from zfloc_stream.frames import CameraFrame

    fr = camera_frames(1, seed=1, shape=(12, 16))[0]
    with pytest.raises(FrameError, match=r"median reading is .* implausible .*depth_unit='mm'"):
        CameraFrame(fr.depth * 1000, fr.labels, fr.K, fr.T_odom_cam, 0.0)
    mm = CameraFrame(fr.depth * 1000, fr.labels, fr.K, fr.T_odom_cam, 0.0, depth_unit="mm")
    np.testing.assert_allclose(mm.depth, fr.depth, rtol=1e-6)


# --- lens distortion ---------------------------------------------------------------------------
@pytest.mark.parametrize("model,D", [("plumb_bob", (-0.28, 0.07, 0.001, -0.0005, 0.0)),
                                     ("rational_polynomial", (0.3, -0.1, 0.001, 0.002, 0.01, 0.6, -0.05, 0.02)),
                                     ("equidistant", (0.05, -0.01, 0.002, -0.0005))])
def test_undistortion_matches_opencv(model, D):
    import cv2

    from zfloc_stream.frontend import lens

    h, w = 48, 64
    K = np.array([[40.0, 0, 31.5], [0, 41.0, 24.2], [0, 0, 1]])
    src, inside = lens._map(K.tobytes(), model, D, (h, w))
    if model == "equidistant":
        mx, my = cv2.fisheye.initUndistortRectifyMap(K, np.array(D), np.eye(3), K, (w, h), cv2.CV_32FC1)
    else:
        mx, my = cv2.initUndistortRectifyMap(K, np.array(D), None, K, (w, h), cv2.CV_32FC1)
    ref_in = (np.rint(mx) >= 0) & (np.rint(mx) < w) & (np.rint(my) >= 0) & (np.rint(my) < h)
    ref = np.rint(my).astype(int) * w + np.rint(mx).astype(int)
    agree = (inside == ref_in) & (~inside | (src == ref))
    assert agree.mean() > 0.99  # float32 maps round a few half-pixels the other way
    assert inside.mean() > 0.8 and (src != np.arange(h * w).reshape(h, w)).mean() > 0.3  # pixels moved


def test_distorted_sessions_are_undistorted_and_unknown_models_noted(tmp_path):
    from zfloc_stream.frontend import lens

    frames = camera_frames(4, seed=3, shape=(24, 32))
    D = (-0.25, 0.05, 0.0, 0.0, 0.0)
    write_messages(tmp_path / "lens.mcap", frame_messages(frames, distortion=D))
    got = list(read_session(tmp_path / "lens.mcap").records())
    for rec, fr in zip(got, frames, strict=True):
        d, lab = lens.undistort([np.nan_to_num(fr.depth), fr.labels], fr.K, "plumb_bob", D)
        assert np.array_equal(np.nan_to_num(rec.frame.depth), d) and np.array_equal(rec.frame.labels, lab)
        assert not np.array_equal(d, np.nan_to_num(fr.depth))
    write_messages(tmp_path / "odd.mcap", frame_messages(frames, distortion=(0.1, 0.2), model="mei"))
    session = read_session(tmp_path / "odd.mcap")
    got = list(session.records())
    assert np.array_equal(np.nan_to_num(got[0].frame.depth), np.nan_to_num(frames[0].depth))
    assert len(session.problems) == 1 and "'mei' is not supported" in session.problems[0] and "ignored" in session.problems[0]
    write_messages(tmp_path / "nan.mcap", frame_messages(frames, distortion=(np.nan, 0.0)))
    with pytest.raises(SessionLogError, match="calibration D .* NaN"):
        list(read_session(tmp_path / "nan.mcap").records())


# --- huge values ------------------------------------------------------------------------------
def _huge_x(i, T):
    if i < 3:
        return T
    T = T.copy()
    T[0, 3] = 1e300
    return T


def test_huge_odometry_is_a_frame_error_at_the_api_and_a_dropped_frame_in_a_session(tmp_path):
    """Issue 44: odometry x = 1e300 raised OverflowError in the scrolling grid."""
    from zfloc_stream.errors import FrameError
    from zfloc_stream.frames import LaserFrame
    from zfloc_stream.frontend.scrolling_grid import ScrollingGrid

    fr = laser_frames(1, beams=20)[0]
    with pytest.raises(FrameError, match=r"T_odom_sensor position .* beyond 1e\+09 m"):
        LaserFrame(fr.ranges, fr.angle_min, fr.angle_increment, fr.range_min, fr.range_max, _huge_x(5, fr.T_odom_sensor), 0.0)
    grid = ScrollingGrid(16, 0.05)
    with pytest.raises(FrameError, match="beyond the map's cells"):
        grid.centre_on(np.array([1e300, 0.0]), 2)
    assert grid.ix0 is None  # refused before any change
    write_messages(tmp_path / "huge.mcap", frame_messages(laser_frames(6, beams=20), pose_edit=_huge_x))
    session = read_session(tmp_path / "huge.mcap")
    assert len(list(session.records())) == 3
    assert len(session.problems) == 3 and all("beyond 1e+09 m" in p for p in session.problems)


def test_times_beyond_2_63_ns_are_one_error_line(tmp_path):
    from benchmarks.inputs.hostile_sessions import with_timestamps

    write_messages(tmp_path / "late.mcap", frame_messages(with_timestamps(laser_frames(4, beams=20), t0=9.3e9)))
    session = read_session(tmp_path / "late.mcap")
    with pytest.raises(SessionLogError, match=r"late\.mcap: /odometry message at log time \d+: its time \d+ ns is beyond 2\^63 ns"):
        list(session.records())
    with pytest.raises(SessionLogError, match="beyond 2\\^63 ns"):
        session.frame_index()
    # log times beyond 2^63 (MCAP allows up to 2^64) with sane header stamps read as usual
    write_messages(tmp_path / "log.mcap", frame_messages(laser_frames(4, beams=20)), log_time=lambda i, t: t + (1 << 63))
    assert len(list(read_session(tmp_path / "log.mcap").records())) == 4
    from zfloc_stream.io.session import schemas as S

    with pytest.raises(SessionLogError, match="before 2\\^63 ns"):
        S.seconds_to_ns(1e300)


@pytest.mark.slow
def test_cli_on_huge_odometry_and_late_times_warns_or_fails_in_one_line(tmp_path):
    import subprocess
    import sys

    from benchmarks.inputs.hostile_sessions import with_timestamps

    from zfloc_stream.sim import build_scene

    plan = build_scene("rooms", seed=0).floorplan.write_ros(tmp_path / "plan", "map")
    write_messages(tmp_path / "huge.mcap", frame_messages(laser_frames(8, beams=90), pose_edit=_huge_x))
    write_messages(tmp_path / "late.mcap", frame_messages(with_timestamps(laser_frames(4, beams=20), t0=9.3e9)))

    def run(name):
        return subprocess.run([sys.executable, "-m", "zfloc_stream.tools.cli", "run", "--floorplan", str(plan), "--input",
                               str(tmp_path / name), "--out", str(tmp_path / name.replace(".", "-")), "--no-progress"],
                              capture_output=True, text=True, timeout=300)

    proc = run("huge.mcap")
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr
    assert "beyond 1e+09 m" in proc.stderr and "5 frame(s) dropped" in proc.stderr
    proc = run("late.mcap")
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1 and "error: " in lines[0] and "2^63" in lines[0], proc.stderr


# --- ROS 2 bags: the same families ---------------------------------------------------------------
def _bag(tmp_path, name="bag.mcap", n=30, **kw):
    from ros2_bag import mount, write_sensor_bag

    frames = camera_frames(n, seed=3, shape=(24, 32), labels=False)
    path = tmp_path / name
    write_sensor_bag(path, frames, mount(0.1, 0.0, 1.0, optical=True), kind="depth", depth_mm=False, **kw)
    return path, frames


def _bag_frames(path, settings=None):
    from zfloc_stream.io.datasets.ros2 import bag_sequence

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        seq = bag_sequence(path, settings or Settings())
        frames = list(seq.frames())
    return frames, [str(w.message) for w in caught]


@pytest.mark.parametrize("order", ["topic", "shuffled"])
def test_bags_out_of_log_time_order_read_the_same_frames(tmp_path, order):
    from benchmarks.inputs.hostile_sessions import rewrite

    path, _ = _bag(tmp_path)
    want, _ = _bag_frames(path)
    rewrite(path, tmp_path / f"{order}.mcap", order, np.random.default_rng(4))
    got, caught = _bag_frames(tmp_path / f"{order}.mcap")
    assert caught == [] and len(got) == len(want) == 30
    for a, b in zip(got, want):
        assert a.timestamp == b.timestamp and np.array_equal(a.depth, b.depth) and np.array_equal(a.T_odom_cam, b.T_odom_cam)


def test_a_shuffled_bag_beyond_the_reorder_limit_is_refused(tmp_path, monkeypatch):
    from benchmarks.inputs.hostile_sessions import rewrite

    import zfloc_stream.io.datasets.ros2 as ros2
    from zfloc_stream.errors import InputError

    path, _ = _bag(tmp_path, n=40)
    rewrite(path, tmp_path / "s.mcap", "shuffled", np.random.default_rng(4), chunk_size=2000)
    monkeypatch.setattr(ros2, "MIB", 1024)  # a 1 KiB 'MiB': the small bag stands in for a large one
    with pytest.raises(InputError, match=r"s\.mcap: .*out of log-time order.*logging\.reorder_max_mb"):
        ros2.bag_sequence(tmp_path / "s.mcap", load_settings(overrides=["logging.reorder_max_mb=1"]))
    assert len(_bag_frames(tmp_path / "s.mcap")[0]) == 40  # within the default limit


def test_bag_depth_in_float_millimetres_is_converted_with_one_warning(tmp_path):
    path, frames = _bag(tmp_path, depth_scale=1000.0)
    got, caught = _bag_frames(path)
    assert len(got) == 30
    np.testing.assert_allclose(got[4].depth, np.nan_to_num(frames[4].depth), rtol=1e-6)
    assert len([c for c in caught if "millimetres" in c and "converted" in c]) == 1


def test_bag_camera_info_distortion_is_removed(tmp_path):
    from zfloc_stream.frontend import lens

    D = (-0.2, 0.04, 0.0, 0.0, 0.0)
    path, frames = _bag(tmp_path, distortion=D)
    got, caught = _bag_frames(path)
    assert caught == []
    want = lens.undistort([np.nan_to_num(frames[2].depth).astype(np.float32)], frames[2].K, "plumb_bob", D)[0]
    assert np.array_equal(got[2].depth, want)
