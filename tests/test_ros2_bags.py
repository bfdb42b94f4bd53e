"""ROS 2 bags written with mcap-ros2-support's writer: a laser at 15 Hz and a depth camera,
odometry at its own rate and stamps, /tf_static mounts; each localizes end to end like the
protobuf session of the same frames."""

import warnings

import numpy as np
import pytest

from ros2_bag import BagWriter, mount, write_sensor_bag
from zfloc_stream import Localizer, load_settings
from zfloc_stream.io.datasets import detect_source, open_dataset
from zfloc_stream.io.datasets.ros2 import find_topics, parse_topic_overrides
from zfloc_stream.errors import InputError
from zfloc_stream.metrics import is_success, position_errors
from zfloc_stream.io.session import record_session
from zfloc_stream.sim import SimSettings, build_scene, simulate, simulate_laser
from zfloc_stream.tools.cli import main

LASER_MOUNT = mount(0.2, 0.05, 0.3, yaw=0.05)  # laser ahead, left and above base_link, turned 3 deg
CAMERA_MOUNT = mount(0.1, 0.0, 1.4, optical=True)


@pytest.fixture(scope="module")
def apartment():
    return build_scene("apartment", seed=0)


@pytest.fixture(scope="module")
def laser_run(apartment):
    return simulate_laser(apartment, seed=0, n_frames=30)


def _localize(sequence, floorplan, truth):
    settings = load_settings(None, [], base_overrides=sequence.settings_overrides)
    localizer = Localizer(floorplan, settings)
    poses = [localizer.push(f).pose for f in sequence.frames()]
    errors = position_errors(np.array([p if p is not None else [np.nan] * 3 for p in poses]), truth)
    return errors, settings


def _planar(T):
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def test_laser_bag_localizes_like_the_protobuf_session(tmp_path, apartment, laser_run):
    bag = tmp_path / "laser.mcap"
    stamps = write_sensor_bag(bag, laser_run.frames, LASER_MOUNT, sensor_hz=15, odom_hz=50, swap_odometry=7)
    seq = detect_source(bag, floorplan=apartment.floorplan)
    assert seq.source.startswith("ros2:") and seq.n_frames == 30 and seq.settings_overrides["estimator"]["scale_mode"] == "fixed"
    frames = list(seq.frames())
    assert [round(f.timestamp * 1e9) for f in frames] == stamps  # the scans' own stamps
    # the laser pose is base odometry (50 Hz, interpolated) composed with the static mount;
    # it differs from the simulated pose only where the bag's odometry cuts a corner of the
    # walk (0.3-0.5 m steps per scan at 15 Hz: a fast walk)
    for f, ref in zip(frames, laser_run.frames):
        d = _planar(f.T_odom_sensor) - _planar(ref.T_odom_sensor)
        assert np.hypot(d[0], d[1]) < 0.05 and abs(np.remainder(d[2] + np.pi, 2 * np.pi) - np.pi) < 0.05
    ros_errors, settings = _localize(seq, apartment.floorplan, laser_run.poses)
    record_session(tmp_path / "session.mcap", apartment.floorplan, laser_run.frames, settings)
    pb_errors, _ = _localize(detect_source(tmp_path / "session.mcap"), apartment.floorplan, laser_run.poses)
    assert is_success(pb_errors, 1.0) and is_success(ros_errors, 1.0)
    assert np.nanmax(ros_errors[-10:]) < 0.2, ros_errors[-10:]


def test_depth_camera_bag_localizes_like_the_protobuf_session(tmp_path, apartment):
    cam = simulate(apartment, SimSettings(width=80, height=60, scale_error=0.0, use_labels=False), seed=0, n_frames=30)
    bag = tmp_path / "depth.mcap"
    write_sensor_bag(bag, cam.frames, CAMERA_MOUNT, kind="depth", sensor_hz=10, odom_hz=30)
    seq = open_dataset(f"ros2:{bag}")[0]
    seq._floorplan = apartment.floorplan  # bags carry no floorplan
    first = next(seq.frames())
    assert first.labels is None and first.depth.dtype == np.float32
    np.testing.assert_allclose(first.K, cam.frames[0].K)
    valid = cam.frames[0].depth > 0
    np.testing.assert_allclose(first.depth[valid], cam.frames[0].depth[valid], atol=0.0006)  # millimetres
    ros_errors, settings = _localize(seq, apartment.floorplan, cam.poses)
    record_session(tmp_path / "session.mcap", apartment.floorplan, cam.frames, settings)
    pb_errors, _ = _localize(detect_source(tmp_path / "session.mcap"), apartment.floorplan, cam.poses)
    assert is_success(pb_errors, 1.0) and is_success(ros_errors, 1.0)
    assert abs(np.nanmean(ros_errors[-10:]) - np.nanmean(pb_errors[-10:])) < 0.1


def test_odometry_from_tf_and_32fc1_depth(tmp_path, apartment):
    cam = simulate(apartment, SimSettings(width=32, height=24, scale_error=0.0), seed=1, n_frames=4)
    bag = tmp_path / "tf.mcap"
    write_sensor_bag(bag, cam.frames, CAMERA_MOUNT, kind="depth", odom_via_tf=True, depth_mm=False)
    frames = list(detect_source(bag, floorplan=apartment.floorplan).frames())
    assert len(frames) == 4
    for f, ref in zip(frames, cam.frames):
        assert np.abs(f.T_odom_cam[:3, 3] - ref.T_odom_cam[:3, 3]).max() < 0.05
        np.testing.assert_array_equal(f.depth, np.nan_to_num(ref.depth, nan=0.0))


def test_frames_before_the_odometry_starts_are_skipped_with_the_reason(tmp_path, apartment, laser_run):
    bag = tmp_path / "late-odom.mcap"
    write_sensor_bag(bag, laser_run.frames[:5], LASER_MOUNT, odom_offset=0.15)  # odometry starts after scan 0
    with pytest.warns(UserWarning, match=r"skipped 1 of 5 frame\(s\) without odometry .*t=100.000000 is outside the odometry /odom time span"):
        seq = detect_source(bag, floorplan=apartment.floorplan)
    assert seq.n_frames == 4 and "outside" in seq.skipped[0]
    assert len(list(seq.frames())) == 4


def test_topics_are_found_by_type_and_overridable(tmp_path, apartment, laser_run):
    channels = {"/front/scan": "sensor_msgs/LaserScan", "/rear/scan": "sensor_msgs/LaserScan",
                "/odom": "nav_msgs/Odometry", "/tf_static": "tf2_msgs/TFMessage", "/tf": "tf2_msgs/TFMessage"}
    with pytest.raises(InputError, match="several sensor_msgs/LaserScan topics .* --topic scan=TOPIC"):
        find_topics("bag.mcap", channels, {})
    topics = find_topics("bag.mcap", channels, parse_topic_overrides(["scan=/rear/scan"]))
    assert topics == {"scan": "/rear/scan", "odom": "/odom", "tf": "/tf", "tf_static": "/tf_static"}
    with pytest.raises(InputError, match="carries nav_msgs/Odometry, expected sensor_msgs/LaserScan"):
        find_topics("bag.mcap", channels, {"scan": "/odom"})
    with pytest.raises(InputError, match="unknown role 'lidar'"):
        parse_topic_overrides(["lidar=/scan"])
    # end to end through the CLI, the scan on a non-default topic
    bag = tmp_path / "front.mcap"
    write_sensor_bag(bag, laser_run.frames[:3], LASER_MOUNT, scan_topic="/front/scan")
    plan = apartment.floorplan.write_ros(tmp_path / "plan")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["run", "--floorplan", str(plan), "--input", str(bag), "--topic", "scan=/front/scan",
                     "--out", str(tmp_path / "out"), "--no-progress"])
    assert code == 0 and (tmp_path / "out" / "trajectory.csv").read_text().count("\n") == 4


def test_bags_without_what_frames_need_are_one_line_errors(tmp_path, capsys, laser_run):
    bag = BagWriter(tmp_path / "no-odom.mcap")
    scan = {"header": {"stamp": {"sec": 1, "nanosec": 0}, "frame_id": "laser"}, "angle_min": -1.0, "angle_max": 1.0,
            "angle_increment": 1.0, "time_increment": 0.0, "scan_time": 0.1, "range_min": 0.1, "range_max": 10.0,
            "ranges": [1.0, 2.0, 3.0], "intensities": []}
    bag.write("/scan", "sensor_msgs/msg/LaserScan", scan, 10**9)
    bag.close()
    code = main(["run", "--floorplan", "x.yaml", "--input", str(tmp_path / "no-odom.mcap"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "floorplan YAML not found" in err
    with pytest.raises(InputError, match=r"no-odom.mcap: no nav_msgs/Odometry topic and no /tf"):
        detect_source(tmp_path / "no-odom.mcap")
    bad = tmp_path / "bad-topic.mcap"
    write_sensor_bag(bad, laser_run.frames[:2], LASER_MOUNT)
    code = main(["run", "--input", str(bad), "--topic", "scan", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and "--topic 'scan' must look like ROLE=/topic" in err


def test_protobuf_session_with_odometry_at_its_own_rate_localizes(tmp_path, apartment, laser_run):
    """Our own MCAP topics, but /odometry at 50 Hz on its own stamps and /scan at 15 Hz (as
    another tool would record them): frames get the interpolated pose, nothing is dropped."""
    from mcap_protobuf.writer import Writer

    from ros2_bag import base_poses_at
    from zfloc_stream.io.session import read_session
    from zfloc_stream.io.session import schemas as S

    frame_ns = [int(round((50.0 + k / 15) * 1e9)) for k in range(len(laser_run.frames))]
    odom_ns = [int(round((49.9 + 0.003 + j / 50) * 1e9)) for j in range(int((len(frame_ns) / 15 + 0.2) * 50))]
    poses = base_poses_at(odom_ns, frame_ns, [f.T_odom_sensor for f in laser_run.frames], np.eye(4))
    events = [(ns, S.TOPIC_ODOMETRY, S.pose_to_msg(T, ns, "odom")) for ns, T in zip(odom_ns, poses)]
    events += [(ns, S.TOPIC_SCAN, S.scan_to_msg(f.ranges, f.angle_min, f.angle_increment, ns)) for ns, f in zip(frame_ns, laser_run.frames)]
    with open(tmp_path / "rates.mcap", "wb") as f:
        writer = Writer(f)
        for ns, topic, msg in sorted(events, key=lambda e: e[0]):
            writer.write_message(topic, msg, log_time=ns, publish_time=ns)
        writer.finish()
    session = read_session(tmp_path / "rates.mcap")
    frames = list(session.frames())
    assert len(frames) == len(laser_run.frames) and session.problems == []
    seq = detect_source(tmp_path / "rates.mcap", floorplan=apartment.floorplan)
    errors, _ = _localize(seq, apartment.floorplan, laser_run.poses)
    assert is_success(errors, 1.0) and np.nanmax(errors[-10:]) < 0.2
