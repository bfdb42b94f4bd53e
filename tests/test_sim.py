"""Simulator: rendering correctness, walks, determinism, noise statistics, conventions."""

import numpy as np
import pytest

from zfloc_stream.errors import ConfigError, InputError
from zfloc_stream.frames import CEILING, FLOOR, OTHER, UNKNOWN, WALL, CameraFrame, LaserFrame
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.sim import (Connection, LaserSimSettings, Room, SimSettings, build_scene, camera_pose,
                              drift_odometry, intrinsics, make_scene, random_walk, render, simulate,
                              simulate_laser, snap, trajectory_through)
from zfloc_stream.geometry.sim2 import wrap_angle

QUIET = dict(depth_noise=0.0, scale_error=0.0, furniture_as_wall_prob=0.0, wall_dropout=0.0,
             odom_translation_noise=0.0, odom_yaw_noise_deg=0.0, camera_height_jitter=0.0)


@pytest.fixture(scope="module")
def box_room():
    """One 6 x 4 m room (inner faces at x = 0.15 / 5.9, y = 0.15 / 3.9), a pillar and a crate."""
    room = Room("r", "room", snap(0.0), snap(0.0), snap(6.0), snap(4.0))
    return make_scene("box", [room], [], pillars=[(4.025, 0.975, 0.3)],
                      furniture=[(4.0, 3.0, 1.0, 1.0, 0.0, 1.0)], wall_height=2.7)


@pytest.fixture(scope="module")
def office():
    return build_scene("office", 0)


# --- rendering ---------------------------------------------------------------------------------


def test_depth_to_a_known_wall(box_room):
    K = intrinsics(161, 121, 90.0)  # odd size: pixel (60, 80) is the optical axis
    depth, labels = render(box_room, camera_pose(2.0, 2.0, 0.0, 1.5), K, (121, 161))
    assert labels[60, 80] == WALL
    assert depth[60, 80] == pytest.approx(5.9 - 2.0, abs=0.01)
    # facing -y: the south wall's inner face is at y = 0.15
    depth, labels = render(box_room, camera_pose(2.0, 2.0, -np.pi / 2, 1.5), K, (121, 161))
    assert depth[60, 80] == pytest.approx(2.0 - 0.15, abs=0.01)
    # an oblique pixel: z-depth, not range
    u = 100  # 14 degrees right of the axis, clear of the pillar
    ray = np.linalg.inv(K) @ [u, 60, 1.0]
    depth, _ = render(box_room, camera_pose(2.0, 2.0, 0.0, 1.5), K, (121, 161))
    hit_x = 3.9  # metres along the optical axis (world x) to the east wall
    assert abs(ray[1]) < 1e-9 and depth[60, u] == pytest.approx(hit_x, abs=0.01)


def test_floor_ceiling_and_label_layout(box_room):
    K = intrinsics(161, 121, 90.0)
    depth, labels = render(box_room, camera_pose(2.0, 2.0, 0.0, 1.5, pitch=np.radians(-30)), K, (121, 161))
    assert labels[60, 80] == FLOOR
    assert depth[60, 80] == pytest.approx(1.5 / np.sin(np.radians(30)), abs=0.01)
    depth, labels = render(box_room, camera_pose(1.0, 2.0, 0.0, 1.5), K, (121, 161))
    assert (labels[0] == CEILING).all() and (labels[-1, 40:121] == FLOOR).all()
    assert (labels[-1, :3] == WALL).all()  # the wide bottom corners still meet the side walls
    assert (labels[60] == WALL).all()
    assert not (labels == UNKNOWN).any() and (depth > 0).all()


def test_pillar_is_wall_and_furniture_is_other(box_room):
    K = intrinsics(161, 121, 90.0)
    depth, labels = render(box_room, camera_pose(1.025, 0.975, 0.0, 1.5), K, (121, 161))
    assert labels[60, 80] == WALL
    assert depth[60, 80] == pytest.approx(4.025 - 0.3 - 1.025, abs=0.01)
    # looking down 10 degrees at the 1 m crate at x in [3.5, 4.5]: the ray lands on its top
    depth, labels, index = render(box_room, camera_pose(1.0, 3.0, 0.0, 1.5, pitch=np.radians(-10)), K,
                                  (121, 161), return_furniture_index=True)
    horizontal = 0.5 / np.tan(np.radians(10))
    assert labels[60, 80] == OTHER and index[60, 80] == 0
    assert depth[60, 80] == pytest.approx(horizontal / np.cos(np.radians(10)), abs=0.01)
    assert (index[labels != OTHER] == -1).all()


def test_beyond_max_range_reads_nothing(box_room):
    K = intrinsics(161, 121, 90.0)
    depth, labels = render(box_room, camera_pose(2.0, 2.0, 0.0, 1.5), K, (121, 161), max_range=3.0)
    assert depth[60, 80] == 0 and labels[60, 80] == UNKNOWN
    assert (depth[labels != UNKNOWN] > 0).all()


def test_fast_render_matches_brute_force(office):
    rng = make_rng(0, "test", "render")
    walk = random_walk(office, rng, 6)
    K = intrinsics(160, 120, 108.0)
    for x, y, yaw in walk:
        T = camera_pose(x, y, yaw, 1.5, *np.radians(rng.uniform(-20, 20, 2)))
        d, lab = render(office, T, K, (120, 160), max_range=15.0)
        db, lb = render(office, T, K, (120, 160), max_range=15.0, brute_force=True)
        assert np.mean(lab != lb) < 0.002
        same = lab == lb
        assert np.quantile(np.abs(d - db)[same], 0.995) < 0.005


# --- walks -------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["apartment", "office", "symmetric"])
def test_random_walk_stays_free_with_regular_steps(name):
    scene = build_scene(name, 1)
    walk = random_walk(scene, make_rng(1, "walk"), 120)
    assert walk.shape == (120, 3)
    assert scene.is_free(walk[:, :2]).all()
    steps = np.linalg.norm(np.diff(walk[:, :2], axis=0), axis=1)
    assert steps.min() >= 0.3 - 1e-9 and steps.max() <= 0.5 + 1e-9
    motion = np.arctan2(*np.diff(walk[:, :2], axis=0).T[::-1])
    err = np.abs(wrap_angle(walk[:-1, 2] - motion))
    assert np.median(err) < np.radians(10)
    assert np.array_equal(walk, random_walk(scene, make_rng(1, "walk"), 120))


def test_trajectory_through_visits_waypoints():
    scene = build_scene("symmetric", 0)
    wp = scene.waypoints
    points = [wp["symmetric_start"], wp["symmetric_end"], wp["distinguishing"]]
    walk = trajectory_through(scene, points, make_rng(0, "through"), step=0.4)
    steps = np.linalg.norm(np.diff(walk[:, :2], axis=0), axis=1)
    assert np.allclose(steps, 0.4)
    for p in points:
        assert np.linalg.norm(walk[:, :2] - p, axis=1).min() < 0.45
    # the walk goes through the symmetric part first, then to the annex
    x_hi = scene.info["symmetric_x_range"][1]
    first_annex = np.argmax(walk[:, 0] > x_hi)
    assert first_annex > 0 and (walk[:first_annex, 0] < x_hi).all()


# --- sequences ------------------------------------------------------------------------------


def test_same_seed_same_frames():
    a = simulate("apartment", SimSettings(), seed=5, n_frames=6)
    b = simulate("apartment", SimSettings(), seed=5, n_frames=6)
    for fa, fb in zip(a, b):
        assert fa.depth.tobytes() == fb.depth.tobytes()
        assert fa.labels.tobytes() == fb.labels.tobytes()
        assert np.array_equal(fa.T_odom_cam, fb.T_odom_cam) and fa.timestamp == fb.timestamp
    # random access gives the same frame as iteration
    assert a[3].depth.tobytes() == list(b)[3].depth.tobytes()
    c = simulate("apartment", SimSettings(), seed=6, n_frames=6)
    assert a[0].depth.tobytes() != c[0].depth.tobytes()


def test_frames_are_valid_camera_frames():
    seq = simulate("rooms", SimSettings(hfov_deg=48.0), seed=2, n_frames=5)
    for k, f in enumerate(seq):
        assert isinstance(f, CameraFrame) and f.depth.shape == (120, 160) and f.labels.dtype == np.uint8
        assert f.timestamp == pytest.approx(k * seq.settings.frame_interval)
        assert np.allclose(f.ground_truth, seq.poses[k])
    assert seq.K[0, 0] == pytest.approx(80.0 / np.tan(np.radians(24.0)))
    assert simulate("rooms", SimSettings(use_labels=False), seed=2, n_frames=2)[0].labels is None


def _backproject(frame: CameraFrame, mask):
    v, u = np.nonzero(mask & (frame.depth > 0))
    z = frame.depth[v, u].astype(float)
    cam = np.stack([(u - frame.K[0, 2]) * z / frame.K[0, 0], (v - frame.K[1, 2]) * z / frame.K[1, 1], z], 1)
    return cam @ frame.T_odom_cam[:3, :3].T + frame.T_odom_cam[:3, 3]


@pytest.mark.parametrize("gravity_aligned", [True, False])
def test_alignment_maps_observed_walls_onto_the_floorplan(gravity_aligned):
    """End to end: depth -> odometry frame (T_odom_cam) -> true alignment -> floorplan walls."""
    settings = SimSettings(**{**QUIET, "scale_error": 0.1, "max_pitch_deg": 20, "max_roll_deg": 20,
                              "odom_gravity_aligned": gravity_aligned})
    seq = simulate("apartment", settings, seed=3, n_frames=8)
    assert abs(seq.scale - 1) > 1e-3
    for k in (0, 7):
        f = seq[k]
        pts = _backproject(f, f.labels == WALL)
        pts = pts @ seq.odom_tilt[:3, :3]  # undo the odometry frame's tilt (identity if aligned)
        world = seq.alignments[k].apply(pts[:, :2])
        d = seq.scene.floorplan.distance(world)
        assert np.median(d) < 0.05 and np.quantile(d, 0.95) < 0.1
        floor = _backproject(f, f.labels == FLOOR) @ seq.odom_tilt[:3, :3]
        cam = seq.T_odom_cam(k)[:3, 3] @ seq.odom_tilt[:3, :3]
        # camera height above the floor, in odometry units (scaled)
        assert np.median(cam[2] - floor[:, 2]) == pytest.approx(seq.scale * seq.heights[k], abs=0.01)


def test_scale_error_is_consistent_between_depth_and_odometry():
    settings = SimSettings(**{**QUIET, "scale_error": 0.1})
    scales = [simulate("rooms", settings, seed=s, n_frames=3).scale for s in range(30)]
    assert 0.9 <= min(scales) and max(scales) <= 1.1 and np.std(scales) > 0.03
    seq = simulate("rooms", settings, seed=1, n_frames=10)
    true_steps = np.linalg.norm(np.diff(seq.poses[:, :2], axis=0), axis=1)
    odom_steps = np.linalg.norm(np.diff(seq.odom[:, :2], axis=0), axis=1)
    assert np.allclose(odom_steps, seq.scale * true_steps)
    clean, _ = render(seq.scene, seq.T_world_cam(4), seq.K, (120, 160), max_range=settings.max_depth)
    ok = clean > 0
    assert np.allclose(seq[4].depth[ok], seq.scale * clean[ok], rtol=1e-5)
    # without drift the alignment is constant
    params = np.array([a.params() for a in seq.alignments])
    assert np.allclose(params, params[0], atol=1e-9)
    assert seq.alignment.s == pytest.approx(1 / seq.scale)


def test_depth_noise_statistics():
    settings = SimSettings(**{**QUIET, "depth_noise": 0.02})
    seq = simulate("hall", settings, seed=4, n_frames=3)
    ratios = []
    for k in range(3):
        clean, _ = render(seq.scene, seq.T_world_cam(k), seq.K, (120, 160), max_range=settings.max_depth)
        ok = clean > 0
        ratios.append(seq[k].depth[ok] / clean[ok] - 1)
    r = np.concatenate(ratios)
    assert abs(r.mean()) < 0.002 and r.std() == pytest.approx(0.02, rel=0.1)


def test_odometry_drift_statistics():
    rng = make_rng(0, "test", "drift")
    n = 4001
    heading = np.cumsum(rng.normal(0, 0.1, n))
    steps = rng.uniform(0.3, 0.5, n - 1)
    xy = np.concatenate([[[0, 0]], np.cumsum(np.stack([np.cos(heading[:-1]), np.sin(heading[:-1])], 1)
                                             * steps[:, None], axis=0)])
    poses = np.column_stack([xy, heading])
    origin = np.array([3.0, -2.0, 1.0])
    odom = drift_odometry(poses, 1.0, make_rng(1), 0.05, np.radians(0.5), origin)
    assert np.allclose(odom[0], origin)
    yaw_err = wrap_angle(np.diff(odom[:, 2]) - np.diff(poses[:, 2]))
    assert np.degrees(yaw_err.std()) == pytest.approx(0.5, rel=0.1)
    # translation error per step, in the previous odometry heading's frame
    d_true = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    local_true = np.stack([c * d_true[:, 0] + s * d_true[:, 1], -s * d_true[:, 0] + c * d_true[:, 1]], 1)
    d_odom = np.diff(odom[:, :2], axis=0)
    c, s = np.cos(odom[:-1, 2]), np.sin(odom[:-1, 2])
    local_odom = np.stack([c * d_odom[:, 0] + s * d_odom[:, 1], -s * d_odom[:, 0] + c * d_odom[:, 1]], 1)
    rel = (local_odom - local_true) / steps[:, None]
    assert rel.std() == pytest.approx(0.05, rel=0.1) and abs(rel.mean()) < 0.005
    # noise-free odometry is the truth moved rigidly (and scaled)
    exact = drift_odometry(poses, 1.2, make_rng(1), 0.0, 0.0, origin)
    assert np.allclose(np.linalg.norm(np.diff(exact[:, :2], axis=0), axis=1), 1.2 * steps)


def test_drifting_alignment_still_maps_the_current_pose():
    seq = simulate("office", SimSettings(odom_translation_noise=0.05, odom_yaw_noise_deg=1.0), seed=7,
                   n_frames=40)
    for k in (0, 20, 39):
        assert np.allclose(seq.alignments[k].apply(seq.odom[k, :2]), seq.poses[k, :2])
        assert wrap_angle(seq.odom[k, 2] + seq.alignments[k].theta - seq.poses[k, 2]) == pytest.approx(0, abs=1e-9)
    thetas = [a.theta for a in seq.alignments]
    assert np.ptp(np.unwrap(thetas)) > np.radians(1)  # it drifts


def test_segmentation_errors():
    base = {**QUIET, "max_pitch_deg": 0, "max_roll_deg": 0}
    clean = simulate("apartment", SimSettings(**base), seed=8, n_frames=10)
    assert any((f.labels == OTHER).any() for f in clean)
    all_wall = simulate("apartment", SimSettings(**{**base, "furniture_as_wall_prob": 1.0}), seed=8, n_frames=10)
    assert all_wall.mislabelled_furniture.all()
    assert not any((f.labels == OTHER).any() for f in all_wall)
    drop = simulate("apartment", SimSettings(**{**base, "wall_dropout": 0.3}), seed=8, n_frames=10)
    fractions = []
    for f_clean, f_drop in zip(clean, drop):
        walls = f_clean.labels == WALL
        fractions.append((f_drop.labels[walls] == UNKNOWN).mean())
    assert np.mean(fractions) == pytest.approx(0.3, abs=0.03)


def test_pitch_and_roll_within_limits():
    seq = simulate("rooms", SimSettings(max_pitch_deg=20, max_roll_deg=5), seed=9, n_frames=60)
    assert np.abs(seq.pitch).max() <= np.radians(20) and np.abs(seq.roll).max() <= np.radians(5)
    assert np.abs(seq.pitch).max() > np.radians(12)
    # the optical axis elevation seen in T_odom_cam is the pitch (gravity-aligned odometry)
    elevation = [np.arcsin(seq.T_odom_cam(k)[2, 2]) for k in range(len(seq))]
    assert np.allclose(elevation, seq.pitch)


def test_bad_inputs_raise_package_errors():
    with pytest.raises(ConfigError):
        SimSettings.load({"widht": 100})
    with pytest.raises(ConfigError):
        SimSettings.load({"hfov_deg": 200})
    with pytest.raises(InputError):
        simulate("rooms", n_frames=0)
    with pytest.raises(InputError):
        simulate("rooms", trajectory=np.zeros((4, 2)))
    with pytest.raises(InputError):
        simulate("nowhere")
    with pytest.raises(ConfigError):
        simulate("rooms", SimSettings(step_min=0.6, step_max=0.4), n_frames=3)


# --- laser ---------------------------------------------------------------------------------


def test_laser_sequence():
    settings = dict(fov_deg=270, n_beams=271, odom_translation_noise=0.0, odom_yaw_noise_deg=0.0)
    seq = simulate_laser("hall", LaserSimSettings(**settings, furniture_occludes=False), seed=1, n_frames=8)
    assert len(seq) == 8 and all(isinstance(f, LaserFrame) for f in seq)
    f = seq[0]
    assert f.angle_min == pytest.approx(-np.radians(135)) and f.ranges.shape == (271,)
    # through the odometry pose and the true alignment, hits land on the floorplan's walls
    for k in (0, 7):
        f = seq[k]
        ok = f.valid
        a = f.angles[ok] + seq.odom[k, 2]
        pts_odom = seq.odom[k, :2] + f.ranges[ok, None] * np.stack([np.cos(a), np.sin(a)], 1)
        d = seq.scene.floorplan.distance(seq.alignments[k].apply(pts_odom))
        assert np.mean(d < 0.1) > 0.99
    # furniture taller than the scanner blocks beams: never longer, sometimes shorter
    cluttered = simulate_laser("hall", LaserSimSettings(**settings), seed=1, n_frames=8)
    r_free = np.concatenate([f.ranges for f in seq])
    r_clut = np.concatenate([f.ranges for f in cluttered])
    both = np.isfinite(r_free) & np.isfinite(r_clut)
    assert (r_clut[both] <= r_free[both] + 0.1).all() and (r_clut[both] < r_free[both] - 0.3).any()


def test_laser_range_noise_statistics():
    quiet = LaserSimSettings(range_noise=0.0)
    noisy = LaserSimSettings(range_noise=0.02)
    a = simulate_laser("apartment", quiet, seed=2, n_frames=5)
    b = simulate_laser("apartment", noisy, seed=2, n_frames=5)
    diff = np.concatenate([fb.ranges[fa.valid] - fa.ranges[fa.valid] for fa, fb in zip(a, b)])
    assert diff.std() == pytest.approx(0.02, rel=0.15) and abs(diff.mean()) < 0.003
    assert np.array_equal(a.poses, b.poses)


def test_given_trajectory_is_used_whole_unless_cut():
    scene = build_scene("rooms", 0)
    walk = random_walk(scene, make_rng(3, "w"), 130)
    seq = simulate(scene, SimSettings(), seed=0, trajectory=walk)
    assert len(seq) == 130 and np.array_equal(seq.poses, walk)
    assert len(simulate(scene, SimSettings(), seed=0, trajectory=walk, n_frames=10)) == 10
    assert len(simulate(scene, SimSettings(), seed=0)) == 100
    assert len(simulate_laser(scene, seed=0, trajectory=walk[:20])) == 20
