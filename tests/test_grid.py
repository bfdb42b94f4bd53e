"""geometry/grid.py and geometry/bilinear.py: the one grid type (cell of a point, centres,
windows) and the one compiled bilinear lookup, bit for bit the numpy arithmetic every copy
of it used to run (the two forms below are those copies, kept here as the reference)."""

import numpy as np
import pytest

from zfloc_stream.geometry.grid import Grid
from zfloc_stream.estimation.field_fit import field_value_and_gradient
from zfloc_stream.frontend.scan_match import GridField


def cell_and_fractions(field, origin, res, q):
    """The part both forms share: cell coordinates, clipped, the lower-left cell and the fractions."""
    h, w = field.shape
    u = (q[:, 0] - origin[0]) / res - 0.5
    v = (q[:, 1] - origin[1]) / res - 0.5
    uc, vc = np.clip(u, 0.0, w - 1.0), np.clip(v, 0.0, h - 1.0)
    c0 = np.minimum(uc.astype(np.int64), w - 2)
    r0 = np.minimum(vc.astype(np.int64), h - 2)
    return u, v, uc, vc, r0 * w + c0, uc - c0, vc - r0


def corner_weights(field, origin, res, q):
    """The corner-weight form (Floorplan.distance and the Cc kernel before the grid type)."""
    f, w = field.ravel(), field.shape[1]
    u, v, uc, vc, i, fu, fv = cell_and_fractions(field, origin, res, q)
    top = f[i] * (1.0 - fu) + f[i + 1] * fu
    bottom = f[i + w] * (1.0 - fu) + f[i + w + 1] * fu
    return top * (1.0 - fv) + bottom * fv + np.hypot(u - uc, v - vc) * res


def differences(field, origin, res, q):
    """The difference form with its gradient (field_fit's numpy lookup before the grid type)."""
    f, w = field.ravel(), field.shape[1]
    u, v, uc, vc, i, fu, fv = cell_and_fractions(field, origin, res, q)
    f00, f01, f10, f11 = f[i], f[i + 1], f[i + w], f[i + w + 1]
    bottom = f00 + (f01 - f00) * fu
    top = f10 + (f11 - f10) * fu
    value = bottom + (top - bottom) * fv + np.hypot(u - uc, v - vc) * res
    gu = np.where(u == uc, (f01 - f00) + (f11 - f10 - f01 + f00) * fv, 0.0) / res
    gv = np.where(v == vc, top - bottom, 0.0) / res
    return value, np.stack([gu, gv], axis=1)


@pytest.fixture(scope="module")
def field_and_points():
    rng = np.random.default_rng(3)
    field = rng.uniform(0.0, 2.0, (37, 53))
    grid = Grid(np.array([-1.3, 2.2]), 0.05, field.shape)
    q = np.column_stack([rng.uniform(-2.0, 2.0, 5000), rng.uniform(1.0, 5.0, 5000)])  # inside and outside
    rows, cols = rng.integers(0, 37, 100), rng.integers(0, 53, 100)
    q[:100] = np.column_stack(grid.centres(rows, cols))
    return field, grid, q, rows, cols


def test_cells_and_centres():
    grid = Grid((-1.0, 0.5), 0.1, (20, 30))
    rows, cols = np.arange(20), np.arange(20)[::-1] + 5
    x, y = grid.centres(rows, cols)
    assert np.array_equal(np.stack(grid.cell_of(np.column_stack([x, y]))), np.stack([rows, cols]))
    row, col = grid.cell_of([[-1.0, 0.5], [-1.0 - 1e-9, 0.5], [1.9999, 2.4999]])
    assert row.tolist() == [0, 0, 19] and col.tolist() == [0, -1, 29]
    row, col, inside = grid.cells([[-5.0, 0.65], [2.05, 2.45], [0.0, 1.05]])
    assert row.tolist() == [1, 19, 5] and col.tolist() == [0, 29, 10] and inside.tolist() == [False, False, True]
    assert grid.window(0.0, 1.0, 0.3, 1.2) == (4, 8, 9, 14)
    assert grid.window(-9.0, -9.0, 9.0, 9.0) == (0, 20, 0, 30)


def test_bilinear_is_the_corner_weight_arithmetic_bit_for_bit(field_and_points):
    field, grid, q, rows, cols = field_and_points
    got = grid.bilinear(field, q)
    assert np.array_equal(got, corner_weights(field, grid.origin, grid.resolution, q))
    assert got[:100] == pytest.approx(field[rows, cols], abs=1e-9)  # the cell values at the centres
    assert np.array_equal(grid.bilinear(field.astype(np.float32), q), corner_weights(field.astype(np.float32), grid.origin, grid.resolution, q))


def test_outside_the_grid_the_edge_value_plus_the_distance(field_and_points):
    field, grid, _, _, _ = field_and_points
    x, y = grid.centres(np.array([10]), np.array([0]))  # the first column's centre
    far = grid.bilinear(field, [[x[0] - 3.0, y[0]]])
    assert far[0] == pytest.approx(field[10, 0] + 3.0, abs=1e-12)


def test_value_and_gradient_is_the_difference_arithmetic_bit_for_bit(field_and_points):
    field, grid, q, _, _ = field_and_points
    for f in (field, field.astype(np.float32)):
        value, grad = field_value_and_gradient(GridField(f, grid.origin, grid.resolution), q)
        ref_value, ref_grad = differences(f, grid.origin, grid.resolution, q)
        assert np.array_equal(value, ref_value) and np.array_equal(grad, ref_grad)
    # the gradient is the interpolant's: a central difference inside a cell agrees
    p = np.column_stack(grid.centres(np.array([12]), np.array([20]))) + 0.3 * grid.resolution
    e = 1e-7
    _, g = field_value_and_gradient(GridField(field, grid.origin, grid.resolution), p)
    dx = (grid.bilinear(field, p + [e, 0]) - grid.bilinear(field, p - [e, 0])) / (2 * e)
    dy = (grid.bilinear(field, p + [0, e]) - grid.bilinear(field, p - [0, e])) / (2 * e)
    assert g[0] == pytest.approx([dx[0], dy[0]], rel=1e-5)


def test_a_nan_point_reads_nan_in_the_gradient_lookup(field_and_points):
    field, grid, _, _, _ = field_and_points
    value, grad = field_value_and_gradient(GridField(field, grid.origin, grid.resolution), np.array([[np.nan, 3.0], [0.0, 3.0]]))
    assert np.isnan(value[0]) and np.isnan(grad[0]).all() and np.isfinite(value[1])


def test_the_floorplan_reads_f_c_through_its_grid():
    from plan_helpers import building

    fp = building()
    rng = np.random.default_rng(0)
    x0, y0, x1, y1 = fp.extent
    q = np.column_stack([rng.uniform(x0 - 1, x1 + 1, 3000), rng.uniform(y0 - 1, y1 + 1, 3000)])
    assert np.array_equal(fp.distance(q), corner_weights(fp.distance_field, fp.origin, fp.resolution, q))
    assert np.array_equal(np.stack(fp.world_to_cell(q)), np.stack(fp.grid.cell_of(q)))
