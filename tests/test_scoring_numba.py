"""estimator.kernels numba for the scores: NumbaScorer gives FloorplanScorer's coarse Cc, full
Cc and Cv bit for bit, on a synthetic building and on a real one, for hypotheses near and
far from the truth, in both Cv modes, and on the edge cases (no points, no models, points
off the grid, no free space). The ranking (rank_coarse_to_fine with kernels numba: a
partial sort and a compiled greedy suppression) picks the same hypotheses in the same
order as the numpy path, also with many ties and deep runs of near duplicates."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from test_scoring import building, observe  # synthetic floorplan + BEV helpers

from zfloc_stream.config import ScoringSettings
from zfloc_stream.errors import InputError
from zfloc_stream.estimation import ransac
from zfloc_stream.estimation.scoring import (BevView, _greedy_distinct, distinct, floorplan_scorer, rank_coarse_to_fine,
                                             scoring_kernels, sparse_line_points)
from zfloc_stream.estimation.scoring_numba import (NumbaScorer, _coarse_kernel, _greedy_distinct_kernel, descending_prefix,
                                                   top_distinct)
from zfloc_stream.ties import descending
from zfloc_stream.sim2 import Sim2, wrap_angle

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
ACES_LOG = Path(__file__).resolve().parents[2] / "shared" / "data" / "carmen" / "aces-corrected.log.gz"


def _models(rng, truth, n_near, n_far, extent):
    """truth, n_near perturbations of it, n_far anywhere over `extent` (x0, y0, x1, y1)
    widened by 10 m, at any heading and scale: many land partly or wholly off the grid."""
    tx, ty, theta, s = truth
    near = np.column_stack([tx + rng.normal(0, 0.3, n_near), ty + rng.normal(0, 0.3, n_near),
                            theta + rng.normal(0, 0.05, n_near), s * np.exp(rng.normal(0, 0.05, n_near))])
    x0, y0, x1, y1 = extent
    far = np.column_stack([rng.uniform(x0 - 10, x1 + 10, n_far), rng.uniform(y0 - 10, y1 + 10, n_far),
                           rng.uniform(-np.pi, np.pi, n_far), rng.uniform(0.4, 2.5, n_far)])
    return np.vstack([np.asarray(truth, dtype=float)[None], near, far])


def _assert_identical(fp, cfg, models, sparse, view):
    """Every score of NumbaScorer equals FloorplanScorer's exactly; returns the two Cv."""
    reference = floorplan_scorer(fp, cfg)
    compiled = NumbaScorer(reference)
    assert np.array_equal(compiled.coarse_consistency(models, sparse, cfg.chunk_size),
                          reference.coarse_consistency(models, sparse, cfg.chunk_size))
    assert np.array_equal(compiled.consistency(models, view.wall_points, cfg.tau_c, cfg.chunk_size),
                          reference.consistency(models, view.wall_points, cfg.tau_c, cfg.chunk_size))
    cv = {}
    for per in ("free", "observed"):
        cv[per] = reference.violation(models, view, cfg.tau_v, cfg.chunk_size, per)
        assert np.array_equal(compiled.violation(models, view, cfg.tau_v, cfg.chunk_size, per), cv[per])
    return cv


@pytest.fixture(scope="module")
def world():
    fp = building()
    obs = observe(fp, Sim2(1.1, 0.7, (3.0, -2.0)), centre=np.array([8.5, 3.0]), radius=5.0)
    cfg = ScoringSettings()
    view = BevView.of(obs, cfg.tau_v)
    sparse = sparse_line_points(obs.lines, cfg.sparse_spacing, cfg.max_sparse_points) if len(obs.lines) else obs.wall_points[::7]
    models = _models(np.random.default_rng(3), (3.0, -2.0, 0.7, 1.1), 1000, 3000, fp.extent)
    return fp, cfg, view, sparse, models


def test_synthetic_building_scores_are_identical(world):
    fp, cfg, view, sparse, models = world
    cv = _assert_identical(fp, cfg, models, sparse, view)
    assert not np.array_equal(cv["free"], cv["observed"])  # the two Cv modes are both exercised


def test_edge_cases_are_identical(world):
    fp, cfg, view, sparse, models = world
    # a single model; and one that maps every point far off the grid (the coarse grid's
    # border ring, f^c's "distance to the grid" term, no bucket under the footprint)
    for m in (models[:1], np.array([[500.0, -300.0, 0.3, 1.0]])):
        _assert_identical(fp, cfg, m, sparse, view)
    compiled = scoring_kernels(fp, cfg, "numba")
    assert isinstance(compiled, NumbaScorer)
    empty_points = np.zeros((0, 2))
    for out in (compiled.coarse_consistency(models[:5], empty_points, cfg.chunk_size),
                compiled.consistency(models[:5], empty_points, cfg.tau_c, cfg.chunk_size)):
        assert np.array_equal(out, np.zeros(5))
    no_models = np.zeros((0, 4))
    assert compiled.coarse_consistency(no_models, sparse, cfg.chunk_size).shape == (0,)
    assert compiled.consistency(no_models, view.wall_points, cfg.tau_c, cfg.chunk_size).shape == (0,)
    assert compiled.violation(no_models, view, cfg.tau_v, cfg.chunk_size).shape == (0,)
    # no observed free space: no footprint, Cv = 0
    blind = BevView(view.wall_points, np.zeros_like(view.state), view.origin_cells, view.resolution, np.zeros(2), 0.0)
    assert np.array_equal(compiled.violation(models[:5], blind, cfg.tau_v, cfg.chunk_size), np.zeros(5))
    # a non-finite mapped point: the same error as Floorplan.distance's
    bad = np.array([[np.nan, 0.0, 0.0, 1.0]])
    with pytest.raises(InputError):
        compiled.consistency(bad, view.wall_points, cfg.tau_c, cfg.chunk_size)
    with pytest.raises(InputError):
        floorplan_scorer(fp, cfg).consistency(bad, view.wall_points, cfg.tau_c, cfg.chunk_size)


def _assert_same_ranking(fp, view, models, sparse, anchor, cfg):
    a = rank_coarse_to_fine(fp, view, models, sparse, anchor, cfg, kernels="numpy")
    b = rank_coarse_to_fine(fp, view, models, sparse, anchor, cfg, kernels="numba")
    assert np.array_equal(a.index, b.index) and a.index.dtype == b.index.dtype
    assert np.array_equal(a.coarse, b.coarse)
    for field in ("total", "consistency", "violation"):
        assert np.array_equal(getattr(a.scores, field), getattr(b.scores, field))
    return a


def test_ranking_is_identical_through_the_dispatch(world):
    fp, cfg, view, sparse, models = world
    anchor = view.wall_points.mean(axis=0)
    _assert_same_ranking(fp, view, models, sparse, anchor, cfg)
    # many exact ties: every model three times, shuffled (equal coarse scores, equal
    # implied poses; the tie goes to the lower index on both paths)
    rng = np.random.default_rng(5)
    tied = np.repeat(models, 3, axis=0)[rng.permutation(3 * len(models))]
    _assert_same_ranking(fp, view, tied, sparse, anchor, cfg)
    # a deep run of near duplicates of the truth ahead of everything else: the first
    # 256 + ... ranked are one pose, so the numba path's prefix has to grow
    crowd = models[:1] + np.column_stack([rng.normal(0, 0.01, (3000, 2)), rng.normal(0, 0.002, 3000), np.zeros(3000)])
    deep = np.vstack([crowd, models])
    ranking = _assert_same_ranking(fp, view, deep, sparse, anchor, cfg.model_copy(update={"top_k": 20}))
    assert ranking.index.max() >= len(crowd)  # survivors from behind the crowd were reached
    # top_k larger than the number of distinct poses: the whole list is walked
    _assert_same_ranking(fp, view, models[:300], sparse, anchor, cfg.model_copy(update={"top_k": 5000}))
    # a single model, and none
    _assert_same_ranking(fp, view, models[:1], sparse, anchor, cfg)
    empty = rank_coarse_to_fine(fp, view, np.zeros((0, 4)), sparse, anchor, cfg, kernels="numba")
    assert empty.index.shape == (0,) and empty.index.dtype == np.int64 and empty.coarse.shape == (0,)


def test_descending_prefix_is_a_prefix_of_descending():
    """Exactly descending's first entries (at least the asked number), ties at 1e-9
    included: values quantised to a few levels, values equal up to last bits (tie_keys
    makes them ties), signed zeros, NaN, and lengths from 1 to past the end."""
    rng = np.random.default_rng(11)
    cases = [rng.integers(0, 7, 5000) / 7.0,  # seven levels: huge ties at every cut
             rng.random(5000),
             np.where(rng.random(5000) < 0.5, 0.3, 0.3 + 1e-13),  # equal at TIE_DECIMALS
             np.where(rng.random(5000) < 0.5, 0.0, -0.0),
             np.where(rng.random(5000) < 0.1, np.nan, rng.integers(0, 4, 5000) / 4.0),
             np.full(5000, np.nan),
             np.full(5000, 0.25)]
    for values in cases:
        full = descending(values)
        for length in (1, 2, 50, 256, 800, 4999, 5000, 6000):
            prefix = descending_prefix(values, length)
            assert len(prefix) >= min(length, len(values))
            assert np.array_equal(prefix, full[: len(prefix)])
    assert descending_prefix(np.zeros(0), 10).shape == (0,)


def test_greedy_distinct_kernel_matches_numpy():
    """The compiled suppression keeps the same hypotheses as _greedy_distinct, with
    positions on a grid of exactly max_distance apart (the test's boundary), headings
    across the +-pi wrap and differences at the angular limit."""
    rng = np.random.default_rng(2)
    turn = np.deg2rad(10.0)
    # the limit the heading difference turn - 0 lands on exactly (wrap_angle rounds)
    max_distance, max_angle = 0.5, float(abs(wrap_angle(turn)))
    for trial in range(40):
        n = int(rng.integers(1, 400))
        pos = rng.integers(-3, 4, (n, 2)) * (max_distance * rng.choice([0.5, 1.0]))
        pos = pos + rng.normal(0, 1e-12, pos.shape) * (trial % 2)
        ang = rng.choice([-np.pi, np.pi, 0.0, turn, -turn, 3.0, -3.0, np.pi - turn], n)
        ang = ang + rng.normal(0, 0.05, n) * (trial % 3 == 0)
        for limit in (1, 7, 50, n + 5):
            expect = _greedy_distinct(pos, ang, max_distance, max_angle, limit)
            kept = np.empty(limit, dtype=np.int64)
            count = _greedy_distinct_kernel(np.ascontiguousarray(pos[:, 0]), np.ascontiguousarray(pos[:, 1]), ang,
                                            max_distance, max_angle, limit, kept)
            assert np.array_equal(kept[:count], expect)


def test_top_distinct_matches_distinct():
    """top_distinct = order[distinct(models[order])] for random coarse scores with many
    ties and models in a few tight clusters (so the greedy pass has to go deep)."""
    rng = np.random.default_rng(4)
    cfg = ScoringSettings()
    anchor = np.array([0.7, -1.2])
    for n, levels, clusters in ((10, 3, 2), (1000, 5, 3), (5000, 50, 8), (20000, 2, 40), (3000, 1, 1)):
        centres = rng.normal(0, 5, (clusters, 4)) * [1, 1, 1, 0] + [0, 0, 0, 1]
        models = centres[rng.integers(0, clusters, n)] + rng.normal(0, 0.05, (n, 4)) * [1, 1, 0.1, 0.01]
        coarse = rng.integers(0, levels, n) / levels
        for top_k in (1, 50, 500):
            settings = cfg.model_copy(update={"top_k": top_k})
            order = descending(coarse)
            expect = order[distinct(models[order], anchor, settings, top_k)]
            got = top_distinct(models, coarse, anchor, settings)
            assert np.array_equal(got, expect) and got.dtype == expect.dtype
    assert top_distinct(np.zeros((0, 4)), np.zeros(0), anchor, cfg).shape == (0,)


def test_coarse_kernel_wide_index_is_identical(world):
    """The 64-bit cell index (grids of more than 2^32 cells) gives the 32-bit one's
    values, which are the numpy path's."""
    fp, cfg, view, sparse, models = world
    scorer = floorplan_scorer(fp, cfg)
    expect = scorer.coarse_consistency(models, sparse, cfg.chunk_size)
    h, w = scorer.shape
    px, py = (np.ascontiguousarray(sparse[:, k], dtype=np.float32) for k in (0, 1))
    for index_type in (np.uint32, np.uint64):
        out = np.zeros(len(models))
        _coarse_kernel(models, np.cos(models[:, 2]), np.sin(models[:, 2]), 1.0 / scorer.resolution,
                       float(scorer.origin[0]), float(scorer.origin[1]), px, py, scorer.coarse_field, h, w, index_type, out)
        assert np.array_equal(out, expect)


@pytest.mark.skipif(not ACES_LOG.is_file(), reason="shared real logs not available")
def test_real_building_scores_are_identical(monkeypatch):
    """The first round of the laser-aces case (benchmarks/profile_round.py): its own
    hypotheses, sparse points and BEV, plus hypotheses anywhere on the 120 x 130 m map."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from profile_round import build_case

    from zfloc_stream.localizer import Localizer

    fp, frames, settings = build_case("laser-aces")
    seen = []

    def capture(floorplan, view, models, sparse, anchor, cfg, kernels="numpy"):
        seen.append((models, sparse, view, cfg))
        return rank_coarse_to_fine(floorplan, view, models, sparse, anchor, cfg, kernels=kernels)

    monkeypatch.setattr(ransac, "rank_coarse_to_fine", capture)
    with Localizer(fp, settings) as loc:
        for frame in frames:
            loc.push(frame)
            if seen:
                break
    assert seen, "no localization round ran"
    models, sparse, view, cfg = seen[0]
    reference = floorplan_scorer(fp, cfg)
    coarse = reference.coarse_consistency(models, sparse, cfg.chunk_size)
    assert np.array_equal(NumbaScorer(reference).coarse_consistency(models, sparse, cfg.chunk_size), coarse)
    # every score on a share of the round's hypotheses (the numpy full scores take ~0.1 ms
    # per hypothesis here) and on more around its best one and anywhere
    extra = _models(np.random.default_rng(0), models[np.argmax(coarse)], 500, 1500, fp.extent)
    _assert_identical(fp, cfg, np.vstack([models[::20], extra]), sparse, view)
    # the round's whole ranking (the numba path sorts and poses only a prefix)
    _assert_same_ranking(fp, view, models, sparse, view.wall_points.mean(axis=0), cfg)
