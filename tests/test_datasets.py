"""Loaders (Gibson(t) fixture, Carmen, MCAP), the registry, detect_source, synthetic
odometry and map-from-log."""

import gzip
import shutil
from pathlib import Path

import numpy as np
import pytest

from benchmarks.shared_data import SHARED_DATA

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.io.datasets import detect_source, open_dataset
from zfloc_stream.io.datasets.base import upright_camera_matrix
from zfloc_stream.io.datasets.carmen import read_carmen
from zfloc_stream.errors import InputError
from zfloc_stream.frames import CEILING, FLOOR, WALL, CameraFrame, LaserFrame
from zfloc_stream.geometry.sim2 import wrap_angle

HERE = Path(__file__).resolve().parent
GIBSON = HERE / "fixtures" / "gibson"
SHARED = SHARED_DATA
INTEL = SHARED / "carmen" / "intel-corrected.log.gz"
SESSION = SHARED / "sessions" / "intel-camera-30" / "session.mcap"
needs_intel = pytest.mark.skipif(not INTEL.is_file(), reason="Intel Carmen log not available")


def _relative(poses):
    """Body-frame steps (dx, dy, dtheta) between consecutive planar poses."""
    poses = np.asarray(poses)
    dp = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    return np.column_stack([c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1], wrap_angle(np.diff(poses[:, 2]))])


def _planar(T):
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def _camera_planar(T):
    forward = T[:3, 2]
    return np.array([T[0, 3], T[1, 3], np.arctan2(forward[1], forward[0])])


# --- registry ------------------------------------------------------------------------------
def test_unknown_kind_and_malformed_spec_are_input_errors():
    with pytest.raises(InputError, match="unknown dataset kind 'nope'"):
        open_dataset("nope:x")
    with pytest.raises(InputError, match="KIND:ARGS"):
        open_dataset("gibson")
    with pytest.raises(InputError, match="unknown simulated scene"):
        open_dataset("sim:atlantis")


# --- simulated scenes ----------------------------------------------------------------------
def test_sim_sequences_render_chunks_lazily_and_deterministically():
    settings = load_settings(overrides={"datasets": {"sim": {"n_frames": 20}}, "seed": 2})
    rooms, hall = open_dataset("sim:rooms,hall", settings)
    assert (rooms.name, rooms.n_frames, hall.name) == ("rooms", 20, "hall")
    chunk = list(rooms.frames(5, 8))
    assert len(chunk) == 3 and all(isinstance(f, CameraFrame) for f in chunk)
    np.testing.assert_array_equal([f.ground_truth for f in chunk], rooms.ground_truth[5:8])
    again = next(open_dataset("sim:rooms", settings)[0].frames(5, 6))
    np.testing.assert_array_equal(again.depth, chunk[0].depth)


# --- Gibson(t) -----------------------------------------------------------------------------
def test_gibson_fixture_loads_from_root_split_and_scene_folder():
    (seq,) = open_dataset(f"gibson:{GIBSON}")
    assert seq.name == "Tinyroom" and seq.n_frames == 40
    assert open_dataset(f"gibson:{GIBSON}:test")[0].name == "Tinyroom"
    with pytest.raises(InputError, match="holds no sequence"):
        open_dataset(f"gibson:{GIBSON}:train")
    assert detect_source(GIBSON / "Tinyroom").name == "Tinyroom"
    fp = seq.floorplan
    assert fp.resolution == 0.01 and tuple(fp.origin) == (-4.0, -3.0)
    assert seq.settings_overrides["estimator"]["solvers"]["pool"] == ["3L", "2L"]


def test_gibson_frames_are_geometrically_consistent_with_the_map():
    """Wall pixels placed with the TRUE pose land on the map's walls; floor pixels on z=0."""
    settings = Settings()
    (seq,) = open_dataset(f"gibson:{GIBSON}", settings)
    cfg = settings.datasets.gibson
    fp = seq.floorplan
    for frame in seq.frames():
        assert isinstance(frame, CameraFrame)
        assert frame.depth.shape == (cfg.image_rows, 40)
        assert set(np.unique(frame.labels)) <= {WALL, FLOOR, CEILING}
        assert frame.K[0, 0] == pytest.approx(15.0) and frame.K[0, 2] == pytest.approx(19.5)
        v, u = np.nonzero(frame.depth > 0)
        z = frame.depth[v, u]
        cam = np.stack([(u - frame.K[0, 2]) / frame.K[0, 0] * z, (v - frame.K[1, 2]) / frame.K[1, 1] * z, z, np.ones_like(z)])
        world = (upright_camera_matrix(*frame.ground_truth, cfg.camera_height) @ cam)[:3].T
        labels = frame.labels[v, u]
        assert fp.distance(world[labels == WALL, :2]).max() < 0.02
        assert np.abs(world[labels == FLOOR, 2]).max(initial=0.0) < 1e-4
        assert np.abs(world[labels == CEILING, 2] - cfg.wall_height).max(initial=0.0) < 1e-4


def test_gibson_odometry_is_relative_only():
    settings = load_settings(overrides={"seed": 3, "datasets": {"odometry": {"noise": 0.0}}})
    (seq,) = open_dataset(f"gibson:{GIBSON}", settings)
    frames = list(seq.frames())
    odom = np.array([_camera_planar(f.T_odom_cam) for f in frames])
    truth = seq.ground_truth
    assert np.linalg.norm(odom[0, :2] - truth[0, :2]) > 1.0  # a random origin, not the map frame
    np.testing.assert_allclose(_relative(odom), _relative(truth), atol=1e-9)  # noise 0: exact relative motion
    assert np.all(np.abs([f.T_odom_cam[2, 3] for f in frames] - np.float64(settings.datasets.gibson.camera_height)) < 1e-12)


def test_gibson_malformed_files_name_the_file(tmp_path):
    scene = tmp_path / "Broken"
    shutil.copytree(GIBSON / "Tinyroom", scene)
    (scene / "poses.txt").write_text("0 0 0\n1 two 3\n")
    with pytest.raises(InputError, match=r"poses.txt:2"):
        detect_source(scene)
    (scene / "depth40.txt").unlink()
    with pytest.raises(InputError, match="not a Gibson"):
        detect_source(scene)


# --- Carmen --------------------------------------------------------------------------------
@needs_intel
def test_intel_log_parses_910_flaser_scans():
    log = read_carmen(INTEL)
    assert len(log) == 910 and log.skipped == 0
    assert all(r.size == 180 for r in log.ranges)
    assert log.angle_min[0] == pytest.approx(-np.pi / 2)
    assert log.angle_increment[0] == pytest.approx(np.pi / 180)
    np.testing.assert_allclose(log.poses[0], [0.600266, -0.0320327, -0.354665])
    assert log.timestamps[0] == pytest.approx(32.9068)
    seq = detect_source(INTEL, odometry_noise=0.0)
    assert seq.settings_overrides == {"estimator": {"scale_mode": "fixed"}}
    frames = list(seq.frames(0, 50))
    assert all(isinstance(f, LaserFrame) for f in frames)
    odom = np.array([_planar(f.T_odom_sensor) for f in frames])
    assert np.linalg.norm(odom[0, :2] - log.poses[0, :2]) > 1.0
    np.testing.assert_allclose(_relative(odom), _relative(log.poses[:50]), atol=1e-9)
    assert frames[0].valid.sum() < 180  # 81.83 m readings are no-returns


def _flaser(ranges, pose, stamp):
    r = " ".join(f"{v:.3f}" for v in ranges)
    x, y, t = pose
    return f"FLASER {len(ranges)} {r} {x} {y} {t} {x} {y} {t} {stamp} host {stamp}\n"


def _robotlaser(ranges, pose, stamp):
    r = " ".join(f"{v:.3f}" for v in ranges)
    x, y, t = pose
    head = f"ROBOTLASER1 0 -1.5707963 3.1415927 0.0174533 81.9 0.01 0 {len(ranges)} {r} 0"
    return f"{head} {x} {y} {t} {x} {y} {t} 0 0 0.5 0.3 0 {stamp} host {stamp}\n"


def _wall_scan(facing: float, distance: float, n: int = 180) -> np.ndarray:
    """Ranges of a 180-deg scan at the origin facing `facing`, in front of a wall
    `distance` away (spanning +-3 m sideways); no-return (81.83) elsewhere."""
    a = np.deg2rad(-90 + np.arange(n) * 180 / n)
    with np.errstate(divide="ignore"):
        r = distance / np.cos(a)
    side = np.abs(np.tan(a) * distance)
    return np.where((np.cos(a) > 0.05) & (side <= 3.0), r, 81.83)


def _two_wall_log(path: Path, gz: bool = False, extra: str = "") -> Path:
    """Scans 0-9 face +x (wall at x = 3); scans 10-19 face -x (wall at x = -2)."""
    lines = ["# synthetic\n", "PARAM robot_frontlaser_offset 0.0 nohost 0\n"]
    for i in range(20):
        facing = 0.0 if i < 10 else np.pi
        lines.append(_flaser(_wall_scan(facing, 3.0 if i < 10 else 2.0), (0.0, 0.01 * i, facing), 1.0 + i))
        lines.append(f"ODOM 0 0 0 0 0 0 {i} host {i}\n")
    text = "".join(lines) + extra
    if gz:
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


def test_carmen_malformed_lines_are_skipped_with_a_counted_warning(tmp_path):
    bad = "FLASER 180 1 2 3\nFLASER 3 1 2 x 0 0 0 0 0 0 5 host 5\n"
    path = _two_wall_log(tmp_path / "log.clf", extra=bad)
    with pytest.warns(UserWarning, match="skipped 2 malformed"):
        log = read_carmen(path)
    assert len(log) == 20 and log.skipped == 2


def test_carmen_gzip_robotlaser_and_empty_files(tmp_path):
    path = _two_wall_log(tmp_path / "log.gz", gz=True)
    assert len(read_carmen(path)) == 20
    assert detect_source(path).n_frames == 20  # detected by content, gzipped
    rl = tmp_path / "robot.log"
    rl.write_text(_robotlaser([1.0, 2.0, 3.0], (1.0, 2.0, 0.5), 7.0))
    log = read_carmen(rl)
    assert log.ranges[0].tolist() == [1.0, 2.0, 3.0]
    assert log.angle_min[0] == pytest.approx(-1.5707963) and log.angle_increment[0] == pytest.approx(0.0174533)
    assert log.max_range[0] == pytest.approx(81.9) and log.timestamps[0] == 7.0
    np.testing.assert_allclose(log.poses[0], [1.0, 2.0, 0.5])
    empty = tmp_path / "empty.log"
    empty.write_text("ODOM 0 0 0 0 0 0 1 host 1\n")
    with pytest.raises(InputError, match="no FLASER or ROBOTLASER1"):
        read_carmen(empty)


def test_odometry_noise_is_seeded_drift(tmp_path):
    path = _two_wall_log(tmp_path / "log.clf")
    a = [_planar(f.T_odom_sensor) for f in detect_source(path, odometry_noise=0.1, seed=1).frames()]
    b = [_planar(f.T_odom_sensor) for f in detect_source(path, odometry_noise=0.1, seed=1).frames()]
    c = [_planar(f.T_odom_sensor) for f in detect_source(path, odometry_noise=0.0, seed=1).frames()]
    np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(np.array(a)[0], np.array(c)[0])  # same origin, noise only in the steps
    assert np.abs(_relative(a) - _relative(c)).max() > 1e-4


# --- detect_source ---------------------------------------------------------------------------
def test_detect_source_rejects_unknown_and_missing_inputs(tmp_path):
    with pytest.raises(InputError, match="input not found"):
        detect_source(tmp_path / "nothing.mcap")
    junk = tmp_path / "notes.txt"
    junk.write_text("hello\n")
    with pytest.raises(InputError, match=r"unrecognised input .*notes.txt"):
        detect_source(junk)
    with pytest.raises(InputError, match="not a Gibson"):
        detect_source(tmp_path)


@pytest.mark.skipif(not SESSION.is_file(), reason="intel-camera-30 session not available")
def test_mcap_session_is_detected_with_its_floorplan_and_truth():
    seq = detect_source(SESSION)
    assert seq.n_frames == 30
    assert np.isfinite(seq.ground_truth).all()
    assert seq.floorplan.resolution == pytest.approx(0.05)
    assert isinstance(next(seq.frames(0, 1)), CameraFrame)


# --- map-from-log --------------------------------------------------------------------------
def test_map_from_log_leaves_the_excluded_window_out(tmp_path):
    from zfloc_stream.plans.floorplan import Floorplan
    from zfloc_stream.plans.map_from_log import map_from_log
    from zfloc_stream.tools.cli import main

    log = read_carmen(_two_wall_log(tmp_path / "log.clf"))
    full = map_from_log(log)
    walls = full.wall_points
    assert (np.abs(walls[:, 0] + 2.0) < 0.1).sum() > 50  # the wall only scans 10-19 see
    assert (np.abs(walls[:, 0] - 3.0) < 0.1).sum() > 50
    held_out = map_from_log(log, [(10, 20)]).wall_points
    assert (held_out[:, 0] < 0).sum() == 0
    assert (np.abs(held_out[:, 0] - 3.0) < 0.1).sum() > 50

    out = tmp_path / "map"
    assert main(["map-from-log", str(tmp_path / "log.clf"), "--exclude", "10:20", "--resolution", "0.05", "--out", str(out)]) == 0
    loaded = Floorplan.load(out / "map.yaml")
    assert (loaded.wall_points[:, 0] < 0).sum() == 0
    assert np.abs(loaded.wall_points[:, 0] - 3.0).min() < 0.05


def test_map_from_log_cli_bad_input_exits_2(tmp_path, capsys):
    from zfloc_stream.tools.cli import main

    path = _two_wall_log(tmp_path / "log.clf")
    assert main(["map-from-log", str(path), "--exclude", "9", "--out", str(tmp_path / "m")]) == 2
    assert "START:STOP" in capsys.readouterr().err
    assert main(["map-from-log", str(path), "--exclude", "0:20", "--out", str(tmp_path / "m")]) == 2
    assert main(["map-from-log", str(tmp_path / "missing.log"), "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("zfloc-stream: error:") for line in err)


def test_gibson_fixture_localizes_end_to_end():
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.metrics import evaluate_run, position_errors

    seq = detect_source(GIBSON / "Tinyroom", seed=0)
    localizer = Localizer(seq.floorplan, load_settings(base_overrides=seq.settings_overrides))
    poses = [localizer.push(frame).pose for frame in seq.frames()]
    run = evaluate_run(position_errors(poses, seq.ground_truth), (1.0, 0.5))
    assert run.success[0.5] and run.max_error < 0.3


def test_carmen_directory_spec_opens_every_log_in_order(tmp_path):
    _two_wall_log(tmp_path / "b.log.gz", gz=True)
    _two_wall_log(tmp_path / "a.clf")
    (tmp_path / "README.md").write_text("not a log")
    sequences = open_dataset(f"carmen:{tmp_path}", Settings())
    assert [s.name for s in sequences] == ["a.clf", "b.log.gz"]
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match="no Carmen log"):
        open_dataset(f"carmen:{empty}", Settings())
