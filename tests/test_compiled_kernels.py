"""The compiled kernels: the one-line notice printed at the first real compile of a process,
once, on stderr (a kernel loaded from numba's cache fires no compile event); the former
estimator.kernels setting still loads, ignored, with a FutureWarning."""

import numba

from zfloc_stream.runtime import numba_support


def test_the_first_compile_says_so_once_on_stderr(capsys, monkeypatch):
    monkeypatch.setattr(numba_support, "_noticed", False)
    numba.njit(lambda x: x + 1)(1)  # not cached: always a real compile
    numba.njit(lambda x: x + 2)(1)
    err = capsys.readouterr().err
    assert err.count(numba_support.COMPILE_NOTICE) == 1 and "once per machine, cached" in err


def test_the_former_kernels_setting_still_loads_and_is_ignored():
    import pytest

    from zfloc_stream.settings.loading import Settings, load_settings

    for kernels in ("numpy", "numba"):
        with pytest.warns(FutureWarning, match="estimator.kernels is ignored"):
            settings = load_settings(overrides=[f"estimator.kernels={kernels}"])
        assert settings == Settings() and "kernels" not in settings.estimator.model_dump()


# --------------------------------------------------------------------------------------
# Degenerate inputs, every compiled kernel (issue 44): empty, one element, all masked.
# Compiled code has no bounds check, so an out-of-bounds write corrupts the heap (issue
# 44: a camera frame without a wall pixel aborted the process). Each test below calls its
# kernels as their callers can; test_degenerate_calls_pass_numbas_bounds_check (slow) reruns
# them with numba's bounds check on, where any out-of-bounds index raises IndexError.
# --------------------------------------------------------------------------------------

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from zfloc_stream.settings.loading import WallMaskSettings  # noqa: E402

EMPTY2 = np.zeros((0, 2))


def _rays(n, z=1.0):
    """n pixel rays K^-1 p spread over a 60-degree view, z = 1."""
    x = np.linspace(-0.5, 0.5, n) if n > 1 else np.zeros(n)
    return np.column_stack([x, np.zeros(n), np.full(n, z)])


@pytest.mark.parametrize("case", ["empty", "one wall", "one other", "no wall", "all wall", "all behind", "wall behind"])
def test_wall_mask_kernels_on_degenerate_pixels(case):
    """_wall_columns, _farthest_segments. "no wall": issue 44's SIGABRT (a frame whose
    labels are all 0 wrote past a 0-length column array)."""
    from zfloc_stream.frontend.wallmask import refine_wall_points

    K = np.array([[100.0, 0, 80], [0, 100, 60], [0, 0, 1]])
    n = {"empty": 0, "one wall": 1, "one other": 1}.get(case, 400)
    rays = _rays(n)
    depth = np.full(n, 3.0)
    is_wall = np.full(n, case in ("one wall", "all wall", "wall behind"))
    if case == "wall behind":  # the walls behind the camera, the rest in front
        is_wall[: n // 2] = True
        is_wall[n // 2:] = False
        rays[: n // 2, 2] = -1.0
    if case == "all behind":
        rays[:, 2] = -1.0
    for _ in range(20):  # an out-of-bounds write shows at a later free(), not at once
        kept = refine_wall_points(rays, depth, is_wall, K, np.eye(3), WallMaskSettings())
    assert kept.shape == (n,) and kept.dtype == bool
    assert not (kept & ~is_wall).any()
    if case in ("one wall", "all wall"):
        assert kept.all()  # one wall depth per column, nothing deeper
    if case in ("no wall", "all behind", "wall behind", "empty", "one other"):
        assert not kept.any()


def test_wall_mask_of_a_frame_without_wall_labels_keeps_nothing():
    """The image-level call on issue 44's frame: labels all 0 (no wall), valid depth."""
    from zfloc_stream.frontend.wallmask import refine_wall_mask

    K = np.array([[100.0, 0, 80], [0, 100, 60], [0, 0, 1]])
    depth = np.full((120, 160), 3.0)
    for labels in (np.zeros((120, 160), np.uint8), np.full((120, 160), 255, np.uint8)):
        for _ in range(20):
            out = refine_wall_mask(depth, labels, K, np.eye(3), WallMaskSettings())
        assert out.shape == depth.shape and not out.any()


def test_scrolling_grid_kernels_on_degenerate_points():
    """_cell, _unique_cells, _open_without_wall_near: no point, one, all outside, NaN,
    reach beyond the grid, a grid of one cell."""
    from zfloc_stream.frontend.scrolling_grid import ScrollingGrid

    for n in (1, 8):
        g = ScrollingGrid(n, 0.1)
        g.centre_on(np.zeros(2), 2)
        g.seen[:] = 1
        g.logodds[:] = -1.0
        far = np.array([[1e3, 1e3], [-1e3, 5.0], [np.nan, 0.0], [0.0, np.inf]])
        for xy in (EMPTY2, np.zeros((1, 2)), far):
            flat = g.unique_flat(xy)
            assert flat.dtype == np.int64 and ((flat >= 0) & (flat < n * n)).all()
            assert len(g.unique_flat(xy, min_count=5)) == 0
            for reach in (0, 3, 10 * n):
                known, lonely = g.open_without_wall_near(xy, 0.0, 1.0, reach, 0)
                assert 0 <= lonely <= known <= len(xy)
        assert g.unique_flat(np.zeros((1, 2))).tolist() == [(n // 2) * n + n // 2]
        assert not g._count.any()  # the scratch is zero again


def test_bev_grid_kernels_on_empty_grids():
    """known_extent, crop_masks, clearance: a 0x0 grid, nothing known, an empty crop, one cell."""
    from zfloc_stream.frontend import bev_grids

    for n in (0, 1, 4):
        lo = np.zeros((n, n), np.float32)
        wall = np.zeros((n, n), np.uint16)
        hits = np.zeros((n, n), np.uint16)
        seen = np.zeros((n, n), np.int32)
        for use_recent in (False, True):
            assert bev_grids.known_extent(lo, wall, hits, seen, 1, 0.5, np.float32(0.5), use_recent, 0) == (False, 0, -1, 0, -1)
        for r0, r1, c0, c1 in ((0, 0, 0, 0), (0, n, 0, n), (0, n, n, n)):
            free, not_occ, pts = bev_grids.crop_masks(lo, wall, hits, seen, r0, r1, c0, c1, 1, 0.5, np.float32(0.5),
                                                      np.float32(-0.5), False, 0, 0.0, 0.0, 0.05)
            assert free.shape == not_occ.shape == (r1 - r0, c1 - c0) and pts.shape == (0, 2)
            out = bev_grids.clearance(np.zeros(free.shape, np.float32), free, 0.05)
            assert out.shape == free.shape and not out.any()
    one = np.ones((1, 1), np.float32)
    free, _, pts = bev_grids.crop_masks(one, np.full((1, 1), 9, np.uint16), np.zeros((1, 1), np.uint16),
                                        np.ones((1, 1), np.int32), 0, 1, 0, 1, 1, 0.5, np.float32(0.5), np.float32(-0.5),
                                        False, 0, 0.0, 0.0, 0.05)
    assert pts.tolist() == [[0.025, 0.025]] and not free.any()


def test_scan_match_rotation_kernel_on_degenerate_fields():
    """_best_rotation: no point, a 1x1 and a 0x0 field, a zero search range, NaN points."""
    from zfloc_stream.frontend.scan_match import _best_rotation

    pts = np.array([[1.0, 0.0], [np.nan, 1.0], [1e300, -1e300]])
    for field in (np.zeros((0, 0)), np.zeros((1, 1)), np.ones((3, 5))):
        for p in (EMPTY2, pts[:1], pts):
            for max_angle in (0.0, 0.2):
                theta = _best_rotation(field, np.zeros(2), 0.05, p, 0.05, 0.2, max_angle, 0.05)
                assert abs(theta) <= max_angle


def test_circle_kernels_on_degenerate_clusters():
    """link_groups, cluster_members, work_sizes, _fit_circle (through _circle_in_cluster),
    angular_coverage_and_span, best_two_line_sse, _clusters: nothing, one point, no
    draws, one cluster of coincident points."""
    from zfloc_stream.primitives import arc_checks, point_groups
    from zfloc_stream.primitives import circle_fitting as cf

    keep, group = point_groups.link_groups(EMPTY2, np.zeros((0, 2), np.int64), 1.0, 1)
    assert len(keep) == len(group) == 0
    keep, group = point_groups.link_groups(np.zeros((1, 2)), np.zeros((0, 2), np.int64), 1.0, 1)
    assert keep.tolist() == [0] and group.tolist() == [0]
    none = np.zeros(0, np.int64)
    assert [len(a) for a in point_groups.cluster_members(none, none, 0, 0)] == [0, 0]
    assert len(point_groups.work_sizes(EMPTY2, none, none, 0, 0, 1.0)) == 0
    assert arc_checks.angular_coverage_and_span(np.zeros(0), 0.5) == (0.0, 0.0)
    assert arc_checks.angular_coverage_and_span(np.zeros(1), 0.5) == (0.0, 0.0)
    assert arc_checks.best_two_line_sse(EMPTY2, 3) == np.inf and arc_checks.best_two_line_sse(np.zeros((6, 2)), 3) == 0.0
    same = np.zeros((5, 2))
    ok = cf._circle_in_cluster(same, same, np.zeros((0, 3), np.int64), 0.02, 0.05, 0.5, 2, 10, 3, 0.5, 0.5, 1.0, 1.0)
    assert ok == (False, 0.0, 0.0, 0.0)
    ok = cf._circle_in_cluster(same, same, np.zeros((4, 3), np.int64), 0.02, 0.05, 0.5, 2, 10, 3, 0.5, 0.5, 1.0, 1.0)
    assert not ok[0]
    centres, radii = cf._clusters(EMPTY2, none, none, 0, none, np.zeros((0, 3), np.int64), 10, 0.02, 0.05, 0.5, 2, 10,
                                  3, 0.5, 0.5, 1.0, 1.0)
    assert centres.shape == (0, 2) and len(radii) == 0


@pytest.mark.parametrize("points", ["none", "one", "two", "coincident", "collinear"])
def test_primitive_extraction_kernels_on_degenerate_clouds(points):
    """line_growing (_extract, _grow, free_points_in_ball / _band, _pca_line) and the
    circle path (extract_circles) on clouds with nothing to find."""
    from zfloc_stream.primitives.circle_fitting import extract_circles
    from zfloc_stream.settings.loading import Settings
    from zfloc_stream.primitives.line_growing import extract_lines
    from zfloc_stream.runtime.rng import make_rng

    pts = {"none": EMPTY2, "one": np.zeros((1, 2)), "two": np.array([[0.0, 0.0], [0.05, 0.0]]),
           "coincident": np.zeros((200, 2)), "collinear": np.column_stack([np.linspace(0, 1, 50), np.zeros(50)])}[points]
    prim = Settings().primitives
    for min_points in (2, prim.lines.min_points):
        lines = extract_lines(pts, prim.lines.model_copy(update={"min_points": min_points, "min_length": 0.0}), make_rng(0))
        assert np.isfinite(lines.offsets).all()
    circles = extract_circles(pts, prim.circles, make_rng(0))
    assert len(circles.radii) == 0


def test_draw_and_solver_kernels_on_no_samples():
    """cumulate, draw_row, _draw_rows, draw_block, _admissible_triplets, the 3L and 2L
    kernels on given and on drawn samples, _wrap_headings: no queries, no candidates,
    lines without neighbours."""
    from zfloc_stream.estimation import draws
    from zfloc_stream.estimation.solvers import models, three_lines, two_lines

    z = np.zeros(0, np.int64)
    for starts, sizes in ((np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64)),
                          (np.zeros((3, 2), np.int64), np.zeros((3, 2), np.int64)),
                          (np.zeros((1, 0), np.int64), np.zeros((1, 0), np.int64))):
        q, r = draws.draw(starts, sizes, 0.5, np.random.default_rng(0))
        assert len(q) == len(r) == 0
    rows, weight = draws.admissible_triplets([], np.zeros(0), 0.1, np.zeros(0))
    assert rows.shape == (0, 3)
    rows, weight = draws.admissible_triplets([[], [0], [0, 1]], np.array([0.0, 1.0, 2.0]), 0.1, np.ones(3))
    assert ((rows >= 0) & (rows < 3)).all() and len(rows) == len(weight) == 2
    f = np.zeros(0)
    lines = models.LineColumns(f, f, f)
    ids3, ids2 = np.zeros((0, 3), np.int64), np.zeros((0, 2), np.int64)
    limits3 = three_lines.Limits3L(0.9, 0.5, 2.0, 0.1, 1e-9, 0.5, 2.0)
    anchor = three_lines.AnchorRotations(f, f, f, 0)
    found, src = three_lines._solve_samples(ids3, ids3, lines, lines, anchor, limits3)
    assert found.shape == (0, 4) and len(src) == 0
    rotations = two_lines.CandidateRotations(f, f, f, f, f, 0)
    limits2 = two_lines.Limits2L(0.9, 0.1, 0.5, 2.0, True)
    found, src = two_lines._solve_samples(ids2, ids2, f, lines, lines, rotations, limits2)
    assert found.shape == (0, 4) and len(src) == 0
    none = draws.Draws(np.zeros((0, 1), np.int64), np.zeros((0, 1), np.int64), z, f)
    found, src = two_lines._solve_drawn(none, (0, 0, 0, 0), ids2, ids2, f, lines, lines, rotations, limits2)
    assert found.shape == (0, 4)
    found, src = three_lines._solve_drawn(none, (0, 0, 0, 0), ids3, ids3, lines, lines, anchor, limits3)
    assert found.shape == (0, 4)
    empty_models = np.zeros((0, 4))
    models._wrap_headings(empty_models)


def test_scoring_kernels_on_no_points_no_models():
    """_coarse_kernel, _consistency_kernel, _violation_kernel, _greedy_distinct_kernel:
    no model, no point (the share is NaN, never an index), no wall point, limit 0."""
    from zfloc_stream.estimation import distinct_poses, scoring

    f32 = np.zeros(0, np.float32)
    one = np.array([[0.0, 0.0, 0.0, 1.0]])
    for models in (np.zeros((0, 4)), one):
        out = np.zeros(len(models))
        scoring._coarse_kernel(models, 20.0, 0.0, 0.0, f32, f32, np.zeros(4, np.uint8), 2, 2, np.uint32, out)
        scoring._coarse_kernel(models, 20.0, 0.0, 0.0, np.ones(1, np.float32), np.ones(1, np.float32),
                               np.zeros(4, np.uint8), 2, 2, np.uint32, out)
        assert scoring._consistency_kernel(models[:, 3], models[:, 2], models[:, 0], models[:, 1], np.ones(1), np.ones(1),
                                           np.zeros(4), 2, 2, 0.0, 0.0, 0.05, 0.1, out)
        z = np.zeros(len(models), np.int64)
        empty = np.ones(len(models), np.bool_)
        scoring._violation_kernel(models[:, 0], models[:, 1], np.ones(len(models)), models[:, 2], np.ones(len(models)),
                                  z, z, z, z, empty, np.zeros(2, np.int64), 1, EMPTY2, np.zeros(4, np.uint8), 2, 2, 0.0,
                                  0.0, False, out)
        scoring._violation_kernel(models[:, 0], models[:, 1], np.ones(len(models)), models[:, 2], np.ones(len(models)),
                                  z, z, z, z, ~empty, np.zeros(2, np.int64), 1, EMPTY2, np.zeros(4, np.uint8), 2, 2, 0.0,
                                  0.0, True, out)
    kept = np.zeros(0, np.int64)
    assert distinct_poses._greedy_distinct_kernel(np.zeros(0), np.zeros(0), np.zeros(0), 1.0, 0.1, 5, kept) == 0
    kept = np.zeros(3, np.int64)
    assert distinct_poses._greedy_distinct_kernel(np.zeros(3), np.zeros(3), np.zeros(3), 1.0, 0.1, 0, kept) == 0
    assert distinct_poses._greedy_distinct_kernel(np.zeros(3), np.zeros(3), np.zeros(3), 1.0, 0.1, 3, kept) == 1


def test_correlative_kernels_on_degenerate_scores():
    """_template, _pair_products, _row_maxima, _kth_largest, _pick: no cell, no placement
    column, fewer candidates than wanted, NaN scores."""
    from zfloc_stream.estimation import angle_search as co

    assert not co._template(np.zeros((0, 2), np.int64), 4, 6).any()
    F = np.zeros((0, 0), np.complex64)
    co._pair_products(F, F, F, F)
    assert len(co._row_maxima(np.zeros((0, 4), np.float32), 4)) == 0
    assert co._row_maxima(np.ones((2, 3), np.float32), 3).tolist() == [1.0, 1.0]
    assert co._kth_largest(np.arange(3.0), 1) == 2.0
    for score in (np.zeros((0, 4), np.float32), np.zeros((3, 4), np.float32), np.full((3, 4), np.nan, np.float32)):
        for per_angle in (1, 5, 100):
            best, counts, ok = co._pick(score, 4, per_angle, 0.01)
            assert len(best) == len(counts) <= per_angle
            assert ok == (per_angle <= len(score) and not np.isnan(score).any())  # else the exact pass
            assert ((best >= 0) & (best < score.shape[0] * 4)).all()


def test_field_fit_kernels_on_degenerate_fields():
    """_evaluate, _solve, _refine_models (via refine_batch): no model, NaN models,
    points far outside a 2x2 field, a singular system."""
    from zfloc_stream.settings.loading import RefineSettings
    from zfloc_stream.estimation.field_fit import _refine_models, _solve, refine_batch
    from zfloc_stream.frontend.scan_match import GridField

    field = GridField(np.zeros((2, 2)), np.zeros(2), 0.05)
    pts = np.array([[1e6, 0.0], [0.0, -1e6], [0.5, 0.5], [1.0, 2.0], [3.0, 1.0]])
    for models in (np.zeros((0, 4)), np.array([[np.nan, 0, 0, 1], [0, 0, 0, 1], [1e300, 0, 0, 1]])):
        out = refine_batch(field, pts, models, RefineSettings(), "fixed")
        assert out.shape == models.shape
    _refine_models(np.zeros(4), 2, 2, 0.0, 0.0, 0.05, EMPTY2, np.zeros((1, 4)), False, -1.0, 1.0, 0.1, 0.3, 1e-3, 10.0,
                   1e-9, 5)
    A = np.zeros((4, 4))
    assert not _solve(A, np.zeros(4), 3, np.zeros(4))


@pytest.mark.slow
def test_degenerate_calls_pass_numbas_bounds_check(tmp_path):
    """The degenerate tests above with numba's bounds check compiled in (NUMBA_BOUNDSCHECK=1,
    a cache of their own so the package's cache keeps its unchecked kernels): an index out
    of bounds raises IndexError instead of writing past an array. Compiles every kernel
    (minutes)."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, NUMBA_BOUNDSCHECK="1", NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", __file__,
                             "-k", "degenerate or without_wall_labels", "-m", "not slow"],
                            env=env, capture_output=True, text=True, timeout=1800)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
