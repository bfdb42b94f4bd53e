"""The hybrid RANSAC's compiled draws (estimation/draws.py) and the fused draw-and-solve
of 3L / 2L samples (estimation/solvers/): what a draw returns, what it takes from the random
stream, the triplet table's definition, and the models' invariants."""

import math

import numpy as np
import pytest

from draw_helpers import assert_same_bits, draw_scene, estimator_for

from zfloc_stream.estimation import correspondences, model_generation
from zfloc_stream.estimation.draws import admissible_triplets, draw

from types import SimpleNamespace

from zfloc_stream.settings.loading import Settings
from zfloc_stream.geometry.shapes import CircleSet, LineSet


@pytest.mark.parametrize("seed", range(6))
def test_a_draw_meets_ceil_fraction_of_each_querys_candidates_inside_its_ranges(seed):
    gen = np.random.default_rng(seed)
    queries, ranges = int(gen.integers(0, 300)), int(gen.choice([1, 3, 9]))
    # empty ranges and whole empty queries included
    sizes = gen.integers(0, 50, (queries, ranges)) * (gen.random((queries, ranges)) < 0.7)
    starts = gen.integers(0, 10_000, (queries, ranges))
    fraction = float(gen.choice([0.03, 0.5, 1.0]))
    q, row = draw(starts, sizes, fraction, np.random.default_rng(seed))
    n = sizes.sum(axis=1)
    expected = [max(math.ceil(fraction * k), 1) if k else 0 for k in n]
    assert np.array_equal(np.bincount(q, minlength=queries), expected) and np.all(np.diff(q) >= 0)
    inside = (row[:, None] >= starts[q]) & (row[:, None] < starts[q] + sizes[q])
    assert inside.any(axis=1).all()
    again = draw(starts, sizes, fraction, np.random.default_rng(seed))
    assert np.array_equal(again[0], q) and np.array_equal(again[1], row)


def test_a_draw_takes_one_uniform_per_draw_from_the_stream():
    sizes, starts = np.array([[3, 0, 5]]), np.array([[10, 20, 30]])
    a, b = np.random.default_rng(4), np.random.default_rng(4)
    q, _ = draw(starts, sizes, 1.0, a)
    b.random(len(q))
    assert a.random() == b.random()


def test_draw_with_no_candidates():
    q, row = draw(np.zeros((4, 9), np.int64), np.zeros((4, 9), np.int64), 0.03, np.random.default_rng(0))
    assert len(q) == 0 and len(row) == 0


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("mode, fraction", [("free", 0.03), ("prior", 1.0), ("fixed", 0.5)])
def test_fused_line_models_are_finite_within_the_scale_bounds_and_repeatable(seed, mode, fraction):
    bev, fp = draw_scene(seed)
    cfg = estimator_for(mode, fraction)
    a, b = np.random.default_rng(seed), np.random.default_rng(seed)
    for solve in (lambda rng: model_generation.models_3l(bev, fp, 700, cfg, rng), lambda rng: model_generation.models_2l(bev, fp, 600, cfg, rng, 1.05)):
        got, again = solve(a), solve(b)
        assert_same_bits(got, again)
        assert len(got) > 20 and np.isfinite(got).all()
        assert np.all(np.abs(got[:, 2]) <= np.pi)
        if mode == "fixed":
            assert np.all(got[:, 3] == 1.0)
        else:
            assert np.all((got[:, 3] >= cfg.solvers.min_scale) & (got[:, 3] <= cfg.solvers.max_scale))
    assert a.random() == b.random()


def test_fused_without_candidates():
    """BEV samples whose angles match no floorplan tuple: no draw, no model, and (at a
    prior) the zero-size noise draw; the generator is left as it was."""
    from zfloc_stream.estimation.solvers import drawn_2l, drawn_3l

    bev, fp = draw_scene(0)
    starts, sizes = np.zeros((5, 9), np.int64), np.zeros((5, 9), np.int64)
    cfg = estimator_for("prior", 0.03)
    a, b = np.random.default_rng(1), np.random.default_rng(1)
    models, source = drawn_3l(starts, sizes, 0.03, a, bev.triplets[:5], fp.triplets.rows, bev.lines, fp.lines,
                              correspondences.line_angles(bev.lines), fp.line_angles, cfg.solvers)
    assert models.shape == (0, 4) and len(source) == 0
    models, _ = drawn_2l(starts[:, :3], sizes[:, :3], 0.03, a, bev.pairs[:5], fp.pairs.rows, bev.lines, fp.lines,
                         correspondences.line_angles(bev.lines), fp.line_angles, 1.0, cfg.solvers, "prior")
    assert models.shape == (0, 4)
    assert a.random() == b.random()


def _random_lines(gen, n, angle_choices):
    """n segments, directions drawn from angle_choices (repeats: exactly parallel lines)
    plus some just inside / outside the parallel threshold, scattered over 20 m."""
    from zfloc_stream.geometry.shapes import LineSet

    angles = gen.choice(angle_choices, n) + gen.choice([0.0, 0.0, 1e-9, -1e-9, 0.3, 5.0], n) * np.pi / 180
    centres = gen.uniform(-10, 10, (n, 2))
    half = gen.uniform(0.3, 3.0, n)[:, None] * np.column_stack([np.cos(angles), np.sin(angles)])
    return LineSet.from_endpoints(np.stack([centres - half, centres + half], axis=1))



@pytest.mark.parametrize("seed", range(6))
def test_the_triplet_table_is_every_ordered_non_parallel_triplet_of_neighbours(seed):
    gen = np.random.default_rng(seed)
    n = int(gen.choice([0, 1, 2, 3, 12, 40]))
    lines = _random_lines(gen, n, np.deg2rad([0.0, 90.0, 45.0, 2.0, 178.0]))
    alpha = correspondences.normal_angles(lines)
    par = np.deg2rad(5.0)
    neighbours = [np.flatnonzero((gen.random(n) < 0.3) & (np.arange(n) != i)) for i in range(n)]
    rows, weights = admissible_triplets(neighbours, alpha, par, lines.lengths)

    def parallel(i, j):
        return abs(math.sin(alpha[i] - alpha[j])) < math.sin(par)

    expected = [(i, j, k) for i, nb in enumerate(neighbours) for j in nb for k in nb
                if j != k and not (parallel(i, j) and parallel(i, k))]
    assert rows.dtype == np.int64 and [tuple(r) for r in rows] == expected
    assert np.array_equal(weights, lines.lengths[rows].min(axis=1) if len(rows) else np.zeros(0))


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("mode", ["free", "prior", "fixed"])
def test_drawn_line_models_are_the_solvers_on_the_drawn_samples(seed, mode):
    """Solving is apart from sampling: drawn_3l / drawn_2l give, bit for bit, what
    draws.draw followed by solve_3l / solve_2l on the drawn samples gives (2L at a prior:
    the same scale noise, drawn after the uniforms)."""
    from zfloc_stream.estimation.solvers import drawn_2l, drawn_3l, sample_scale_noise, solve_3l
    from zfloc_stream.estimation.solvers.two_lines import two_lines_at_scales

    bev, fp = draw_scene(seed)
    cfg = estimator_for(mode, 0.5)
    angles = correspondences.line_angles(bev.lines)
    three = mode == "free"
    picks = bev.triplets if three else bev.pairs
    table = fp.triplets if three else fp.pairs
    starts, sizes = table.ranges(np.mod(bev.alpha[picks[:, 1:]] - bev.alpha[picks[:, :1]], np.pi))
    a, b = np.random.default_rng(seed), np.random.default_rng(seed)
    if three:
        got, source = drawn_3l(starts, sizes, 0.5, a, picks, table.rows, bev.lines, fp.lines, angles, fp.line_angles, cfg.solvers)
    else:
        got, source = drawn_2l(starts, sizes, 0.5, a, picks, table.rows, bev.lines, fp.lines, angles, fp.line_angles, 1.05,
                               cfg.solvers, "fixed" if mode == "fixed" else "prior")
    q, row = draw(starts, sizes, 0.5, b)
    i, j = picks[q], table.rows[row]
    n, d, m, e = bev.lines.normals[i], bev.lines.offsets[i], fp.lines.normals[j], fp.lines.offsets[j]
    if three:
        want, want_source = solve_3l(n, d, m, e, cfg.solvers, "free")
    elif mode == "fixed":
        want, want_source = two_lines_at_scales(n, d, m, e, np.ones(len(q)), cfg.solvers, check_scale=False)
    else:
        with np.errstate(all="ignore"):
            s = 1.05 + sample_scale_noise(len(q), 1.05, cfg.solvers, b)
            want, want_source = two_lines_at_scales(n, d, m, e, s, cfg.solvers, check_scale=True)
    assert len(got) > 20
    assert_same_bits(got, want)
    assert np.array_equal(source, want_source)
    assert a.random() == b.random()
