import numpy as np
import pytest
from benchmarks.inputs.box_world import camera_sequence

from zfloc_stream.settings.loading import GravitySettings, load_settings
from zfloc_stream.errors import InputError
from zfloc_stream.frames import WALL, CameraFrame
from zfloc_stream.frontend.bev import RollingBEV
from zfloc_stream.frontend.gravity import GravityEstimator, fit_plane, plane_pose, rotation_from_up
from zfloc_stream.runtime.rng import make_rng


def angle_deg(a, b):
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1))))


def test_fit_plane_ignores_outliers():
    rng = make_rng(0, "plane")
    n_true = np.array([0.2, -0.1, 1.0])
    n_true /= np.linalg.norm(n_true)
    basis = np.linalg.svd(n_true[None])[2][1:]  # two in-plane directions
    pts = rng.uniform(-3, 3, (800, 2)) @ basis + 1.5 * n_true + rng.normal(0, 0.005, (800, 1)) * n_true
    outliers = rng.uniform(-3, 3, (400, 3))
    n, c, inliers = fit_plane(np.concatenate([pts, outliers]), rng)
    assert min(angle_deg(n, n_true), angle_deg(-n, n_true)) < 0.5
    assert abs(abs(c) - 1.5) < 0.02
    assert inliers[:800].mean() > 0.95 and inliers[800:].mean() < 0.1
    with pytest.raises(InputError):
        fit_plane(np.zeros((2, 3)), rng)


def test_rotation_from_up_keeps_odom_x_heading():
    up = np.array([0.1, 0.2, 0.95])
    R = rotation_from_up(up)
    assert np.allclose(R @ R.T, np.eye(3)) and np.isclose(np.linalg.det(R), 1)
    assert np.allclose(R @ (up / np.linalg.norm(up)), [0, 0, 1])
    x_plane = R @ [1.0, 0, 0]
    assert abs(x_plane[1]) < 1e-12 and x_plane[0] > 0  # odom x projects onto plane x
    assert np.allclose(rotation_from_up([1.0, 0, 0]) @ [1.0, 0, 0], [0, 0, 1])  # degenerate case


def gravity_errors(seeds, n_frames, labels=True):
    errors, height_errors = [], []
    for seed in seeds:
        rng = make_rng(seed, "gravity-seq")
        frames, T_odom_world = camera_sequence(rng, n_frames, max_tilt_deg=20.0, labels=labels, noise=0.0015)
        bev = RollingBEV(load_settings(overrides={"seed": seed}))
        for f in frames:
            bev.add(f)
        assert bev.gravity.ready and bev.pending_frames == 0 and bev.frames_fused == n_frames
        up_true = T_odom_world[:3, :3] @ [0, 0, 1]
        errors.append(angle_deg(bev.gravity.up_odom, up_true))
        floor_true = bev.gravity.R_plane_odom[2] @ T_odom_world[:3, 3]  # world z = 0
        height_errors.append(abs(bev.gravity.floor_height - floor_true))
    return np.array(errors), np.array(height_errors)


def test_gravity_error_below_one_degree_with_tilted_cameras():
    err, h_err = gravity_errors(range(4), 6)
    assert np.median(err) < 1.0 and err.max() < 2.0
    assert np.median(h_err) < 0.03


def test_gravity_from_unlabelled_frames():
    err, h_err = gravity_errors(range(2), 6, labels=False)
    assert np.median(err) < 1.0 and np.median(h_err) < 0.05


@pytest.mark.slow
def test_gravity_error_statistics_over_many_sequences():
    for labels in (True, False):
        err, h_err = gravity_errors(range(30), 10, labels=labels)
        assert np.median(err) < 1.0, labels
        assert np.quantile(err, 0.9) < 2.0, labels


def test_trust_odometry_takes_odom_z_and_estimates_floor_height():
    rng = make_rng(1, "trust")
    frames, T_odom_world = camera_sequence(rng, 3, odom_tilt_deg=0.0)
    bev = RollingBEV(load_settings(overrides=["frontend.gravity.trust_odometry=true"]))
    bev.add(frames[0])
    assert bev.gravity.ready and bev.frames_fused == 1  # no waiting
    assert np.allclose(bev.gravity.R_plane_odom, np.eye(3))
    assert bev.gravity.floor_height == pytest.approx(T_odom_world[2, 3], abs=0.02)


def test_frames_wait_for_gravity_in_a_bounded_buffer():
    settings = load_settings(overrides=["frontend.gravity.max_pending_frames=3"])
    bev = RollingBEV(settings)
    rng = make_rng(2, "pending")
    frames, _ = camera_sequence(rng, 8)
    walls_only = [
        CameraFrame(f.depth, np.full(f.depth.shape, WALL, dtype=np.uint8), f.K, f.T_odom_cam, f.timestamp)
        for f in frames[:6]
    ]
    for f in walls_only:  # no floor: gravity cannot be estimated
        bev.add(f)
    assert not bev.gravity.ready and bev.frames_fused == 0
    assert bev.pending_frames == 3 and bev.frames_dropped == 3
    x, y, yaw = bev.plane_pose(walls_only[-1])  # provisional pose still available
    assert np.isfinite([x, y, yaw]).all()
    for f in frames[6:]:
        bev.add(f)
    assert bev.gravity.ready and bev.pending_frames == 0 and bev.frames_fused == 3  # the buffer's 3


def test_gravity_sign_and_plane_pose():
    rng = make_rng(4, "pose")
    frames, T_odom_world = camera_sequence(rng, 6, max_tilt_deg=10.0)
    bev = RollingBEV(load_settings())
    for f in frames:
        bev.add(f)
    R = bev.gravity.R_plane_odom
    # cameras are 1.3-1.5 m above the floor: up points from the floor to the cameras
    heights = [R[2] @ f.T_odom_cam[:3, 3] - bev.gravity.floor_height for f in frames]
    assert np.all((np.array(heights) > 1.2) & (np.array(heights) < 1.6))
    # plane yaw = world heading of the optical axis + one constant (the odom heading)
    T_world_odom = np.linalg.inv(T_odom_world)
    offsets = []
    for f in frames:
        axis = T_world_odom[:3, :3] @ f.T_odom_cam[:3, 2]
        offsets.append(bev.plane_pose(f)[2] - np.arctan2(axis[1], axis[0]))
    spread = np.angle(np.exp(1j * (np.array(offsets) - offsets[0])))
    assert np.abs(spread).max() < np.deg2rad(0.5)
    # a laser pose is read in the odometry plane directly (x axis heading)
    T = np.eye(4)
    T[:2, :2] = [[0, -1], [1, 0]]
    T[:3, 3] = [1, 2, 0.3]
    assert np.allclose(plane_pose(T, np.eye(3), "x"), (1, 2, np.pi / 2))


def test_gravity_estimator_is_deterministic():
    rng = make_rng(5, "det")
    frames, _ = camera_sequence(rng, 3)

    def run():
        bev = RollingBEV(load_settings())
        for f in frames:
            bev.add(f)
        return bev.gravity.R_plane_odom, bev.gravity.floor_height

    (Ra, ha), (Rb, hb) = run(), run()
    assert np.array_equal(Ra, Rb) and ha == hb


# --- on the simulator's scenes (tilted odometry frame, pitch/roll up to 20 deg) ------------
def sim_gravity_errors(scene, seeds, n_frames, labels):
    from zfloc_stream.sim.simulator import SimSettings, simulate

    errors = []
    for seed in seeds:
        s = SimSettings(max_pitch_deg=20, max_roll_deg=20, odom_gravity_aligned=False, use_labels=labels)
        seq = simulate(scene, s, seed=seed, n_frames=n_frames)
        bev = RollingBEV(load_settings(overrides={"seed": seed}))
        for f in seq:
            bev.add(f)
        errors.append(angle_deg(bev.gravity.up_odom, seq.odom_tilt[:3, :3] @ [0, 0, 1]))
    return np.array(errors)


@pytest.mark.parametrize("labels", [True, False])
def test_gravity_on_simulated_sequences(labels):
    err = sim_gravity_errors("rooms", range(2), 8, labels)
    assert np.median(err) < 1.0


@pytest.mark.slow
def test_gravity_on_simulated_sequences_all_scenes():
    for scene in ("rooms", "apartment", "office", "hall"):
        for labels in (True, False):
            err = sim_gravity_errors(scene, range(5), 12, labels)
            assert np.median(err) < 1.0, (scene, labels)


def test_asking_for_poses_before_gravity_does_not_change_it():
    rng = make_rng(6, "provisional")
    frames, _ = camera_sequence(rng, 4)
    settings = load_settings(overrides=["frontend.gravity.min_frames=3"])
    quiet, asking = RollingBEV(settings), RollingBEV(settings)
    for f in frames:
        quiet.add(f)
        asking.add(f)
        asking.plane_pose(f)  # provisional fits while gravity is unknown
    assert np.array_equal(quiet.gravity.R_plane_odom, asking.gravity.R_plane_odom)


def test_gravity_estimator_freezes_after_enough_frames_and_points():
    rng = make_rng(8, "estimator")
    up = np.array([0.1, -0.05, 1.0])
    up /= np.linalg.norm(up)
    basis = np.linalg.svd(up[None])[2][1:]
    settings = GravitySettings(min_frames=2, min_floor_points=300)
    est = GravityEstimator(settings, make_rng(0, "g"))
    camera = 1.5 * up  # above the floor plane through the origin
    for frame in range(2):
        assert not est.ready
        floor = rng.uniform(-4, 4, (400, 2)) @ basis + rng.normal(0, 0.005, (400, 1)) * up
        table = rng.uniform(-0.5, 0.5, (100, 2)) @ basis + 0.75 * up  # not the floor
        est.add_floor_points(np.concatenate([floor, table]), camera)
    assert est.ready
    assert angle_deg(est.up_odom, up) < 0.3  # signed: up, towards the cameras
    assert est.floor_height == pytest.approx(0.0, abs=0.01)  # table tops do not lift the floor
    assert est.buffered_bytes == 0  # points are released once gravity is frozen
    est.observe_floor_heights(np.full(10, 0.1))  # slow vertical drift is followed
    assert 0.0 < est.floor_height < 0.1
