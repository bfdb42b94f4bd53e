import numpy as np
import pytest

from zfloc_stream.errors import InputError
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.frames import LaserFrame
from zfloc_stream.sim.raycast2d import RangeSensor2D, beam_angles, cast_rays, to_laser_frame

RES = 0.05


@pytest.fixture(scope="module")
def box():
    """A 10 x 6 m box (1-cell walls) with origin (-2, -1): inner faces at x = -1.95, 7.95,
    y = -0.95, 4.95."""
    occ = np.zeros((120, 200), dtype=bool)
    occ[0], occ[-1], occ[:, 0], occ[:, -1] = True, True, True, True
    return Floorplan.from_occupancy(occ, RES, (-2.0, -1.0))


def test_ranges_to_known_walls(box):
    x, y = 1.013, 2.27
    scan = cast_rays(box, (x, y, 0.0), 2 * np.pi, 20.0, 4)
    # beams at -pi, -pi/2, 0, pi/2 relative to heading 0
    expected = [x + 1.95, y + 0.95, 7.95 - x, 4.95 - y]
    assert scan.hit_mask.all()
    assert np.allclose(scan.ranges, expected, atol=1e-9)  # the wall face is exact
    assert np.allclose(scan.true_ranges, scan.ranges)


def test_ranges_at_random_angles_within_one_cell(box):
    rng = np.random.default_rng(0)
    for _ in range(20):
        pose = (rng.uniform(0, 6), rng.uniform(0, 4), rng.uniform(-np.pi, np.pi))
        scan = cast_rays(box, pose, 2 * np.pi, 12.0, 181)  # the box diagonal is 11.7 m
        world = pose[2] + scan.angles
        d = np.stack([np.cos(world), np.sin(world)], axis=1)
        # analytic distance to the inner faces of the box
        with np.errstate(divide="ignore"):
            tx = np.where(d[:, 0] > 0, (7.95 - pose[0]) / d[:, 0], (-1.95 - pose[0]) / d[:, 0])
            ty = np.where(d[:, 1] > 0, (4.95 - pose[1]) / d[:, 1], (-0.95 - pose[1]) / d[:, 1])
        truth = np.minimum(np.abs(tx), np.abs(ty))
        assert scan.hit_mask.all()
        assert np.abs(scan.ranges - truth).max() < 1e-6
        assert np.abs(box.distance(scan.hit_points)).max() <= RES  # hits sit on wall cells


def test_heading_rotates_the_beams(box):
    a = cast_rays(box, (1.0, 1.0, 0.0), np.pi, 20.0, 3)  # -90, 0, +90 deg
    b = cast_rays(box, (1.0, 1.0, np.pi / 2), np.pi, 20.0, 3)  # 0, 90, 180 deg in the world
    assert np.allclose(a.angles, [-np.pi / 2, 0, np.pi / 2])
    assert np.isclose(b.ranges[0], a.ranges[1]) and np.isclose(b.ranges[1], a.ranges[2])
    assert np.isclose(b.ranges[2], 1.0 + 1.95)


def test_no_hit_beyond_max_range_is_inf(box):
    scan = cast_rays(box, (1.0, 2.0, 0.0), 2 * np.pi, 3.0, 8)
    # from (1, 2) the walls are 2.95 m behind and on each side, 6.95 m ahead, > 4 m diagonally
    assert scan.hit_mask.tolist() == [True, False, True, False, False, False, True, False]
    assert np.isinf(scan.ranges[~scan.hit_mask]).all()
    assert np.allclose(scan.ranges[scan.hit_mask], 2.95)
    assert np.isnan(scan.hits[~scan.hit_mask]).all()
    # leaving the grid without a wall is a no-hit, not an error
    occ = np.zeros((50, 50), bool)
    occ[10, 30] = True  # at (1.525, 0.525): between the 16 beams from (2, 2)
    open_plan = Floorplan.from_occupancy(occ, RES, (0, 0))
    assert not cast_rays(open_plan, (2.0, 2.0, 0.0), 2 * np.pi, 10.0, 16).hit_mask.any()


def test_range_noise_statistics(box):
    rng = np.random.default_rng(1)
    sigma = 0.03
    scan = cast_rays(box, (3.0, 2.0, 0.0), 2 * np.pi, 6.0, 4000, rng=rng, range_noise=sigma)
    assert scan.hit_mask.all()
    err = scan.ranges - scan.true_ranges
    assert abs(err.mean()) < 4 * sigma / np.sqrt(len(err))
    assert abs(err.std() / sigma - 1) < 0.05
    # hit points follow the noisy ranges
    assert np.allclose(np.hypot(*(scan.hits - (3.0, 2.0)).T), scan.ranges)


def test_outlier_statistics(box):
    rng = np.random.default_rng(2)
    scan = cast_rays(box, (3.0, 2.0, 0.0), 2 * np.pi, 6.0, 5000, rng=rng, outlier_ratio=0.2)
    assert scan.hit_mask.all()
    frac = scan.outlier_mask.mean()
    assert abs(frac - 0.2) < 4 * np.sqrt(0.2 * 0.8 / 5000)
    ratio = scan.ranges[scan.outlier_mask] / scan.true_ranges[scan.outlier_mask]
    assert (ratio > 0).all() and (ratio <= 1).all()
    assert abs(ratio.mean() - 0.5) < 0.03  # uniform in (0, true]
    assert np.array_equal(scan.ranges[~scan.outlier_mask], scan.true_ranges[~scan.outlier_mask])


def test_noise_is_seeded(box):
    kw = dict(fov=np.pi, max_range=10.0, n_beams=90, range_noise=0.02, outlier_ratio=0.1)
    a = cast_rays(box, (3, 2, 0.4), rng=np.random.default_rng(5), **kw)
    b = cast_rays(box, (3, 2, 0.4), rng=np.random.default_rng(5), **kw)
    assert np.array_equal(a.ranges, b.ranges)


def test_bad_arguments(box):
    with pytest.raises(InputError, match="rng"):
        cast_rays(box, (1, 1, 0), np.pi, 5.0, 10, range_noise=0.1)
    with pytest.raises(InputError, match="pose"):
        cast_rays(box, (np.nan, 1, 0), np.pi, 5.0, 10)
    with pytest.raises(InputError, match="fov"):
        cast_rays(box, (1, 1, 0), 0.0, 5.0, 10)
    with pytest.raises(InputError, match="max_range"):
        cast_rays(box, (1, 1, 0), np.pi, -1.0, 10)
    with pytest.raises(InputError, match="n_beams"):
        cast_rays(box, (1, 1, 0), np.pi, 5.0, 0)


def test_beam_angles():
    assert np.allclose(beam_angles(2 * np.pi, 4), [-np.pi, -np.pi / 2, 0, np.pi / 2])
    assert np.allclose(beam_angles(np.pi, 181)[[0, 90, 180]], [-np.pi / 2, 0, np.pi / 2])


def test_laser_frame_from_scan(box):
    sensor = RangeSensor2D(fov=np.pi, max_range=8.0, n_beams=181)
    true_pose = (1.0, 2.0, 0.3)
    odom_pose = (10.0, -3.0, 1.2)  # drifted odometry: the frame carries it, ground truth the truth
    frame = sensor.frame(box, true_pose, odom_pose, timestamp=4.5)
    assert isinstance(frame, LaserFrame)
    assert np.allclose(frame.ground_truth, true_pose)
    assert np.allclose(frame.T_odom_sensor[:2, 3], odom_pose[:2])
    assert np.isclose(np.arctan2(frame.T_odom_sensor[1, 0], frame.T_odom_sensor[0, 0]), 1.2)
    assert np.allclose(frame.angles, sensor.scan(box, true_pose).angles)
    # re-projecting the valid readings from the true pose lands on walls
    ok = frame.valid
    a = true_pose[2] + frame.angles[ok]
    pts = np.asarray(true_pose[:2]) + frame.ranges[ok, None] * np.stack([np.cos(a), np.sin(a)], axis=1)
    assert ok.sum() > 100 and np.abs(box.distance(pts)).max() <= RES
    assert to_laser_frame(sensor.scan(box, true_pose), odom_pose, 0.0, 8.0).range_max == 8.0
