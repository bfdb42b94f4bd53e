"""TUM trajectories: the format evo's reader takes (evo.tools.file_interface.
read_tum_trajectory_file: '#' comment lines, single-space separated rows of exactly 8
floats, no trailing delimiter; PoseTrajectory3D wants ordered stamps and unit quaternions)."""

import csv
import math

import numpy as np

from zfloc_stream.estimate import Estimate
from zfloc_stream.errors import InputError
from zfloc_stream.io.session import record_session
from zfloc_stream.sim import build_scene, simulate_laser
from zfloc_stream.tools.cli import main
from zfloc_stream.io.tum import TumWriter, export_session_tum

import pytest


def read_like_evo(path):
    """The checks evo applies, written out: returns (stamps, xyz, quat_xyzw)."""
    with open(path) as f:
        rows = list(csv.reader((line for line in f if not line.startswith("#")), delimiter=" "))
    assert rows and all(len(r) == 8 for r in rows), "TUM rows need 8 entries and no trailing space"
    mat = np.array(rows).astype(float)
    stamps, xyz, quat = mat[:, 0], mat[:, 1:4], mat[:, 4:]
    assert np.all(np.diff(stamps) > 0)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-9)
    return stamps, xyz, quat


def _est(frame, t, pose):
    return Estimate(frame, t, "tracking" if pose is not None else "initializing", None if pose is None else np.array(pose),
                    None, None, float("nan"), (), {}, None)


def test_tum_rows_are_planar_poses_with_yaw_quaternions(tmp_path):
    path = tmp_path / "t.tum"
    with TumWriter(path) as tum:
        tum.write(_est(0, 1.0, None))  # no pose yet: left out
        tum.write(_est(1, 1.5, [1.0, 2.0, math.pi / 2]))
        tum.write(_est(2, 1.5, [9.0, 9.0, 0.0]))  # same stamp again: kept, 1 us later
        tum.write(_est(3, 2.0, [1.5, -2.0, -3.0]))
    assert (tum.rows, tum.moved) == (3, 1)
    stamps, xyz, quat = read_like_evo(path)
    np.testing.assert_allclose(stamps, [1.5, 1.5 + 1e-6, 2.0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(xyz, [[1.0, 2.0, 0.0], [9.0, 9.0, 0.0], [1.5, -2.0, 0.0]])
    np.testing.assert_allclose(quat[0], [0, 0, math.sin(math.pi / 4), math.cos(math.pi / 4)])
    yaw = 2 * np.arctan2(quat[2, 2], quat[2, 3])
    assert math.isclose(math.remainder(yaw + 3.0, 2 * math.pi), 0.0, abs_tol=1e-12)
    assert path.read_text().splitlines()[0].startswith("# timestamp tx ty tz qx qy qz qw")


def test_repeated_stamps_keep_every_pose_and_both_writers_share_stamps(tmp_path):
    """One input stamp for every frame (belgioioso-camera-50) keeps every posed frame, and
    a ground-truth writer fed the same frames gets the same stamps (evo pairs them)."""
    from zfloc_stream.io.tum import read_tum

    with TumWriter(tmp_path / "est.tum") as est, TumWriter(tmp_path / "gt.tum") as gt:
        for i in range(6):
            est.write(_est(i, 1e9, None if i < 2 else [i, 0.0, 0.1 * i]))
            gt.write_pose(1e9, [i, 1.0, 0.1 * i])
    assert (est.rows, est.moved, gt.rows, gt.moved) == (4, 4, 6, 5)
    t_est, p_est = read_tum(tmp_path / "est.tum")
    t_gt, p_gt = read_tum(tmp_path / "gt.tum")
    assert np.all(np.diff(t_gt) > 0)
    np.testing.assert_array_equal(t_est, t_gt[2:])  # same stamp for the same frame
    np.testing.assert_allclose(p_est[:, 2], [0.2, 0.3, 0.4, 0.5], atol=1e-12)


def test_run_writes_tum_beside_the_csv_and_export_rewrites_it_from_the_session(tmp_path, capsys):
    scene = build_scene("rooms", seed=0)
    run = simulate_laser(scene, seed=0, n_frames=12)
    from zfloc_stream import load_settings

    settings = load_settings(None, [], base_overrides={"estimator": {"scale_mode": "fixed"}})
    estimates = record_session(tmp_path / "session.mcap", scene.floorplan, run.frames, settings)
    assert main(["export", str(tmp_path / "session.mcap"), "--tum", str(tmp_path / "out.txt")]) == 0
    stamps, xyz, quat = read_like_evo(tmp_path / "out.txt")
    with_pose = [e for e in estimates if e.pose is not None]
    assert len(stamps) == len(with_pose) and "wrote" in capsys.readouterr().out
    np.testing.assert_allclose(xyz[:, :2], [e.pose[:2] for e in with_pose], atol=1e-12)
    # the same file from a live run: default beside trajectory.csv, or where --tum says
    plan = scene.floorplan.write_ros(tmp_path / "plan")
    assert main(["run", "--floorplan", str(plan), "--input", str(tmp_path / "session.mcap"), "--out", str(tmp_path / "r"), "--no-progress"]) == 0
    # the plan reloaded from its PNG/YAML sits at a float-rounded origin: same poses to 1e-9
    live, _, _ = read_like_evo(tmp_path / "r" / "trajectory.tum")
    np.testing.assert_array_equal(live, stamps)
    np.testing.assert_allclose(read_like_evo(tmp_path / "r" / "trajectory.tum")[1], xyz, atol=1e-9)
    assert main(["run", "--input", str(tmp_path / "session.mcap"), "--out", str(tmp_path / "r2"), "--tum", str(tmp_path / "x" / "y.txt"), "--no-progress"]) == 0
    again = read_like_evo(tmp_path / "x" / "y.txt")
    np.testing.assert_array_equal(again[0], stamps)
    np.testing.assert_allclose(np.hstack(again[1:]), np.hstack([xyz, quat]), atol=1e-9)


def test_export_of_a_session_without_estimates_is_a_one_line_error(tmp_path, capsys):
    from zfloc_stream.io.session import SessionWriter
    from zfloc_stream.settings.loading import Settings

    frames = simulate_laser("rooms", seed=0, n_frames=2).frames
    with SessionWriter(tmp_path / "inputs.mcap", Settings()) as log:
        for i, f in enumerate(frames):
            log.write_frame(i, f)
    with pytest.raises(InputError, match="holds no logged estimates"):
        export_session_tum(tmp_path / "inputs.mcap", tmp_path / "o.txt")
    assert main(["export", str(tmp_path / "missing.mcap"), "--tum", str(tmp_path / "o.txt")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
