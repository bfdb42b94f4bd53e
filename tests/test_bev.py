import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.errors import ConfigError, FrameError, InputError
from zfloc_stream.frames import LaserFrame
from zfloc_stream.frontend.bev import RollingBEV
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.geometry.sim2 import Sim2, wrap_angle

ROOM = (0.0, 0.0, 10.0, 6.0)  # x0, y0, x1, y1: an empty rectangular room


def pose(x, y, yaw, z=0.0):
    T = np.eye(4)
    c, s = np.cos(yaw), np.sin(yaw)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = [x, y, z]
    return T


def box_ranges(x, y, yaw, angles, box=ROOM):
    """Exact ranges from (x, y) inside an axis-aligned box."""
    x0, y0, x1, y1 = box
    a = yaw + angles
    c, s = np.cos(a), np.sin(a)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (x1 - x) / c, np.where(c < 0, (x0 - x) / c, np.inf))
        ty = np.where(s > 0, (y1 - y) / s, np.where(s < 0, (y0 - y) / s, np.inf))
    return np.minimum(tx, ty)


def laser(x, y, yaw, n=360, fov=2 * np.pi, noise=0.0, rng=None, box=ROOM, t=0.0):
    angles = -fov / 2 + fov * np.arange(n) / n
    r = box_ranges(x, y, yaw, angles, box)
    if noise:
        r = r + rng.normal(0, noise, r.shape)
    return LaserFrame(r, -fov / 2, fov / n, 0.05, 30.0, pose(x, y, yaw), t)


def distance_to_box_walls(p, box=ROOM):
    x0, y0, x1, y1 = box
    return np.min(np.abs(np.stack([p[:, 0] - x0, p[:, 0] - x1, p[:, 1] - y0, p[:, 1] - y1])), axis=0)


def test_laser_hits_land_on_walls_and_interior_is_free():
    bev = RollingBEV(Settings())
    rng = make_rng(0, "test")
    for i, (x, y) in enumerate([(2, 2), (3, 3), (5, 3), (7, 2.5), (8, 4)]):
        bev.add(laser(x, y, 0.3 * i, noise=0.01, rng=rng, t=i))
    obs = bev.observation(make_rng(0, "obs"))
    d = distance_to_box_walls(obs.wall_points)
    assert len(obs.wall_points) > 300
    assert np.quantile(d, 0.99) < 0.1  # every wall point within two cells of a true wall
    inner = np.stack(np.meshgrid(np.linspace(1, 9, 30), np.linspace(1, 5, 20)), -1).reshape(-1, 2)
    assert obs.free_at(inner).mean() > 0.95
    outside = np.array([[-1.0, 3.0], [11.0, 3.0], [5.0, -1.0], [5.0, 7.5]])
    assert not obs.free_at(outside).any()  # nothing seen behind the walls
    # clearance: ~ distance to the nearest wall inside the room, 0 outside free space
    c = obs.clearance_at(np.array([[5.0, 3.0], [1.0, 3.0]]))
    assert c[0] == pytest.approx(3.0, abs=0.15) and c[1] == pytest.approx(1.0, abs=0.15)
    assert obs.clearance_at(outside).max() == 0.0
    assert obs.trajectory.shape == (5, 3)
    assert np.allclose(obs.trajectory[-1], [8, 4, 1.2])


def test_laser_lines_are_extracted():
    bev = RollingBEV(Settings())
    for i, (x, y) in enumerate([(2, 2), (5, 3), (8, 4)]):
        bev.add(laser(x, y, 0.0, t=i))
    obs = bev.observation(make_rng(0, "obs"))
    assert len(obs.lines) >= 4
    n = np.abs(obs.lines.normals)
    assert np.all((n.max(axis=1) > 0.99))  # axis-aligned walls


def test_empty_bev_raises_input_error():
    bev = RollingBEV(Settings())
    with pytest.raises(InputError, match="empty"):
        bev.observation(make_rng(0))
    with pytest.raises(FrameError):
        bev.add("not a frame")


def test_bad_bev_settings_raise_config_error():
    with pytest.raises(ConfigError):
        RollingBEV(load_settings(overrides=["bev.resolution=0"]))


def test_grid_scrolls_and_memory_stays_flat_along_a_long_corridor():
    # a 200 m corridor, 2 m wide: walk along it; the grid must scroll and keep its size
    settings = load_settings(overrides=["bev.window_radius=5.0"])
    bev = RollingBEV(settings)
    box = (0.0, 0.0, 200.0, 2.0)
    sizes = []
    for i in range(150):
        x = 1.0 + i * 1.3
        bev.add(laser(x, 1.0, 0.0, n=180, box=box, t=i))
        sizes.append(bev.memory_bytes())
    assert sizes[-1] == sizes[10]  # flat: fixed grid + bounded buffers
    obs = bev.observation(make_rng(0))
    # only the last window survives: every wall point is near the sensor
    d = np.hypot(*(obs.wall_points - [x, 1.0]).T)
    assert d.max() < 5.0 + 1.0 + 0.5 * np.sqrt(2) * 2
    side = obs.wall_points[:, 0] < 199.9  # the rest lies on the end wall x = 200
    assert np.all(np.abs(obs.wall_points[side, 1] - 1.0) > 0.9)  # on the corridor walls y=0, y=2
    assert obs.free_at(np.array([[x - 2.0, 1.0]])).all()
    assert not obs.free_at(np.array([[20.0, 1.0]])).any()  # far behind: dropped


def test_same_input_same_observation():
    def run():
        bev = RollingBEV(Settings())
        rng = make_rng(3, "noise")
        for i in range(4):
            bev.add(laser(2 + i, 3, 0.2 * i, noise=0.02, rng=rng, t=i))
        return bev.observation(make_rng(0, "obs"))

    a, b = run(), run()
    assert np.array_equal(a.wall_points, b.wall_points)
    assert np.array_equal(a.free, b.free)
    assert np.array_equal(a.lines.offsets, b.lines.offsets)


def test_camera_fusion_puts_walls_on_walls_and_memory_stays_flat():
    from benchmarks.inputs.box_world import CameraFrame, camera_sequence, distance_to_true_walls, plane_to_world

    frames, T_odom_world = camera_sequence(make_rng(0, "bev-camera"), 12, noise=0.0015)
    bev = RollingBEV(Settings())  # cameras are not scan matched by default: the plane frame is the odometry's
    for f in frames:
        bev.add(f)
    obs = bev.observation(make_rng(0, "obs"))
    d = distance_to_true_walls(plane_to_world(bev, T_odom_world)(obs.wall_points))
    assert len(d) > 300 and np.median(d) < 0.05 and (d < 0.2).mean() > 0.95
    # the camera path keeps a fixed footprint while the odometry carries it 60 m away
    sizes = []
    for i in range(40):
        f = frames[i % len(frames)]
        T = f.T_odom_cam.copy()
        T[:3, 3] += 1.5 * i * T_odom_world[:3, 0]  # along world x
        bev.add(CameraFrame(f.depth, f.labels, f.K, T, f.timestamp))
        sizes.append(bev.memory_bytes())
    assert len(set(sizes)) == 1
    assert bev.observation(make_rng(0)).free.size <= bev.grid.n**2


def test_clear_map_forgets_the_grid_but_keeps_the_trajectory():
    bev = RollingBEV(Settings())
    for i in range(3):
        bev.add(laser(2 + i, 3, 0.0, t=i))
    bev.clear_map()
    with pytest.raises(InputError, match="empty"):
        bev.observation(make_rng(0))
    assert len(bev.trajectory) == 3
    bev.add(laser(6, 3, 0.0, t=4))
    assert len(bev.observation(make_rng(0)).wall_points) > 100


def test_upside_down_laser_and_negative_increment():
    # the same room seen by a scanner mounted upside down (sensor y, z flipped) whose
    # beams run clockwise: beam directions come from the pose, not from the yaw alone
    x, y, yaw = 4.0, 3.0, 0.5
    n = 360
    angles = np.pi - 2 * np.pi * np.arange(n) / n  # decreasing
    flip = np.diag([1.0, -1.0, -1.0])  # upside down: sensor angle a points at world angle -a
    T = pose(x, y, yaw)
    T[:3, :3] = T[:3, :3] @ flip
    r = box_ranges(x, y, yaw, -angles)
    scan = LaserFrame(r, np.pi, -2 * np.pi / n, 0.05, 30.0, T, 0.0)
    bev = RollingBEV(Settings())
    bev.add(scan)
    obs = bev.observation(make_rng(0))
    assert np.quantile(distance_to_box_walls(obs.wall_points), 0.99) < 0.1
    inner = np.stack(np.meshgrid(np.linspace(1, 9, 20), np.linspace(1, 5, 10)), -1).reshape(-1, 2)
    assert obs.free_at(inner).mean() > 0.95


def test_memory_frames_forgets_cells_no_recent_frame_touched():
    # two rooms along x: first scans see room A only, the later ones room B only
    room_a, room_b = (0.0, 0.0, 6.0, 6.0), (8.0, 0.0, 14.0, 6.0)  # both inside the 15 m window

    def walk(memory):
        bev = RollingBEV(load_settings(overrides=[f"bev.memory_frames={memory}"]))
        for i in range(5):
            bev.add(laser(3.0, 3.0, 0.2 * i, box=room_a, t=i))
        for i in range(5, 10):
            bev.add(laser(11.0, 3.0, 0.2 * i, box=room_b, t=i))
        return bev.observation(make_rng(0, "obs"))

    kept, forgotten = walk(0), walk(5)
    assert (kept.wall_points[:, 0] < 7).any()  # without a memory room A stays in the view
    assert not (forgotten.wall_points[:, 0] < 7).any()  # older than 5 frames: gone
    assert (forgotten.wall_points[:, 0] > 7.9).sum() == (kept.wall_points[:, 0] > 7.9).sum()  # room B untouched
    assert not forgotten.free_at(np.array([[3.0, 3.0]])).any()  # room A's free space is unknown again
    assert kept.free_at(np.array([[3.0, 3.0]])).all()
    # a run no longer than the memory (10 frames) is the run without one, bit for bit:
    # the default (300) leaves every run of up to 300 frames as it was
    full = walk(10)
    for name in ("wall_points", "free", "clearance"):
        assert np.array_equal(getattr(full, name), getattr(kept, name))
    assert np.array_equal(full.lines.endpoints, kept.lines.endpoints)


def test_scan_matching_keeps_the_map_sharp_under_drifting_odometry():
    # The sensor walks through the room while its odometry heading drifts 1 deg and its
    # position 2 cm per frame. Fused from raw odometry the walls smear; with
    # bev.scan_match each scan is matched to the walls fused so far, so the walls stay where
    # the first frame put them and the corrected pose follows the truth.
    def walk(scan_match):
        bev = RollingBEV(load_settings(overrides=[f"bev.scan_match={'laser' if scan_match else 'none'}"]))
        drift = Sim2(1.0, 0.0)
        errors = []
        for i in range(30):
            x, y, yaw = 2.0 + 0.2 * i, 2.0 + 0.05 * i, 0.05 * i
            if i:  # frame 0's odometry plane is the truth; from there on the odometry drifts
                drift = Sim2(1.0, np.deg2rad(1.0), (0.02, -0.01)) @ drift
            ox, oy, oyaw = drift.inverse().apply_pose(x, y, yaw)
            frame = laser(x, y, yaw, n=360, t=i)
            frame = LaserFrame(frame.ranges, frame.angle_min, frame.angle_increment, 0.05, 30.0, pose(ox, oy, oyaw), i)
            bev.add(frame)
            px, py, pyaw = bev.plane_pose(frame)
            errors.append(np.hypot(px - x, py - y))
        obs = bev.observation(make_rng(0, "obs"))
        return np.quantile(distance_to_box_walls(obs.wall_points), 0.9), max(errors)

    smeared, drifted = walk(False)
    sharp, tracked = walk(True)
    assert smeared > 0.5 and drifted > 1.0  # the drift is real (measured: 2.4 m and 3.8 m)
    assert sharp < 0.05  # 90% of the wall points within 5 cm of a true wall (measured: 0.025 m)
    assert tracked < 0.1  # (measured: 0.036 m)


def test_scan_matching_corrects_a_sparse_log_whose_turns_odometry_underreports():
    # Scans 0.6 m and 60 deg apart (a sparse log, like the shared orebro log's 1 m and up
    # to 76 deg), the odometry reporting each turn 10% short: 6 deg per frame, more than
    # scan_match_max_angle_deg (5) alone allows and, at the room's 5-8 m ranges, hits
    # 0.5-0.8 m off, beyond the LM's loss cutoff (0.3 m). The bounds grow with the turn
    # (scan_match_angle_per_turn) and the coarse search finds the basin: the heading stays
    # within a degree. Without the growth each correction is refused and the heading drifts.
    def final_heading_error(overrides):
        bev = RollingBEV(load_settings(overrides=["bev.scan_match=laser", *overrides]))
        reported = 0.0
        for i in range(8):
            x, y, yaw = 5.0 + 0.6 * np.cos(i), 3.0 + 0.6 * np.sin(i), np.deg2rad(60.0) * i
            frame = laser(x, y, yaw, n=360, t=i)
            if i:
                reported += np.deg2rad(54.0)
            # the odometry's position is exact: only its heading drifts
            frame = LaserFrame(frame.ranges, frame.angle_min, frame.angle_increment, 0.05, 30.0, pose(x, y, reported), i)
            bev.add(frame)
            heading_error = np.rad2deg(abs(wrap_angle(bev.plane_pose(frame)[2] - yaw)))
        return heading_error

    assert final_heading_error([]) < 1.0  # (measured: 0.0x deg)
    drifted = final_heading_error(["bev.scan_match_angle_per_turn=0", "bev.scan_match_shift_per_step=0"])
    assert drifted > 20.0  # 7 turns x 6 deg, none corrected (measured: 42 deg)


def test_scan_matching_bounds_grow_with_the_odometry_step_and_turn():
    from zfloc_stream.frontend.scan_match import step_bounds

    b = load_settings(overrides=["bev.scan_match_max_shift=0.3", "bev.scan_match_max_angle_deg=5",
                                 "bev.scan_match_shift_per_step=0.2", "bev.scan_match_angle_per_turn=0.1"]).bev
    assert step_bounds(None, (1.0, 2.0, 0.3), b) == (0.3, pytest.approx(np.deg2rad(5.0)))
    # standing still (or carried off while the odometry stood still): the base bounds
    assert step_bounds((1.0, 2.0, 0.3), (1.0, 2.0, 0.3), b) == (pytest.approx(0.3), pytest.approx(np.deg2rad(5.0)))
    # 3-4-5 m step and a 60 deg turn across the +-pi seam
    shift, angle = step_bounds((0.0, 0.0, np.pi - 0.5), (3.0, 4.0, -np.pi + np.deg2rad(60.0) - 0.5), b)
    assert shift == pytest.approx(0.3 + 0.2 * 5.0) and angle == pytest.approx(np.deg2rad(5.0 + 6.0))


# --- the observation's grids ----------------------------------------------------------------


def _assert_same_observation(a, b):
    """Two observations (or the InputErrors both raised) equal bit for bit."""
    assert type(a) is type(b)
    if isinstance(a, InputError):
        assert str(a) == str(b)
        return
    for name in ("wall_points", "origin", "free", "clearance"):  # dtype and shape included
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y), name
    for x, y in ((a.lines, b.lines), (a.circles, b.circles)):
        for u, v in zip(x.__dict__.values(), y.__dict__.values()):
            assert np.array_equal(u, v)


@pytest.mark.parametrize("memory", [0, 3])
def test_observation_grids_follow_the_thresholds_on_random_grids(memory):
    """Random grids whose values sit on the thresholds (float32 0.4 vs 0.4, hits at exactly
    the wall ratio, seen stamps at the memory's edge): the wall points are the cells that
    pass bev.wall_cells (and were seen recently), the free mask the recent cells below
    free_threshold, the clearance 0 off free cells and the distance to the nearest cell
    not free elsewhere; the crop holds every known cell."""
    from scipy import ndimage

    from zfloc_stream.frontend.bev_snapshot import BevSnapshot, wall_cells

    gen = np.random.default_rng(memory)
    settings = load_settings(overrides=["bev.occupied_threshold=0.4", "bev.free_threshold=-0.3", "bev.wall_min_ratio=0.3",
                                        f"bev.memory_frames={memory}"])
    b = settings.bev
    raised = 0
    for trial in range(12):
        n = 80
        logodds = np.zeros((n, n), np.float32)
        wall, hits = np.zeros((n, n), np.uint16), np.zeros((n, n), np.uint16)
        r0, c0 = gen.integers(0, n // 2, 2)
        r1, c1 = np.array([r0, c0]) + gen.integers(1, n // 2, 2)
        if trial == 0:
            r0, c0, r1, c1 = 0, 0, n, n
        shape = (r1 - r0, c1 - c0)
        values = np.array([0.0, 0.4, -0.3, 0.5, -1.0, 2.0, np.nextafter(np.float32(0.4), 1)], np.float32)
        logodds[r0:r1, c0:c1] = gen.choice(values, shape)
        hits[r0:r1, c0:c1] = gen.integers(0, 11, shape)
        wall[r0:r1, c0:c1] = np.where(gen.random(shape) < 0.5, (hits[r0:r1, c0:c1] * 3) // 10, gen.integers(0, 4, shape))
        stamp = 20
        seen = gen.integers(stamp - 5, stamp + 1, (n, n)).astype(np.int32)
        if trial == 1:
            wall[:] = 0  # no wall cell
        snap = BevSnapshot(logodds, wall, hits, seen, -7, 11, np.zeros((0, 3)), settings, stamp)
        recent = seen > stamp - memory if memory else np.ones((n, n), bool)
        walls = wall_cells(wall, hits, logodds, b) & recent
        try:
            obs = snap.observation(make_rng(0, "obs"))
        except InputError:
            assert not walls.any()
            raised += 1
            continue
        assert trial != 1
        # the crop's origin in cells, and the grids on it
        oc = np.rint(obs.origin / b.resolution).astype(int) - [-7, 11]
        h, w = obs.free.shape
        crop = (slice(oc[1], oc[1] + h), slice(oc[0], oc[0] + w))
        known = ((logodds != 0) | (wall > 0)) & recent
        assert known[crop].sum() == known.sum()  # every known cell inside the crop
        free = (logodds[crop] < b.free_threshold) & recent[crop]
        assert np.array_equal(obs.free, free)
        rr, cc = np.nonzero(walls[crop])
        assert np.array_equal(obs.wall_points, obs.origin + (np.stack([cc, rr], axis=1) + 0.5) * b.resolution)
        occupied = ((logodds[crop] > b.occupied_threshold) | walls[crop]) & recent[crop]
        expected = np.where(free, ndimage.distance_transform_edt(~occupied) * b.resolution, 0.0)
        np.testing.assert_allclose(obs.clearance, expected, rtol=0, atol=1e-9)
    assert raised <= 3  # most grids give an observation


def test_observation_of_fused_scans_is_repeatable():
    settings = load_settings()
    bev = RollingBEV(settings)
    rng = make_rng(5, "noise")
    for i, (x, y) in enumerate([(2, 2), (3, 3), (5, 3), (7, 2.5)]):
        bev.add(laser(x, y, 0.3 * i, noise=0.01, rng=rng, t=i))
    a = bev.snapshot().observation(make_rng(0, "obs"))
    b = bev.snapshot(copy=False).observation(make_rng(0, "obs"))
    assert len(a.wall_points) > 300 and len(a.lines) > 0
    _assert_same_observation(a, b)


def test_forget_before_and_a_snapshot_since_keep_what_later_frames_touched():
    """A kidnap test's round sees only what frames from a stamp on saw (snapshot since), and
    an adopted kidnap empties the rest (forget_before): room A, seen by frames 1-5 only, is
    gone from both; room B, seen by frames 6-10, is as it was, and the plane frame stays."""
    room_a, room_b = (0.0, 0.0, 6.0, 6.0), (8.0, 0.0, 14.0, 6.0)
    bev = RollingBEV(load_settings(overrides=["bev.memory_frames=0"]))
    for i in range(5):
        bev.add(laser(3.0, 3.0, 0.2 * i, box=room_a, t=i))
    for i in range(5, 10):
        bev.add(laser(11.0, 3.0, 0.2 * i, box=room_b, t=i))
    assert bev.stamp == 10
    full = bev.observation(make_rng(0, "obs"))
    since = bev.snapshot(copy=True, since=6).observation(make_rng(0, "obs"))
    assert (full.wall_points[:, 0] < 7).any() and not (since.wall_points[:, 0] < 7).any()
    assert (since.wall_points[:, 0] > 7.9).sum() == (full.wall_points[:, 0] > 7.9).sum()
    assert not since.free_at(np.array([[3.0, 3.0]])).any() and since.free_at(np.array([[11.0, 3.0]])).all()
    pose = bev.plane_pose(laser(11.0, 3.0, 0.0, box=room_b, t=10))
    bev.forget_before(6)
    forgotten = bev.observation(make_rng(0, "obs"))
    for name in ("wall_points", "free", "clearance"):
        assert np.array_equal(getattr(forgotten, name), getattr(since, name))
    assert bev.plane_pose(laser(11.0, 3.0, 0.0, box=room_b, t=10)) == pose


def test_a_frame_whose_walls_cut_through_what_older_frames_saw_open_contradicts_them():
    """last_contradiction: the share of a frame's wall hits on cells older frames saw open,
    no occupied cell within localizer.monitor_distance. The same room seen again: 0; a
    smaller room at the same odometry pose (carried off): its walls stand in the open space
    of the first, all of them contradict it (the kidnap test's evidence)."""
    room, smaller = (0.0, 0.0, 8.0, 6.0), (2.0, 1.5, 6.0, 4.5)
    bev = RollingBEV(Settings())
    for i in range(5):
        bev.add(laser(4.0, 3.0, 0.2 * i, box=room, t=i))
    assert bev.last_contradiction == 0.0  # (the first frame: nothing older to contradict)
    bev.add(laser(4.0, 3.0, 0.1, box=room, t=5))
    assert bev.last_contradiction == 0.0
    bev.add(laser(4.0, 3.0, 0.1, box=smaller, t=6))
    assert bev.last_contradiction > 0.9


def test_grid_cell_passes_count_points_per_cell_and_look_around_open_cells():
    """ScrollingGrid.unique_flat: the cells (ascending flat index) holding at least
    min_count of the points, points outside the grid ignored, whatever the call before.
    open_without_wall_near: of the points on seen cells, those on open cells with no
    occupied cell within reach (the window clipped at the grid's edge)."""
    from zfloc_stream.frontend.scrolling_grid import ScrollingGrid

    g = ScrollingGrid(10, 1.0)
    g.centre_on(np.array([5.5, 5.5]), 0)  # cell (0, 0) is x, y in [0, 1)
    pts = np.array([[2.5, 1.5], [2.2, 1.9], [2.9, 1.1], [7.5, 3.5], [7.1, 3.2], [0.5, 0.5], [-0.5, 0.5], [10.5, 9.5]])
    assert g.unique_flat(pts).tolist() == [0, 12, 37]
    assert g.unique_flat(pts, min_count=2).tolist() == [12, 37]
    assert g.unique_flat(pts, min_count=3).tolist() == [12]
    assert g.unique_flat(pts[:0]).tolist() == []
    assert g.unique_flat(pts, min_count=2).tolist() == [12, 37]  # the scratch counts were reset

    g.seen[:, :] = 1
    g.logodds[:, :] = -1.0  # open everywhere
    g.logodds[9, 9] = 1.0  # one occupied corner cell
    hits = np.array([[0.5, 0.5], [8.5, 8.5], [9.5, 7.5], [5.5, 5.5], [20.0, 20.0]])
    assert g.open_without_wall_near(hits, -0.3, 0.0, reach=2, min_known=1) == (4, 2)  # (8, 8) and (7, 9) see the corner
    assert g.open_without_wall_near(hits, -0.3, 0.0, reach=2, min_known=5) == (0, 0)  # too few on seen cells
    g.seen[0, 0] = 0
    assert g.open_without_wall_near(hits, -0.3, 0.0, reach=1, min_known=1) == (3, 2)
