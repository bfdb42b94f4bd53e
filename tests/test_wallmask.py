import numpy as np
import pytest
from benchmarks.inputs.box_world import (
    camera_pose,
    camera_sequence,
    distance_to_true_walls,
    intrinsics,
    plane_to_world,
    render,
    room_scene,
    world_points,
    world_to_plane,
)

from zfloc_stream.settings.loading import WallMaskSettings, load_settings
from zfloc_stream.frames import CEILING, FLOOR, OTHER, WALL
from zfloc_stream.frontend.bev import RollingBEV
from zfloc_stream.frontend.labeller import depth_normals, label_frame
from zfloc_stream.frontend.wallmask import refine_wall_mask, upright_rotation
from zfloc_stream.runtime.rng import make_rng

W, H = 160, 120
K = intrinsics(W, H)
GRAVITY = np.array([0.0, 0.0, -1.0])  # world frame


def view(x, y, yaw, tilt_axis=(1, 0, 0), tilt=0.0):
    T = camera_pose(x, y, 1.4, yaw, tilt_axis, tilt)
    depth, labels = render(room_scene(), T, K, W, H)
    return depth, labels, T, world_points(depth, K, T)


def inside(p, lo, hi, tol=0.02):
    return np.all((p >= np.array(lo) - tol) & (p <= np.array(hi) + tol), axis=-1)


@pytest.mark.parametrize("tilt", [0.0, 15.0])
def test_furniture_labelled_wall_is_removed_and_the_wall_behind_kept(tilt):
    depth, labels, T, P = view(1.0, 4.3, 0.0, (0.3, 0.2, 1.0), np.deg2rad(tilt))
    cabinet = inside(P, (3.0, 4.0, 0), (4.0, 4.6, 1.2)) & (labels == WALL)
    back_wall = (np.abs(P[..., 0] - 8.0) < 0.02) & (labels == WALL)
    assert cabinet.sum() > 100 and back_wall.sum() > 100
    refined = refine_wall_mask(depth, labels, K, upright_rotation(T[:3, :3], GRAVITY), WallMaskSettings())
    assert refined[cabinet].mean() < 0.05
    assert refined[back_wall].mean() > 0.6
    assert not (refined & (labels != WALL)).any()  # never adds pixels


def test_door_lintel_is_dropped_and_far_wall_through_the_door_kept():
    depth, labels, T, P = view(6.0, 3.0, 0.0)
    lintel = inside(P, (7.98, 2.55, 2.1), (8.1, 3.45, 2.6), tol=0.0) & (labels == WALL)
    far = (np.abs(P[..., 0] - 12.0) < 0.02) & (np.abs(P[..., 1] - 3.0) < 0.45)
    assert lintel.sum() > 20 and far.sum() > 20
    refined = refine_wall_mask(depth, labels, K, upright_rotation(T[:3, :3], GRAVITY), WallMaskSettings())
    assert not refined[lintel].any()
    assert refined[far].mean() > 0.8


def test_disabled_mask_is_the_raw_wall_label():
    depth, labels, T, _ = view(1.0, 4.3, 0.0)
    raw = refine_wall_mask(depth, labels, K, np.eye(3), WallMaskSettings(enabled=False))
    assert np.array_equal(raw, labels == WALL)


def test_upright_rotation_levels_a_tilted_camera():
    T = camera_pose(0, 0, 1.4, 0.7, (1.0, 0.5, 0.2), np.deg2rad(20))
    R_up = upright_rotation(T[:3, :3], GRAVITY)
    assert np.allclose(R_up @ R_up.T, np.eye(3)) and np.isclose(np.linalg.det(R_up), 1)
    g_up = R_up @ T[:3, :3].T @ GRAVITY
    assert np.allclose(g_up, [0, 1, 0])  # gravity is the upright image's +y
    z_world = T[:3, :3] @ R_up.T @ [0, 0, 1]
    assert abs(z_world[2]) < 1e-12  # the upright optical axis is horizontal...
    assert np.arctan2(z_world[1], z_world[0]) == pytest.approx(np.arctan2(T[1, 2], T[0, 2]))  # ...same heading


def fuse(frames, wall_mask: bool):
    bev = RollingBEV(load_settings(overrides=[f"frontend.wall_mask.enabled={str(wall_mask).lower()}"]))
    for f in frames:
        bev.add(f)
    return bev


def ghost_and_true(bev, T_odom_world):
    obs = bev.observation(make_rng(0, "obs"))
    d = distance_to_true_walls(plane_to_world(bev, T_odom_world)(obs.wall_points))
    return int((d > 0.2).sum()), int((d <= 0.2).sum()), obs


def door_state(bev, obs, T_odom_world):
    door = np.stack([np.full(9, 8.05), np.linspace(2.7, 3.3, 9)], 1)
    p = world_to_plane(bev, T_odom_world)(door)
    near_door_wall = np.min(np.linalg.norm(obs.wall_points[:, None] - p[None], axis=2), axis=0) < 0.1
    return obs.free_at(p), near_door_wall


def check_ghost_reduction(seed, n_frames):
    rng = make_rng(seed, "wallmask-seq")
    frames, T_odom_world = camera_sequence(rng, n_frames, noise=0.0015)
    ghost_on, true_on, obs_on = ghost_and_true(on := fuse(frames, True), T_odom_world)
    ghost_off, true_off, obs_off = ghost_and_true(off := fuse(frames, False), T_odom_world)
    assert ghost_off > 50  # the scene does produce ghosts without the mask
    assert ghost_on <= 0.2 * ghost_off, (ghost_on, ghost_off)
    assert true_on >= 0.6 * true_off, (true_on, true_off)
    free, wall = door_state(on, obs_on, T_odom_world)
    assert free.mean() >= 0.8 and not wall.any()  # the door stays open
    _, wall_off = door_state(off, obs_off, T_odom_world)
    return ghost_on, ghost_off, true_on, true_off, wall_off.any()


def test_wall_mask_removes_ghosts_keeps_walls_and_doors_in_the_bev():
    _, _, _, _, door_blocked_without_mask = check_ghost_reduction(0, 30)
    assert door_blocked_without_mask  # the lintel closes the door when the mask is off


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(1, 8))
def test_wall_mask_ghost_reduction_over_seeds(seed):
    check_ghost_reduction(seed, 40)


def test_geometric_labeller_matches_rendered_labels():
    rng = make_rng(7, "labeller")
    frames, T_odom_world = camera_sequence(rng, 4, labels=True, noise=0.0015)
    bev = RollingBEV(load_settings())
    for f in frames:
        bev.add(f)
    s = load_settings().frontend
    f = frames[-1]
    R = bev.gravity.R_plane_odom
    v, u = np.mgrid[0 : f.shape[0], 0 : f.shape[1]]
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(f.K).T
    pts = ((rays * f.depth[..., None]) @ f.T_odom_cam[:3, :3].T + f.T_odom_cam[:3, 3]) @ R.T
    valid = f.depth > 0
    # full resolution here, as the BEV does on images this small (stride 1)
    assert bev.pixel_stride(f.shape) == 1
    normals = depth_normals(pts, f.depth, valid, s.labeller.normal_step)
    labels = label_frame(pts[..., 2] - bev.gravity.floor_height, normals, valid, s.labeller)
    truth = f.labels
    for code, min_recall in ((FLOOR, 0.9), (CEILING, 0.85), (WALL, 0.6)):
        sel = truth == code
        if sel.sum() > 50:
            assert (labels[sel] == code).mean() > min_recall, code
    # geometric "wall" on true building walls, not on the table (labelled OTHER)
    called_wall = labels == WALL
    assert (truth[called_wall] != OTHER).mean() > 0.9


# --- on the simulator's scenes: every furniture piece labelled wall --------------------------
def sim_ghosts(scene, seed, n_frames):
    """(ghost, true) BEV wall cells with the mask on and off; ghosts lie > 0.2 m from every
    floorplan wall. No odometry drift or scale error, so one alignment maps the BEV."""
    from zfloc_stream.sim.simulator import SimSettings, simulate

    s = SimSettings(
        max_pitch_deg=20, max_roll_deg=20, furniture_as_wall_prob=1.0,
        odom_translation_noise=0, odom_yaw_noise_deg=0, scale_error=0,
    )
    seq = simulate(scene, s, seed=seed, n_frames=n_frames)
    frames = seq.frames
    out = {}
    for on in (True, False):
        bev = fuse(frames, on)
        obs = bev.observation(make_rng(0, "obs"))
        # plane -> odometry plane (gravity-aligned odometry here) -> floorplan
        lifted = np.c_[obs.wall_points, np.full(len(obs.wall_points), bev.gravity.floor_height + 1.0)]
        d = seq.scene.floorplan.distance(seq.alignment.apply((lifted @ bev.gravity.R_plane_odom)[:, :2]))
        out[on] = np.array([(d > 0.2).sum(), (d <= 0.2).sum()])
    return out[True], out[False]


def test_wall_mask_on_a_simulated_scene():
    on, off = sim_ghosts("rooms", 0, 30)
    assert off[0] > 50
    assert on[0] <= 0.2 * off[0] and on[1] >= 0.6 * off[1]


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["rooms", "office", "hall"])
def test_wall_mask_on_simulated_scenes(scene):
    on, off = np.sum([sim_ghosts(scene, seed, 40) for seed in range(3)], axis=0)
    assert on[0] <= 0.2 * off[0] and on[1] >= 0.6 * off[1]
