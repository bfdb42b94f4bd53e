"""Boundary tests of the prior.* settings (prior.py): for each, the smallest input on each
side of the value where the gate, the seed grid or PriorWatch's verdict changes.

The prior used throughout: a pose at the floorplan origin, heading 0, sigma_xy 1 m,
sigma_theta 15 deg, bound to a frame whose plane pose is the identity, so a model row
(tx, ty, theta, 1) implies the frame's floorplan pose (tx, ty, theta) directly.
"""

import math

import numpy as np
import pytest

from zfloc_stream.estimation.results import Hypothesis
from zfloc_stream.geometry.sim2 import Sim2
from zfloc_stream.prior import ACTIVE, CONTRADICTED, RELEASED, SAME_PLACE, Prior, PriorWatch
from zfloc_stream.settings.loading import load_settings

SIGMA_THETA = math.radians(15.0)


def prior_settings(*overrides: str):
    return load_settings(overrides=list(overrides)).prior


def bound(*overrides: str):
    return Prior.at(0.0, 0.0, 0.0, 1.0, SIGMA_THETA).bind((0.0, 0.0, 0.0), prior_settings(*overrides))


def test_gate_sigmas_is_the_gate_radius_in_position_and_heading():
    """prior.gate_sigmas=2: a pose 2 sigma off (plus a hair) is outside, just under is inside,
    in position (sigma_xy 1 m) and in heading (sigma_theta 15 deg) alike."""
    gate = bound("prior.gate_sigmas=2")
    eps = 1e-6
    rows = np.array([[2 - eps, 0, 0, 1], [2 + eps, 0, 0, 1],
                     [0, 0, 2 * SIGMA_THETA - eps, 1], [0, 0, 2 * SIGMA_THETA + eps, 1]])
    assert gate.inside(rows).tolist() == [True, False, True, False]
    # the same rows under a slightly wider gate are all inside
    assert bound("prior.gate_sigmas=2.01").inside(rows).all()


def _positions(seeds):
    return {tuple(np.round(xy, 9)) for xy in seeds[:, :2]}


def test_seed_step_is_the_seed_grids_spacing():
    """prior.seed_step against the gate radius (2.5 sigma x 1 m = 2.5 m): a step just under
    the radius puts the centre and its four neighbours on the disc, just over only the centre."""
    under = bound("prior.seed_step=2.49").seeds(1.0)
    over = bound("prior.seed_step=2.51").seeds(1.0)
    assert _positions(under) == {(0.0, 0.0), (2.49, 0.0), (-2.49, 0.0), (0.0, 2.49), (0.0, -2.49)}
    assert _positions(over) == {(0.0, 0.0)}
    assert bound("prior.gate_sigmas=2.5").inside(under).all()


def test_seed_angle_step_deg_is_the_seed_headings_spacing():
    """prior.seed_angle_step_deg against the heading half-gate (2.5 x 15 = 37.5 deg): a step
    just under it gives three headings (-step, 0, +step), just over only the prior's."""
    under = bound("prior.seed_angle_step_deg=37.4").seeds(1.0)
    over = bound("prior.seed_angle_step_deg=37.6").seeds(1.0)
    assert np.allclose(sorted(set(np.round(np.degrees(under[:, 2]), 9))), [-37.4, 0.0, 37.4])
    assert set(np.round(over[:, 2], 12)) == {0.0}
    assert len(under) == 3 * len(over)


def test_max_seeds_coarsens_the_grid_only_beyond_the_estimate():
    """prior.max_seeds: the grid's estimated size (pi (r / step + 1)^2 (2 half_turn / angle_step
    + 1)) at or under max_seeds is laid as asked; one seed fewer allowed coarsens both grids;
    0 adds no seeds at all."""
    radius, half_turn = 2.5, 2.5 * SIGMA_THETA
    count = math.pi * (radius / 0.25 + 1) ** 2 * (2 * half_turn / math.radians(5.0) + 1)
    fits = bound(f"prior.max_seeds={math.ceil(count)}").seeds(1.0)
    coarse = bound(f"prior.max_seeds={math.floor(count)}").seeds(1.0)
    assert len(fits) == len(bound().seeds(1.0))  # the default (100 000) is far above count
    assert len(coarse) < len(fits)
    assert np.diff(sorted(set(np.round(fits[:, 0], 9))))[0] == pytest.approx(0.25)
    assert np.diff(sorted(set(np.round(coarse[:, 0], 9))))[0] > 0.25
    assert len(bound("prior.max_seeds=0").seeds(1.0)) == 0
    assert len(bound("prior.max_seeds=1").seeds(1.0)) >= 1


# --- PriorWatch: contradiction, doubt and release -------------------------------------
INSIDE, OUTSIDE = Sim2(1.0, 0.0, (0.0, 0.0)), Sim2(1.0, 0.0, (30.0, 0.0))


def watch(*overrides: str) -> PriorWatch:
    s = prior_settings(*overrides)
    w = PriorWatch(Prior.at(0.0, 0.0, 0.0, 1.0, SIGMA_THETA), s, confirm_rounds=s.confirm_rounds)
    w.bind(0, (0.0, 0.0, 0.0))
    assert w.state == ACTIVE
    return w


def round_of(score_in: float, score_out: float) -> list[Hypothesis]:
    return [Hypothesis(INSIDE, score_in, score_in, 0.0, "3L"), Hypothesis(OUTSIDE, score_out, score_out, 0.0, "3L")]


def test_contradiction_gap_is_how_far_the_best_outside_may_lead():
    """prior.contradiction_gap=0.3: a round whose best outside leads the best inside by just
    over 0.3 contradicts the prior (at contradiction_rounds 1); by just under it keeps it and
    prunes the outside hypothesis."""
    over = watch("prior.contradiction_gap=0.3", "prior.contradiction_rounds=1").weigh(round_of(0.5, 0.5 + 0.3 + 1e-6))
    assert over.contradicted
    under_watch = watch("prior.contradiction_gap=0.3", "prior.contradiction_rounds=1")
    under = under_watch.weigh(round_of(0.5, 0.5 + 0.3 - 1e-6))
    assert not under.contradicted and under_watch.state == ACTIVE
    assert [h.alignment for h in under.hypotheses] == [INSIDE]


def test_contradiction_gap_is_also_the_lead_that_releases_the_prior():
    """prior.contradiction_gap=0.3: a tracked mode inside is released only when the round's
    best inside leads every outside hypothesis by more than 0.3."""
    for lead, released in ((0.3 + 1e-6, True), (0.3 - 1e-6, False)):
        w = watch("prior.contradiction_gap=0.3", "prior.release_rounds=1")
        w.weigh(round_of(0.5 + lead, 0.5))
        w.after_round(INSIDE, tracked_rounds=1)
        assert (w.state == RELEASED) is released, lead


def test_doubt_gap_withholds_tracking_beyond_it():
    """prior.doubt_gap=0.1: the prior is doubted when the latest round's best outside leads
    the best inside by just over 0.1, not by just under (the prior holds either way)."""
    for lead, doubted in ((0.1 + 1e-6, True), (0.1 - 1e-6, False)):
        w = watch("prior.doubt_gap=0.1")
        w.weigh(round_of(0.5, 0.5 + lead))
        assert w.state == ACTIVE and bool(w.doubted) is doubted, lead


def test_contradiction_rounds_counts_contradicting_rounds_in_a_row():
    """prior.contradiction_rounds=3: two contradicting rounds keep the prior, the third drops
    it; an agreeing round in between starts the count over."""
    w = watch("prior.contradiction_rounds=3")
    for _ in range(2):
        assert not w.weigh(round_of(0.0, 1.0)).contradicted
    assert w.state == ACTIVE
    assert w.weigh(round_of(0.0, 1.0)).contradicted and w.state == CONTRADICTED

    w = watch("prior.contradiction_rounds=3")
    w.weigh(round_of(0.0, 1.0))
    w.weigh(round_of(0.0, 1.0))
    w.weigh(round_of(1.0, 0.0))  # agrees: the count starts over
    w.weigh(round_of(0.0, 1.0))
    w.weigh(round_of(0.0, 1.0))
    assert w.state == ACTIVE


def test_release_rounds_is_how_long_a_mode_inside_is_tracked_before_release():
    """prior.release_rounds=4: a mode inside tracked 3 rounds keeps the prior, 4 rounds
    releases it (the round's best inside leading clearly)."""
    for tracked, released in ((3, False), (4, True)):
        w = watch("prior.release_rounds=4")
        w.weigh(round_of(1.0, 0.0))
        w.after_round(INSIDE, tracked_rounds=tracked)
        assert (w.state == RELEASED) is released, tracked


def test_contradicting_rounds_count_only_while_they_name_one_place():
    """SAME_PLACE: at the default contradiction_rounds (2), a second contradicting round
    whose leading place outside implies a frame position SAME_PLACE (plus a hair) from the
    first round's starts the count over; just within it, the prior is dropped."""
    def second(shift: float) -> PriorWatch:
        w = watch()
        assert not w.weigh(round_of(0.0, 1.0)).contradicted and w.against == 1
        moved = Sim2(1.0, 0.0, (30.0, shift))
        w.weigh([Hypothesis(INSIDE, 0.0, 0.0, 0.0, "3L"), Hypothesis(moved, 1.0, 1.0, 0.0, "3L")])
        return w

    assert second(SAME_PLACE - 1e-6).state == CONTRADICTED
    apart = second(SAME_PLACE + 1e-6)
    assert apart.state == ACTIVE and apart.against == 1 and apart.doubted
