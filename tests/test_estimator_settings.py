"""Boundary tests of the user-facing estimator.* settings that no other test names:
estimator.scoring.{violation_weight, wall_bucket_size} and
estimator.ransac.{guided_modes, guided_distance, guided_angle_deg}."""

import dataclasses

import numpy as np
import pytest

from plan_helpers import building, observe

from zfloc_stream.estimation import localize
from zfloc_stream.estimation.model_generation import _guided_candidates
from zfloc_stream.estimation.scoring import BevView, floorplan_scorer, score_hypotheses
from zfloc_stream.geometry.shapes import LineSet
from zfloc_stream.geometry.sim2 import Sim2
from zfloc_stream.primitives.extract import extract_lines
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.settings.loading import load_settings

TRUTH = Sim2(1.1, 0.7, (3.0, -2.0))
# two alignments near TRUTH: A lays the BEV's walls closer to the plan's (higher Cc) but puts
# some plan walls in observed free space (Cv > 0); B has a lower Cc and no violation
A = [3.213, -1.987, 0.7013, 1.1]
B = [3.213, -1.987, 0.7213, 1.1]
# (off-grid values: shifts of whole cells put BEV points exactly at tau_c from a wall, where
# the last bit of the angle decides Cc)


@pytest.fixture(scope="module")
def world():
    fp = building()
    return fp, observe(fp, TRUTH, centre=np.array([8.5, 3.0]), radius=5.0)


def scoring(*overrides: str):
    return load_settings(overrides=list(overrides)).estimator.scoring


# --- estimator.scoring -----------------------------------------------------------------
def test_violation_weight_decides_between_closer_walls_and_fewer_violations(world):
    """estimator.scoring.violation_weight: C = Cc - w Cv. A beats B on Cc, B beats A on Cv;
    the ranking turns at w* = (Cc_A - Cc_B) / (Cv_A - Cv_B): just under it A ranks first,
    just over it B does (and at 0 Cv is ignored)."""
    fp, obs = world
    plain = score_hypotheses(fp, obs, [A, B], scoring())
    (cc_a, cc_b), (cv_a, cv_b) = plain.consistency, plain.violation
    assert cc_a > cc_b and cv_a > cv_b == 0.0
    turn = float((cc_a - cc_b) / (cv_a - cv_b))
    assert 0.1 < turn < 1.0  # the default (1, the paper's C) ranks B first
    for w, best in ((0.0, 0), (turn - 1e-3, 0), (turn + 1e-3, 1), (1.0, 1)):
        s = score_hypotheses(fp, obs, [A, B], scoring(f"estimator.scoring.violation_weight={float(w)!r}"))
        assert np.array_equal(s.consistency, plain.consistency) and np.array_equal(s.violation, plain.violation)
        assert int(np.argmax(s.total)) == best, w


def test_wall_bucket_size_changes_the_buckets_not_the_violation(world):
    """estimator.scoring.wall_bucket_size only sorts the plan's wall points into square
    buckets for Cv's lookup (speed): a bucket wider than the walls' extent (12 m x 8 m) makes
    one bucket, just narrower two along x; Cv is the same, bit for bit, at every size."""
    fp, obs = world
    models = np.array([A, B, [3.013, -1.987, 0.7313, 1.1], [3.313, -1.987, 0.7013, 1.1], [4.013, -1.987, 0.7513, 1.1]])
    walls = fp.sample_wall_points()
    extent = float(np.ptp(walls, axis=0).max())  # the x extent (the plan is wider than tall)
    shapes, violations = {}, {}
    for size in (0.1, 2.0, extent - 0.01, extent + 0.01):
        s = scoring(f"estimator.scoring.wall_bucket_size={size!r}")
        shapes[size] = floorplan_scorer(fp, s).bucket_shape
        violations[size] = score_hypotheses(fp, obs, models, s).violation
    assert shapes[extent + 0.01] == (1, 1) and shapes[extent - 0.01][1] == 2
    assert shapes[0.1][0] * shapes[0.1][1] > shapes[2.0][0] * shapes[2.0][1]
    assert violations[2.0].max() > 0
    for v in violations.values():
        assert np.array_equal(v, violations[2.0])


# --- estimator.ransac: guided sampling around live modes ------------------------------
def guided_cfg(*overrides: str):
    return load_settings(overrides=list(overrides)).estimator.ransac


def test_guided_distance_is_how_far_a_segment_may_lie_from_a_plan_line():
    """estimator.ransac.guided_distance=0.3: a BEV segment parallel to a plan line 0.3 m
    away (plus a hair) does not match it; 0.3 m less a hair does."""
    plan = LineSet.from_endpoints([[[0.0, 0.0], [4.0, 0.0]]])
    cfg = guided_cfg("estimator.ransac.guided_distance=0.3")
    for offset, matches in ((0.3 - 1e-6, True), (0.3 + 1e-6, False)):
        bev = LineSet.from_endpoints([[[1.0, offset], [2.0, offset]]])
        starts, cols = _guided_candidates(bev, plan, Sim2.identity(), cfg)
        assert bool(starts[1] - starts[0] == 1) is matches and (cols.tolist() == [0]) is matches, offset


def test_guided_angle_deg_is_how_far_a_segment_may_turn_from_a_plan_line():
    """estimator.ransac.guided_angle_deg=5: a 1 m BEV segment centred on a plan line and
    turned 4.9 deg from it matches it, turned 5.1 deg does not (its ends stay within
    guided_distance either way)."""
    plan = LineSet.from_endpoints([[[0.0, 0.0], [4.0, 0.0]]])
    cfg = guided_cfg("estimator.ransac.guided_angle_deg=5")
    for turn, matches in ((4.9, True), (5.1, False)):
        d = 0.5 * np.array([np.cos(np.radians(turn)), np.sin(np.radians(turn))])
        bev = LineSet.from_endpoints([[[2.0, 0.0] - d, [2.0, 0.0] + d]])
        _, cols = _guided_candidates(bev, plan, Sim2.identity(), cfg)
        assert (cols.tolist() == [0]) is matches, turn


def test_guided_modes_is_how_many_live_modes_are_sampled_around():
    """estimator.ransac.guided_modes: of the warm starts [far, near] (far: 100 m off the
    plan, where no BEV line meets a plan line; near: the true alignment), guided samples come
    only from the first guided_modes of them. 1 samples around `far` alone (no guided models),
    2 reaches `near` too; 0 samples none."""
    settings = load_settings(overrides=["estimator.scale_mode=fixed", "estimator.correlative.enabled=false"])
    fp = building()
    truth = Sim2(1.0, 2.1, (-4.0, 7.0))
    centre = np.array([8.5, 3.0])
    obs = observe(fp, truth, centre, 6.0)
    obs = dataclasses.replace(obs, lines=extract_lines(obs.wall_points, settings.primitives.lines, make_rng(0, "lines")))
    far = Sim2(truth.s, truth.theta, (truth.t[0] + 100.0, truth.t[1]))
    n_models = {}
    for modes in (0, 1, 2):
        est = settings.estimator.model_copy(update={"ransac": settings.estimator.ransac.model_copy(update={"guided_modes": modes})})
        result = localize(fp, obs, est, make_rng(6, "t"), warm_start=[far, truth], iterations=0)
        n_models[modes] = result.n_models
    assert n_models[0] == 2 and n_models[1] == 2  # the two warm starts alone
    assert n_models[2] > 2  # guided models around `near` (estimator.ransac.guided_modes=2)
