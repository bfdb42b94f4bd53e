"""Boundary tests of the front-end and plan settings a user sets for their sensor and their
building (issue 42): for each, the smallest input on either side of the value, showing the
behaviour changes exactly there, and that moving the setting moves the boundary.
(Tuning a user should not touch is a constant instead: settings/retired.py.)"""

import cv2
import numpy as np
import pytest

from zfloc_stream.frames import CEILING, FLOOR, OTHER, WALL, LaserFrame
from zfloc_stream.frontend.bev import RollingBEV
from zfloc_stream.frontend.labeller import label_frame
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.settings.loading import LabellerSettings, load_settings


def _above(v: float) -> float:
    return float(np.nextafter(v, np.inf))


# --- frontend.target_pixels: the automatic camera pixel stride ------------------------------
def test_target_pixels_sets_the_automatic_stride_at_its_square_multiples():
    """stride = floor(sqrt(H W / target_pixels)): 4 x target_pixels pixels is the first
    image read at stride 2, one pixel fewer is read whole."""
    bev = RollingBEV(load_settings(overrides=["frontend.target_pixels=12000"]))
    assert bev.pixel_stride((1, 4 * 12000 - 1)) == 1
    assert bev.pixel_stride((1, 4 * 12000)) == 2
    assert bev.pixel_stride((120, 400)) == 2  # the same count as an image
    assert RollingBEV(load_settings(overrides=["frontend.target_pixels=12001"])).pixel_stride((1, 4 * 12000)) == 1
    # a set pixel_stride wins over the automatic one
    assert RollingBEV(load_settings(overrides=["frontend.pixel_stride=3"])).pixel_stride((1, 4 * 12000)) == 3


# --- bev.recenter_distance: when the rolling grid scrolls -----------------------------------
def _scan_at(x: float, y: float, t: float) -> LaserFrame:
    T = np.eye(4)
    T[:2, 3] = [x, y]
    n = 90
    return LaserFrame(np.full(n, 2.0), -np.pi, 2 * np.pi / n, 0.05, 30.0, T, t)


@pytest.mark.parametrize("recenter, cells, scrolls", [(1.0, 20, False), (1.0, 21, True), (1.05, 21, False), (1.05, 22, True)])
def test_the_grid_scrolls_once_the_sensor_leaves_the_recenter_box(recenter, cells, scrolls):
    """The grid scrolls when the sensor's cell is more than recenter_distance / resolution
    cells from the grid's centre: 20 cells (1.0 m at 0.05 m) stays, 21 scrolls."""
    bev = RollingBEV(load_settings(overrides=[f"bev.recenter_distance={recenter}", "bev.scan_match=none"]))
    bev.add(_scan_at(5.025, 3.025, 0.0))  # a cell's centre
    origin = (bev.grid.ix0, bev.grid.iy0)
    bev.add(_scan_at(5.025 + cells * 0.05, 3.025, 0.1))
    assert ((bev.grid.ix0, bev.grid.iy0) != origin) == scrolls
    if scrolls:
        assert bev.grid.ix0 - origin[0] == cells  # re-centred on the sensor's cell


# --- frontend.labeller: heights that make a surface floor, wall or ceiling -------------------
def _labels(heights, nz, settings=None):
    """Labels of single points at these heights above the floor, with normals of z part nz
    (0: a vertical surface, 1: a horizontal one)."""
    h = np.asarray(heights, dtype=float)[None, :]
    n = np.zeros(h.shape + (3,), dtype=np.float32)
    n[..., 0], n[..., 2] = np.sqrt(1 - nz * nz), nz
    return label_frame(h, n, np.ones(h.shape, bool), settings or LabellerSettings())[0].tolist()


def test_floor_tolerance_bounds_the_floor_on_both_sides():
    tol = LabellerSettings().floor_tolerance
    below = float(np.nextafter(tol, 0.0))
    assert _labels([below, tol, -below, -tol], nz=1.0) == [FLOOR, OTHER, FLOOR, OTHER]
    assert _labels([tol], nz=1.0, settings=LabellerSettings(floor_tolerance=_above(tol))) == [FLOOR]


def test_wall_min_height_is_where_a_vertical_surface_becomes_a_wall():
    lo = LabellerSettings().wall_min_height
    assert _labels([lo, _above(lo)], nz=0.0) == [OTHER, WALL]
    assert _labels([_above(lo)], nz=0.0, settings=LabellerSettings(wall_min_height=_above(lo))) == [OTHER]


def test_ceiling_min_height_is_where_a_level_surface_becomes_ceiling():
    hi = LabellerSettings().ceiling_min_height
    assert _labels([hi, _above(hi)], nz=1.0) == [OTHER, CEILING]
    assert _labels([_above(hi)], nz=1.0, settings=LabellerSettings(ceiling_min_height=_above(hi))) == [OTHER]
    assert _labels([_above(hi)], nz=0.0) == [WALL]  # a vertical surface up there is still a wall


# --- floorplan.image_wall_threshold: which grey levels of a plain image are walls -----------
def test_image_wall_threshold_splits_the_grey_levels(tmp_path):
    """A plain image's pixel is wall when (255 - v) / 255 exceeds the threshold: at 0.5,
    grey 127 (0.502) is wall and 128 (0.498) is not."""
    img = np.full((8, 8), 255, dtype=np.uint8)
    img[2, 2], img[2, 5], img[6, 6] = 127, 128, 0  # (black: always a wall; a plan needs one)
    path = tmp_path / "plan.png"
    cv2.imwrite(str(path), img)

    def walls(threshold):
        settings = load_settings(overrides=[f"floorplan.image_wall_threshold={threshold}"])
        plan = Floorplan.load(path, resolution=0.05, origin=(0.0, 0.0), settings=settings)
        return int(plan.occupied.sum()), bool(plan.occupied[::-1][2, 2]), bool(plan.occupied[::-1][2, 5])

    assert walls(0.5) == (2, True, False)
    assert walls((255 - 128) / 255) == (2, True, False)  # 128 exactly at the threshold: not above it
    assert walls(float(np.nextafter((255 - 128) / 255, 0.0))) == (3, True, True)
    assert walls((255 - 127) / 255) == (1, False, False)
