"""Issue 43: a plan over floorplan.max_cells (the cells the estimator keeps) loads pooled to
coarser cells with a warning instead of being refused; floorplan.max_image_cells is the
limit on what is read, named in its error. Small rasters with small budgets stand for a
300 m building against the defaults (benchmarks/bench_plan_load.py --large 300 loads one)."""

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.errors import FloorplanError
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.plans.raster_files import coarsening, pooled


def rooms(h=120, w=160):
    occ = np.zeros((h, w), dtype=bool)
    occ[:2], occ[-2:], occ[:, :2], occ[:, -2:] = True, True, True, True
    occ[60, 20:140] = True  # a one-cell wall: pooling must keep it closed
    return occ


def test_default_limits_hold_a_300_m_building():
    cfg = Settings().floorplan
    cells = 6040 * 6040  # 300 m + margins at 0.05 m, over the old refusal limit (25 M)
    assert cells > cfg.max_cells and cells <= cfg.max_image_cells
    assert coarsening((6040, 6040), Settings()) == 2


@pytest.mark.parametrize("shape,limit,k", [((10, 10), 100, 1), ((10, 10), 99, 2), ((11, 10), 30, 2), ((11, 10), 29, 3)])
def test_coarsening_is_the_smallest_factor_that_fits(shape, limit, k):
    settings = load_settings(overrides=[f"floorplan.max_cells={limit}"])
    assert coarsening(shape, settings) == k


def test_pooled_keeps_thin_walls_and_origin():
    occ = np.zeros((5, 7), dtype=bool)
    occ[3, 0:7] = True
    occ[0, 6] = True
    out = pooled(occ, 2)
    assert out.shape == (3, 4)
    assert out[1].all() and not out[0, :3].any() and out[0, 3] and not out[2].any()


def test_plan_over_max_cells_loads_pooled_with_a_warning():
    occ = rooms()
    settings = load_settings(overrides=[f"floorplan.max_cells={occ.size - 1}"])
    with pytest.warns(UserWarning, match=r"floorplan.max_cells = 19,199: localizing on 0.1 m cells \(80x60\)"):
        plan = Floorplan.from_occupancy(occ, 0.05, (-1.0, 2.0), settings, name="big")
    assert plan.resolution == 0.1 and plan.shape == (60, 80) and tuple(plan.origin) == (-1.0, 2.0)
    assert plan.occupied[30, 10:70].all()  # the one-cell wall at row 60 of the raster
    # at its limit the plan keeps every cell, as before
    exact = Floorplan.from_occupancy(occ, 0.05, (-1.0, 2.0), load_settings(overrides=[f"floorplan.max_cells={occ.size}"]))
    assert exact.resolution == 0.05 and exact.shape == occ.shape


def test_plan_over_max_image_cells_is_refused_naming_the_setting(tmp_path):
    path = Floorplan.from_occupancy(rooms(), 0.05, (0.0, 0.0)).write_ros(tmp_path)
    settings = load_settings(overrides=[f"floorplan.max_image_cells={120 * 160 - 1}"])
    with pytest.raises(FloorplanError, match=r"more than floorplan.max_image_cells = 19,199 .*--set floorplan.max_image_cells=N"):
        Floorplan.load(path, settings=settings)
    assert Floorplan.load(path).shape == (120, 160)


def test_ros_map_with_unknown_cells_over_max_cells_loads_pooled(tmp_path):
    # a ROS map's grey (unknown) cells are pooled with the walls, not refused as a mask of
    # the wrong shape (every gmapping map has grey around the building)
    occ = rooms()
    unknown = np.zeros_like(occ)
    unknown[10:20, 10:21] = True
    path = Floorplan(occ, 0.05, (0.0, 0.0), unknown=unknown, name="grey").write_ros(tmp_path)
    settings = load_settings(overrides=[f"floorplan.max_cells={occ.size - 1}"])
    with pytest.warns(UserWarning, match=r"localizing on 0.1 m cells \(80x60\)"):
        plan = Floorplan.load(path, settings=settings)
    assert plan.shape == (60, 80) and plan.unknown is not None
    assert plan.unknown[5:10, 5:11].all() and plan.unknown.sum() == 5 * 6
    assert not (plan.unknown & plan.occupied).any()


def test_vector_plan_over_max_cells_is_drawn_coarser_with_a_warning(tmp_path):
    """A drawing over floorplan.max_cells is drawn at once on coarser cells (no full-size
    raster); its lines stay the drawing's own. A 300 m drawing (36.5 M cells at 0.05 m) is
    under datasets.vector_floorplan.max_cells by default, so it loads."""
    from benchmarks.inputs.hostile_plans import BOX, write_dxf
    from zfloc_stream.plans.vector import load_vector_floorplan

    path = write_dxf(tmp_path / "room.dxf", BOX + [((0, 4), (6, 4))])  # 10 x 8 m + 1 m margins: 240 x 200 cells
    exact = load_vector_floorplan(path)
    settings = load_settings(overrides=[f"floorplan.max_cells={240 * 200 - 1}"])
    with pytest.warns(UserWarning, match=r"floorplan 'room': 240x200 cells at 0.05 m .* localizing on 0.1 m cells \(120x100\)"):
        plan = load_vector_floorplan(path, settings)
    assert plan.resolution == pytest.approx(0.1) and plan.shape == (100, 120)
    assert np.allclose(plan.origin, exact.origin)
    assert np.array_equal(plan.lines.endpoints, exact.lines.endpoints)
    assert plan.occupied[plan.world_to_cell(np.array([[3.0, 4.0]]))].all()  # the inner wall is drawn
    assert Settings().datasets.vector_floorplan.max_cells >= 6040 * 6040
