"""Built-in scenes: registry, determinism, plausible sizes, connectivity, doors, symmetry."""


import numpy as np
import pytest
from scipy import ndimage

from zfloc_stream.errors import InputError
from zfloc_stream.sim import SCENES, build_scene

NAMES = sorted(SCENES)


@pytest.fixture(scope="module")
def scenes():
    return {(n, s): build_scene(n, s) for n in NAMES for s in (0, 1)}


def test_unknown_scene_names_the_known_ones():
    with pytest.raises(InputError) as err:
        build_scene("castle")
    for name in NAMES:
        assert name in str(err.value)


def test_registry_has_the_promised_scenes():
    assert set(NAMES) >= {"rooms", "apartment", "office", "symmetric", "hall"}


@pytest.mark.parametrize("name", NAMES)
def test_same_seed_same_scene_other_seed_other_scene(name, scenes):
    a, b = scenes[(name, 0)], build_scene(name, 0)
    assert np.array_equal(a.occupied, b.occupied)
    assert np.array_equal(a.walls, b.walls) and np.array_equal(a.furniture, b.furniture)
    assert a.waypoints == b.waypoints
    c = scenes[(name, 1)]
    assert a.occupied.shape != c.occupied.shape or not np.array_equal(a.occupied, c.occupied)


@pytest.mark.parametrize("name", NAMES)
def test_floor_area_near_target(name, scenes):
    for seed in (0, 1):
        s = scenes[(name, seed)]
        assert 0.75 * s.target_area <= s.floor_area <= 1.25 * s.target_area, (seed, s.floor_area)


def test_target_areas():
    targets = {n: build_scene(n).target_area for n in ("rooms", "apartment", "office")}
    assert targets == {"rooms": 40.0, "apartment": 100.0, "office": 2500.0}


@pytest.mark.parametrize("name", NAMES)
def test_walkable_space_is_one_piece_and_reaches_every_room(name, scenes):
    s = scenes[(name, 0)]
    labels, n = ndimage.label(s.free)
    assert n == 1
    interior_labels, n_interior = ndimage.label(s.interior)
    assert n_interior == 1
    for room_name, point in s.waypoints.items():
        assert s.is_free([point])[0], room_name
    assert not (s.free & s.occupied).any()
    assert s.free.sum() < s.interior.sum()  # furniture takes some floor


@pytest.mark.parametrize("name", NAMES)
def test_doors_are_open_in_the_floorplan(name, scenes):
    s = scenes[(name, 0)]
    assert len(s.doors) >= 1
    for door in s.doors:
        cx, cy = door.center
        along = np.linspace(-0.35, 0.35, 8) * door.width
        pts = np.stack([cx + along, np.full_like(along, cy)], 1) if door.axis == "h" \
            else np.stack([np.full_like(along, cx), cy + along], 1)
        row, col, inside = s.cells(pts)
        assert inside.all()
        assert not s.occupied[row, col].any(), door
        # ...and a wall continues on both sides of the opening
        for sign in (-1, 1):
            beyond = door.width / 2 + 0.1
            p = (cx + sign * beyond, cy) if door.axis == "h" else (cx, cy + sign * beyond)
            r, c, _ = s.cells([p])
            assert s.occupied[r, c].all(), (door, sign)


@pytest.mark.parametrize("name", NAMES)
def test_plausible_building_dimensions(name, scenes):
    s = scenes[(name, 0)]
    assert 0.1 <= s.wall_thickness.min() and s.wall_thickness.max() <= 0.25
    assert 2.5 <= s.wall_height <= 3.0
    widths = np.array([d.width for d in s.doors])
    assert ((widths >= 0.8) & (widths <= 4.0)).all()
    assert np.median(widths) <= 1.0
    for r in s.rooms:
        w = min(r.size)
        if r.kind == "corridor" and name != "apartment":
            assert 1.5 <= w <= 2.5, r
        elif r.kind == "room" and r.name != "alcove":
            assert w >= 2.2, r
    if len(s.pillars):
        assert ((s.pillars[:, 2] >= 0.2) & (s.pillars[:, 2] <= 0.5)).all()


def test_office_has_corridors_and_pillars(scenes):
    s = scenes[("office", 0)]
    assert sum(r.kind == "corridor" for r in s.rooms) >= 3
    assert len(s.pillars) >= 4
    assert len(s.rooms) >= 30
    # pillars are in the floorplan
    row, col, _ = s.cells(s.pillars[:, :2])
    assert s.occupied[row, col].all()


def test_hall_has_pillars(scenes):
    assert len(scenes[("hall", 0)].pillars) >= 4


def test_furniture_is_not_in_the_floorplan(scenes):
    s = scenes[("apartment", 0)]
    assert len(s.furniture)
    row, col, _ = s.cells(s.furniture[:, :2])
    assert not s.occupied[row, col].any()
    assert not s.free[row, col].any()


def _flip_ious(occupied):
    rows, cols = np.where(occupied.any(1))[0], np.where(occupied.any(0))[0]
    o = occupied[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    return [(o & f).sum() / (o | f).sum() for f in (o[::-1], o[:, ::-1], o[::-1, ::-1])]


@pytest.mark.parametrize("name", ["rooms", "apartment", "office", "hall"])
def test_ordinary_scenes_are_not_symmetric(name, scenes):
    for seed in (0, 1):
        assert max(_flip_ious(scenes[(name, seed)].occupied)) < 0.8, seed


def test_symmetric_scene_main_part_is_point_symmetric(scenes):
    s = scenes[("symmetric", 0)]
    c = np.array(s.info["symmetry_center"])
    x_lo, x_hi = s.info["symmetric_x_range"]
    rows, cols = np.nonzero(s.occupied)
    x, y = s.grid.centres(rows, cols)
    keep = (x > x_lo + 0.5) & (x < x_hi - 0.5)
    pts = np.stack([x[keep], y[keep]], 1)
    r, cc, inside = s.cells(2 * c - pts)
    assert inside.all()
    assert s.occupied[r, cc].mean() > 0.999
    # furniture of the symmetric part too (it is seen by the camera)
    f = s.furniture[(s.furniture[:, 0] > x_lo) & (s.furniture[:, 0] < x_hi)]
    mirrored = 2 * c - f[:, :2]
    d = np.linalg.norm(mirrored[:, None] - f[None, :, :2], axis=2).min(axis=1)
    assert d.max() < 1e-6
    # ...but the whole building is not: the annex only exists at one end
    rows, cols = np.nonzero(s.occupied)
    x, y = s.grid.centres(rows, cols)
    pts = np.stack([x, y], 1)
    r, cc, inside = s.cells(2 * c - pts)
    assert (inside & s.occupied[r, cc]).mean() < 0.97


def test_symmetric_waypoints(scenes):
    s = scenes[("symmetric", 0)]
    wp = s.waypoints
    a, b, d = (np.array(wp[k]) for k in ("symmetric_start", "symmetric_end", "distinguishing"))
    x_lo, x_hi = s.info["symmetric_x_range"]
    margin = s.info["sym_margin"]
    for p in (a, b):
        assert x_lo + margin - 1e-6 <= p[0] <= x_hi - margin + 1e-6
        assert s.is_free([p])[0]
    assert d[0] > x_hi and s.is_free([d])[0]
    assert margin > 10.0  # farther than a 10 m sensor from both ends


def test_floorplan_and_ros_export(tmp_path, scenes):
    s = scenes[("rooms", 0)]
    fp = s.floorplan
    assert np.array_equal(np.asarray(fp.occupied), s.occupied)
    s.write_ros(tmp_path)
    assert list(tmp_path.glob("*.yaml")) and list(tmp_path.glob("*.png"))


@pytest.mark.parametrize("name", NAMES)
def test_every_room_is_reachable_by_the_walk_planner(name, scenes):
    from zfloc_stream.sim import plan_path

    s = scenes[(name, 1)]
    start = s.waypoints[s.rooms[0].name]
    for room in s.rooms[1:]:
        path = plan_path(s, start, s.waypoints[room.name])
        assert s.is_free(path).all(), room.name


@pytest.mark.parametrize("name", ["rooms", "apartment", "symmetric", "hall"])
def test_more_seeds_stay_plausible(name):
    for seed in range(2, 8):
        s = build_scene(name, seed)
        assert 0.75 * s.target_area <= s.floor_area <= 1.25 * s.target_area, seed
        assert ndimage.label(s.free)[1] == 1, seed


def test_offices_repeat_exactly_along_the_corridor(scenes):
    """'offices' (issue 43): the floorplan and the furniture repeat with the office width,
    so a place and the place whole offices along look the same; the ends do not."""
    for seed in (0, 1):
        s = scenes[("offices", seed)]
        period, n = s.info["period"], s.info["n_offices"]
        x0, y0, x1, y1 = s.info["corridor"]
        step = int(round(period / s.resolution))
        assert abs(step * s.resolution - period) < 1e-9 and x1 - x0 == pytest.approx(n * period)
        _, c0, _ = s.cells([[x0 + period, y0]])
        block = s.occupied[:, c0[0]:c0[0] + (n - 3) * step]
        moved = s.occupied[:, c0[0] + step:c0[0] + (n - 2) * step]
        assert np.array_equal(block, moved)
        for side in (s.furniture[:, 1] < y0, s.furniture[:, 1] > y1):
            pieces = s.furniture[side & (s.furniture[:, 0] > x0) & (s.furniture[:, 0] < x1)]
            office = np.floor((pieces[:, 0] - x0) / period).astype(int)
            assert (office == 0).any()
            for k in range(1, n):
                assert np.allclose(pieces[office == k] - [k * period, 0, 0, 0, 0, 0], pieces[office == 0])
        # the two ends differ from the offices and from each other
        stairs, kitchen = s.room("stairs"), s.room("kitchen")
        assert stairs.size != kitchen.size and min(kitchen.size) > period
