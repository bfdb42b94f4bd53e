"""Boundary tests of the datasets.* settings no other test names: each at the smallest
input on either side of where a reader's output changes.

datasets.ros2.max_odometry_gap, datasets.vector_floorplan.solid_max_width,
datasets.odometry.{heading_noise_per_m, translation_floor, heading_floor_deg, origin_extent},
datasets.gibson.focal_fraction, datasets.carmen.{flaser_fov_deg, flaser_start_deg,
min_range, heldout_margin}, datasets.mapping.{logodds_free, free_range, free_margin},
datasets.sim.scene_seed.
"""

import json
import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest

from laser_helpers import laser_run, write_carmen
from ros2_bag import mount, write_sensor_bag
from benchmarks.inputs.session_frames import laser_frames
from benchmarks.inputs.hostile_sessions import frame_messages, with_timestamps, write_messages

from zfloc_stream.errors import InputError
from zfloc_stream.frames import FLOOR, WALL
from zfloc_stream.io.datasets import open_dataset
from zfloc_stream.io.datasets.base import synthetic_odometry
from zfloc_stream.io.datasets.carmen import carmen_sequence, read_carmen
from zfloc_stream.io.datasets.gibson import synthesize_image
from zfloc_stream.io.datasets.sim import scene_sequence
from zfloc_stream.io.session import read_session
from zfloc_stream.plans.map_from_log import map_from_log, rasterize_scans
from zfloc_stream.plans.vector import load_vector_floorplan
from zfloc_stream.sim import build_scene
from zfloc_stream.settings.loading import load_settings

EPS = 1e-6


def settings(*overrides: str):
    return load_settings(overrides=list(overrides))


# --- datasets.ros2.max_odometry_gap ------------------------------------------------------
def test_max_odometry_gap_skips_frames_in_a_longer_gap_of_a_session(tmp_path):
    """datasets.ros2.max_odometry_gap: frames 2-4 of a session from another tool have no
    odometry of their own; frames 1 and 5, 0.4 s apart, bound them. A gap of 0.4 s is
    interpolated across, 1 ns less drops those frames (the caller's settings reach a
    foreign file's read)."""
    frames = with_timestamps(laser_frames(7, seed=3), t0=0.5, dt=0.1)
    msgs = [m for m in frame_messages(frames) if not (m[0] == "/odometry" and 2 <= frames_index(frames, m[1]) <= 4)]
    path = tmp_path / "gappy.mcap"
    write_messages(path, msgs)
    read = lambda gap: [f.timestamp for f in read_session(path, settings=settings(f"datasets.ros2.max_odometry_gap={gap!r}")).frames()]  # noqa: E731
    assert len(read(0.4)) == 7
    assert read(0.4 - 1e-9) == [frames[k].timestamp for k in (0, 1, 5, 6)]


def frames_index(frames, log_ns: int) -> int:
    """The frame whose message this log time (stamp + 5 ms, session_hostile) belongs to."""
    stamp = log_ns - 5_000_000
    return next(k for k, f in enumerate(frames) if int(round(f.timestamp * 1e9)) == stamp)


def test_max_odometry_gap_skips_frames_between_sparse_bag_odometry(tmp_path):
    """datasets.ros2.max_odometry_gap in a ROS 2 bag: odometry at 2 Hz (0.5 s apart) carries
    every scan at a limit just over 0.5 s; just under it, no scan has an odometry pose."""
    _, seq = laser_run("rooms", 8)
    bag = tmp_path / "sparse.mcap"
    write_sensor_bag(bag, seq.frames, mount(0.1, 0.0, 0.3), kind="scan", sensor_hz=10, odom_hz=2)
    (bagged,) = open_dataset(f"ros2:{bag}", settings("datasets.ros2.max_odometry_gap=0.501"))
    assert bagged.n_frames == 8
    with pytest.raises(InputError, match="no frame has an odometry pose"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        open_dataset(f"ros2:{bag}", settings("datasets.ros2.max_odometry_gap=0.499"))[0].frames()


# --- datasets.vector_floorplan.solid_max_width --------------------------------------------
def test_solid_max_width_fills_narrow_shapes_and_outlines_wider_ones(tmp_path):
    """datasets.vector_floorplan.solid_max_width: a closed 1 m x 3 m shape is 2 area /
    perimeter = 6 / 8 = 0.75 m wide: filled (a wall) when the limit is 0.75, outlined (a
    room) when it is a hair less, so its middle is free."""
    room = [[0, 0], [8, 0], [8, 6], [0, 6], [0, 0]]
    slab = [[3, 2], [6, 2], [6, 3], [3, 3], [3, 2]]
    path = tmp_path / "plan.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [ring]}} for ring in (room, slab)]}))
    middle = np.array([[4.5, 2.5]])

    def filled(limit: float) -> bool:
        plan = load_vector_floorplan(path, settings(f"datasets.vector_floorplan.solid_max_width={limit!r}"))
        r, c = plan.world_to_cell(middle)
        return bool(plan.occupied[r[0], c[0]])

    assert filled(0.75)
    assert not filled(0.75 - EPS)


# --- datasets.odometry ---------------------------------------------------------------------
def standing_still(n: int = 4001) -> np.ndarray:
    return np.tile([1.0, 2.0, 0.3], (n, 1))


def straight_walk(n: int = 4001, step: float = 0.5) -> np.ndarray:
    return np.column_stack([np.arange(n) * step, np.zeros(n), np.zeros(n)])


def odometry(truth, *overrides: str, noise: float | None = None) -> np.ndarray:
    cfg = settings(*overrides).datasets.odometry
    return synthetic_odometry(truth, cfg, np.random.default_rng(7), noise=noise)


def body_steps(odom: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per step: the translation in the previous pose's frame (n-1, 2) and the turn (n-1,)."""
    d = np.diff(odom[:, :2], axis=0)
    c, s = np.cos(odom[:-1, 2]), np.sin(odom[:-1, 2])
    turn = np.angle(np.exp(1j * np.diff(odom[:, 2])))
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]), turn


def test_translation_floor_is_the_drift_of_a_sensor_standing_still():
    """datasets.odometry.translation_floor: standing still, each step drifts with this std
    per axis (when noise > 0); at 0 the odometry stands still too."""
    steps, _ = body_steps(odometry(standing_still(), "datasets.odometry.translation_floor=0.02", "datasets.odometry.heading_floor_deg=0"))
    assert steps.std(axis=0) == pytest.approx([0.02, 0.02], rel=0.05)
    steps, turns = body_steps(odometry(standing_still(), "datasets.odometry.translation_floor=0", "datasets.odometry.heading_floor_deg=0"))
    assert np.abs(steps).max() < 1e-9 and np.abs(turns).max() < 1e-12
    # noise 0: exact relative motion, the floors off
    steps, _ = body_steps(odometry(standing_still(), "datasets.odometry.translation_floor=0.02", noise=0.0))
    assert np.abs(steps).max() < 1e-9


def test_heading_floor_deg_is_the_turn_drift_of_a_sensor_standing_still():
    """datasets.odometry.heading_floor_deg: standing still, each step turns with this std
    (degrees, when noise > 0); at 0 it does not turn."""
    _, turns = body_steps(odometry(standing_still(), "datasets.odometry.heading_floor_deg=0.5"))
    assert np.degrees(turns.std()) == pytest.approx(0.5, rel=0.05)
    _, turns = body_steps(odometry(standing_still(), "datasets.odometry.heading_floor_deg=0"))
    assert np.abs(turns).max() < 1e-12


def test_heading_noise_per_m_turns_a_straight_walk():
    """datasets.odometry.heading_noise_per_m: a straight walk of 0.5 m steps turns by
    noise x heading_noise_per_m x 0.5 m std per step (floors off); 0 keeps it straight."""
    floors_off = ("datasets.odometry.heading_floor_deg=0", "datasets.odometry.translation_floor=0")
    _, turns = body_steps(odometry(straight_walk(), "datasets.odometry.heading_noise_per_m=2", *floors_off, noise=0.1))
    assert turns.std() == pytest.approx(0.1 * 2 * 0.5, rel=0.05)
    _, turns = body_steps(odometry(straight_walk(), "datasets.odometry.heading_noise_per_m=0", *floors_off, noise=0.1))
    assert np.abs(turns).max() < 1e-12


def test_origin_extent_bounds_the_odometry_origin():
    """datasets.odometry.origin_extent: the chain starts at a position drawn in
    [-extent, extent]^2 (the same draw scaled by the extent); 0 starts it at the origin."""
    truth = straight_walk(3)
    starts = {e: odometry(truth, f"datasets.odometry.origin_extent={e!r}")[0, :2] for e in (0.0, 1.0, 50.0)}
    assert np.array_equal(starts[0.0], [0.0, 0.0])
    assert np.abs(starts[1.0]).max() <= 1.0 and np.abs(starts[1.0]).max() > 0
    np.testing.assert_allclose(starts[50.0], 50.0 * starts[1.0], rtol=1e-12)
    many = np.array([synthetic_odometry(truth, settings("datasets.odometry.origin_extent=3").datasets.odometry,
                                        np.random.default_rng(seed))[0, :2] for seed in range(400)])
    assert np.abs(many).max() <= 3.0 and np.abs(many).max() > 2.9


# --- datasets.gibson.focal_fraction ------------------------------------------------------
def test_focal_fraction_decides_where_the_floor_meets_a_wall():
    """datasets.gibson.focal_fraction: a wall 2 m away and the camera 1 m above the floor:
    the bottom row (14.5 rows under the centre of 30) sees the floor before the wall when
    14.5 / f > 1 / 2, i.e. f < 29 px = 0.725 x 40 columns. Just under 0.725 it is floor,
    just over it wall."""
    z = np.full(40, 2.0)
    for fraction, label in ((0.725 - EPS, FLOOR), (0.725 + EPS, WALL)):
        cfg = settings(f"datasets.gibson.focal_fraction={fraction!r}").datasets.gibson
        assert (cfg.image_rows, cfg.camera_height) == (30, 1.0)
        depth, labels = synthesize_image(z, cfg)
        assert (labels[-1] == label).all(), fraction
        assert (labels[-2] == WALL).all()


# --- datasets.carmen ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def carmen_log(tmp_path_factory):
    _, seq = laser_run("rooms", 24)
    path = tmp_path_factory.mktemp("carmen") / "rooms.log"
    write_carmen(path, seq, stamp_digits=12)
    return path


def test_flaser_fov_and_start_place_the_beams(carmen_log):
    """datasets.carmen.flaser_fov_deg / flaser_start_deg: FLASER's n beams start at
    flaser_start_deg and are fov / n apart. The 180 beams of the log over 90 deg from -45:
    half a degree apart, the first at -45; the default spreads them 1 deg from -90."""
    log = read_carmen(carmen_log, settings("datasets.carmen.flaser_fov_deg=90", "datasets.carmen.flaser_start_deg=-45"))
    assert np.allclose(np.degrees(log.angle_min), -45.0) and np.allclose(np.degrees(log.angle_increment), 0.5)
    log = read_carmen(carmen_log, settings())
    assert np.allclose(np.degrees(log.angle_min), -90.0) and np.allclose(np.degrees(log.angle_increment), 1.0)


def test_min_range_is_the_shortest_return(carmen_log):
    """datasets.carmen.min_range: a reading at min_range is a return, a hair shorter a
    no-return, in the frames and in the map made from the log."""
    log = read_carmen(carmen_log, settings())
    shortest = min(float(r[np.isfinite(r) & (r < 80)].min()) for r in log.ranges)
    for limit, kept in ((shortest, True), (shortest + EPS, False)):
        s = settings(f"datasets.carmen.min_range={limit!r}")
        seq = carmen_sequence(carmen_log, s)
        returns = [bool(f.valid[f.ranges == shortest].any()) for f in seq.frames() if (f.ranges == shortest).any()]
        assert returns and all(r is kept for r in returns), limit
    # the map: a scan whose only reading is 0.5 m hits (0.5 m) or not (0.5 m + a hair)
    one = SimpleNamespace(poses=np.array([[0.0, 0.0, 0.0]]), ranges=[np.array([0.5, 3.0])], angle_min=np.array([0.0]),
                          angle_increment=np.array([math.pi / 2]), max_range=np.array([80.0]))
    for limit, hit in ((0.5, True), (0.5 + EPS, False)):
        cfg = settings(f"datasets.carmen.min_range={limit!r}")
        logodds, lo = rasterize_scans(one.poses, one.ranges, one.angle_min, one.angle_increment, one.max_range,
                                      cfg.datasets.mapping, min_range=cfg.datasets.carmen.min_range)
        res = cfg.datasets.mapping.resolution
        c, r = np.floor((np.array([0.5, 0.0]) - lo) / res).astype(int)
        assert bool(logodds[r, c] > 0) is hit, limit


def test_heldout_margin_widens_a_windows_held_out_map(carmen_log):
    """datasets.carmen.heldout_margin: a window's map leaves out [start - margin, stop +
    margin): scans 7..14 for window 10..12 at margin 3 (not 8..13, not 6..15)."""
    s = settings("datasets.carmen.heldout_margin=3")
    seq = carmen_sequence(carmen_log, s)
    held = seq.floorplan_for(10, 12)
    log = read_carmen(carmen_log, s)

    def same(a, b):
        return a.occupied.shape == b.occupied.shape and np.array_equal(a.occupied, b.occupied) and np.allclose(a.origin, b.origin)

    assert same(held, map_from_log(log, [(7, 15)], s))
    assert not same(held, map_from_log(log, [(8, 14)], s))
    assert not same(held, map_from_log(log, [(6, 16)], s))


# --- datasets.mapping ----------------------------------------------------------------------
RES = 0.05


def one_beam_map(ranges, *overrides: str, min_range: float = 0.0):
    """Log-odds of scans from the origin along +x, one beam each; cell value at x."""
    cfg = settings(f"datasets.mapping.resolution={RES}", *overrides).datasets.mapping
    n = len(ranges)
    logodds, lo = rasterize_scans(np.zeros((n, 3)), [np.array([r]) for r in ranges], np.zeros(n), np.full(n, 0.01),
                                  np.full(n, 80.0), cfg, min_range=min_range)

    def at(x: float) -> float:
        c, r = np.floor((np.array([x, 0.0]) - lo) / RES).astype(int)
        return float(logodds[r, c])

    return at


def test_logodds_free_against_one_hit_decides_a_wall_seen_through_once():
    """datasets.mapping.logodds_free: a cell hit once (+0.85) and crossed once by a longer
    beam stays wall (log-odds > 0) when logodds_free is a hair above -0.85, turns free at a
    hair below."""
    for free, wall in ((-0.85 + EPS, True), (-0.85 - EPS, False)):
        at = one_beam_map([2.0, 4.0], f"datasets.mapping.logodds_free={free!r}", "datasets.mapping.free_margin=0")
        assert at(2.0) == pytest.approx(0.85 + free, abs=1e-6)
        assert (at(2.0) > 0) is wall, free


def test_free_range_clears_no_further():
    """datasets.mapping.free_range: a beam returning at 10 m clears free space only to
    free_range: the cell at 2.93 m is free with free_range 3, the one at 3.07 m is not; with
    free_range 3.15 it is."""
    at = one_beam_map([10.0], "datasets.mapping.free_range=3")
    assert at(2.93) < 0 and at(3.07) == 0
    assert one_beam_map([10.0], "datasets.mapping.free_range=3.15")(3.07) < 0


def test_free_margin_stops_free_space_short_of_a_return():
    """datasets.mapping.free_margin: a beam returning at 4 m clears free space to 4 m less
    free_margin: with 0.5 the cell at 3.43 m is free and the one at 3.57 m untouched; with
    0.4 it is free too."""
    at = one_beam_map([4.0], "datasets.mapping.free_margin=0.5")
    assert at(3.43) < 0 and at(3.57) == 0 and at(4.01) > 0
    assert one_beam_map([4.0], "datasets.mapping.free_margin=0.4")(3.57) < 0


# --- datasets.sim.scene_seed ---------------------------------------------------------------
def test_scene_seed_chooses_the_building_not_the_walk_seed():
    """datasets.sim.scene_seed: `sim:rooms` is the rooms scene built with this seed (0 and 1
    differ); settings.seed leaves the building as it is."""
    plans = {}
    for scene_seed, seed in ((0, 0), (1, 0), (0, 5)):
        seq = scene_sequence("rooms", settings(f"datasets.sim.scene_seed={scene_seed}", f"seed={seed}", "datasets.sim.n_frames=2"))
        plans[scene_seed, seed] = seq.floorplan.occupied
    assert np.array_equal(plans[0, 0], build_scene("rooms", seed=0).floorplan.occupied)
    assert np.array_equal(plans[1, 0], build_scene("rooms", seed=1).floorplan.occupied)
    assert not (plans[0, 0].shape == plans[1, 0].shape and np.array_equal(plans[0, 0], plans[1, 0]))
    assert np.array_equal(plans[0, 5], plans[0, 0])
