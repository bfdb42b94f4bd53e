"""Scoring: C = Cc - Cv ranks the true alignment above perturbed ones, Cv penalises
floorplan walls placed in observed free space, coarse-to-fine ranking and distinctness."""

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from zfloc_stream.settings.loading import ScoringSettings
from zfloc_stream.geometry.shapes import LineSet
from zfloc_stream.observation import BevObservation
from zfloc_stream.estimation.distinct_poses import distinct
from zfloc_stream.estimation.scoring import (
    BevView,
    floorplan_scorer,
    rank_coarse_to_fine,
    score_hypotheses,
    sparse_line_points,
    transform_points,
)
from zfloc_stream.geometry.sim2 import Sim2

# RES is re-exported for test files issue 25 still has importing it from here
from plan_helpers import RES, building, observe  # noqa: F401


@pytest.fixture(scope="module")
def world():
    fp = building()
    truth = Sim2(1.1, 0.7, (3.0, -2.0))
    obs = observe(fp, truth, centre=np.array([8.5, 3.0]), radius=5.0)
    return fp, truth, obs


def params(T: Sim2) -> np.ndarray:
    return np.array([T.t[0], T.t[1], T.theta, T.s])


def perturbed(T: Sim2, dx=0.0, dtheta=0.0, ds=1.0) -> Sim2:
    return Sim2(T.s * ds, T.theta + dtheta, (T.t[0] + dx, T.t[1]))


def test_transform_points_matches_sim2(world):
    _, truth, obs = world
    models = np.array([params(truth), params(Sim2(0.7, -2.0, (1, 2)))])
    out = transform_points(models, obs.wall_points[:50])
    assert np.allclose(out[0], truth.apply(obs.wall_points[:50]))
    assert np.allclose(out[1], Sim2(0.7, -2.0, (1, 2)).apply(obs.wall_points[:50]))


def test_true_transform_scores_highest(world):
    fp, truth, obs = world
    candidates = [truth] + [
        perturbed(truth, dx=0.3),
        perturbed(truth, dx=-0.5),
        perturbed(truth, dtheta=np.deg2rad(3)),
        perturbed(truth, dtheta=np.deg2rad(-8)),
        perturbed(truth, ds=1.05),
        perturbed(truth, ds=0.9),
    ]
    scores = score_hypotheses(fp, obs, np.array([params(T) for T in candidates]))
    assert scores.consistency[0] > 0.95 and scores.violation[0] < 0.02
    assert (scores.total[0] > scores.total[1:] + 0.05).all()
    assert np.allclose(scores.total, scores.consistency - scores.violation)


def test_violation_penalises_walls_in_free_space(world):
    fp, truth, obs = world
    # Shift the BEV 2 m along x: its free room now covers the interior wall at x = 5
    # while most BEV wall points still land near some floorplan wall (outer walls).
    shifted = perturbed(truth, dx=-3.9)
    s = score_hypotheses(fp, obs, np.array([params(truth), params(shifted)]))
    assert s.violation[0] < 0.02
    assert s.violation[1] > 0.2
    assert s.total[1] < s.consistency[1] - 0.2
    # With no observed free space there is nothing to violate: Cv = 0
    empty_free = BevObservation(obs.wall_points, obs.origin, obs.resolution, np.zeros_like(obs.free), np.zeros_like(obs.clearance))
    assert score_hypotheses(fp, empty_free, np.array([params(shifted)])).violation[0] == 0.0


def test_violation_ignores_shallow_free_space(world):
    """Floorplan walls inside free space but within tau_v of its border are not violations."""
    fp, truth, obs = world
    view = BevView.of(obs, ScoringSettings().tau_v)
    deep = view.state == 2
    assert deep.any() and (view.state[deep] > 0).all()
    rows, cols = np.nonzero(deep)
    # every deep cell is farther than tau_v from any non-free cell
    depth = distance_transform_edt(np.pad(obs.free, 1))[1:-1, 1:-1] * obs.resolution
    assert (depth[rows, cols] > ScoringSettings().tau_v).all()


def test_coarse_consistency_agrees_with_full(world):
    fp, truth, obs = world
    rng = np.random.default_rng(0)
    models = np.array([params(truth)] + [params(perturbed(truth, dx=rng.normal(0, 0.3), dtheta=rng.normal(0, 0.05))) for _ in range(30)])
    cfg = ScoringSettings()
    scorer = floorplan_scorer(fp, cfg)
    coarse = scorer.coarse_consistency(models, obs.wall_points, cfg.chunk_size)
    full = scorer.consistency(models, obs.wall_points, cfg.tau_c, cfg.chunk_size)
    # The coarse pass looks up the wall-surface field on the nearest cell, the full score
    # the floorplan's bilinear f^c (0 inside thick walls): equal at the truth, close and
    # strongly correlated elsewhere (they differ where a shift puts points inside walls).
    assert coarse[0] > 0.98 and full[0] > 0.98
    assert np.abs(coarse - full).max() < 0.25
    assert np.corrcoef(coarse, full)[0, 1] > 0.9
    # chunking does not change results
    small = cfg.model_copy(update={"chunk_size": 100})
    assert np.array_equal(scorer.coarse_consistency(models, obs.wall_points, small.chunk_size), coarse)


def test_coarse_to_fine_puts_truth_first(world):
    fp, truth, obs = world
    rng = np.random.default_rng(1)
    wrong = [Sim2(rng.uniform(0.6, 1.6), rng.uniform(-np.pi, np.pi), rng.uniform(-10, 10, 2)) for _ in range(2000)]
    near = [perturbed(truth, dx=0.05 * k) for k in range(1, 4)]  # near-duplicates of the truth
    models = np.array([params(T) for T in wrong + near + [truth]])
    lines = LineSet.from_endpoints(truth.inverse().apply(np.array([[0.7, 0.7], [12.3, 0.7], [12.3, 0.7], [12.3, 8.3]])).reshape(2, 2, 2))
    sparse = sparse_line_points(lines, 0.25)
    anchor = obs.wall_points.mean(axis=0)
    ranking = rank_coarse_to_fine(fp, obs, models, sparse, anchor, ScoringSettings(top_k=20))
    assert len(ranking.index) <= 20
    best = models[ranking.index[0]]
    assert np.abs(best[:2] - params(truth)[:2]).max() < 0.2
    assert np.all(np.diff(ranking.scores.total) <= 0)  # best first
    # the near-duplicates of the truth were merged into one entry
    kept = models[ranking.index]
    pos = transform_points(kept, anchor[None])[:, 0]
    close = np.linalg.norm(pos - truth.apply(anchor), axis=1) < ScoringSettings().distinct_translation
    assert close.sum() == 1


def test_distinct_suppresses_near_duplicates():
    cfg = ScoringSettings()
    anchor = np.array([1.0, 2.0])
    base = np.array([0.0, 0.0, 0.3, 1.0])
    models = np.array(
        [
            base,
            base + [0.1, 0.0, 0.0, 0.0],  # same pose
            base + [0.0, 0.0, np.deg2rad(3), 0.0],  # same pose (small turn about origin moves anchor < 0.5 m)
            base + [2.0, 0.0, 0.0, 0.0],  # different position
            base + [0.0, 0.0, np.pi, 0.0],  # same position of the anchor? no: rotated by pi
            base + [0.05, 0.0, np.deg2rad(30), 0.0],  # different heading
        ]
    )
    kept = distinct(models, anchor, cfg)
    assert kept.tolist() == [0, 3, 4, 5]
    assert distinct(models, anchor, cfg, limit=2).tolist() == [0, 3]
    assert distinct(np.zeros((0, 4)), anchor, cfg).size == 0


def test_sparse_line_points_spacing():
    lines = LineSet.from_endpoints([[[0, 0], [10, 0]], [[0, 0], [0, 0.1]]])
    pts = sparse_line_points(lines, 0.25)
    assert len(pts) == 41 + 2
    assert np.allclose(pts[0], [0, 0]) and np.allclose(pts[40], [10, 0])
    capped = sparse_line_points(lines, 0.25, max_points=20)
    assert len(capped) <= 22


def test_face_field_measures_to_surfaces_seen_from_inside(world):
    fp = world[0]
    field = floorplan_scorer(fp, ScoringSettings()).face_field
    pts = np.array(
        [
            [3.0, 0.7],  # inner surface of the bottom exterior wall (0.5 - 0.7)
            [3.0, 0.55],  # inside that wall, near its outer surface (nobody sees that one)
            [3.0, 1.7],  # 1 m into the room
            [5.0, 6.0],  # west surface of the interior wall (5.0 - 5.15): seen from the left room
            [5.15, 6.0],  # east surface: seen from the right room
        ]
    )
    rows, cols = fp.world_to_cell(pts)
    values = field.distance_field[np.clip(rows, 0, None), np.clip(cols, 0, None)]
    assert values[0] < 0.03 and values[3] < 0.03 and values[4] < 0.03
    assert values[1] > 0.05  # penalised, where the floorplan's f^c is 0 (inside the wall)
    assert fp.distance(pts[1:2])[0] == 0.0
    assert abs(values[2] - 1.0) < 0.04
