"""estimator.kernels numba for the scores: NumbaScorer gives FloorplanScorer's coarse Cc, full
Cc and Cv bit for bit, on a synthetic building and on a real one, for hypotheses near and
far from the truth, in both Cv modes, and on the edge cases (no points, no models, points
off the grid, no free space)."""

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("numba")

from test_scoring import building, observe  # synthetic floorplan + BEV helpers

from zfloc_stream.config import ScoringSettings
from zfloc_stream.errors import InputError
from zfloc_stream.estimation import ransac
from zfloc_stream.estimation.scoring import BevView, floorplan_scorer, rank_coarse_to_fine, scoring_kernels, sparse_line_points
from zfloc_stream.estimation.scoring_numba import NumbaScorer
from zfloc_stream.sim2 import Sim2

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


def test_ranking_is_identical_through_the_dispatch(world):
    fp, cfg, view, sparse, models = world
    anchor = view.wall_points.mean(axis=0)
    a = rank_coarse_to_fine(fp, view, models, sparse, anchor, cfg, kernels="numpy")
    b = rank_coarse_to_fine(fp, view, models, sparse, anchor, cfg, kernels="numba")
    assert np.array_equal(a.index, b.index) and np.array_equal(a.coarse, b.coarse)
    for field in ("total", "consistency", "violation"):
        assert np.array_equal(getattr(a.scores, field), getattr(b.scores, field))


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
