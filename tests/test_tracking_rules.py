"""Every tracker setting at its boundary: just below and just above the value where the
decision it governs flips. The policy's rules (tracking_policy.py) are tested as pure
functions; the filter bank's numbers (gate, noises, weights, pruning, merging) through
HypothesisTracker, with the expected value computed here the way the tracker defines it."""

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import pytest

from zfloc_stream.tracking import policy
from zfloc_stream.settings.loading import TrackingSettings
from zfloc_stream.geometry.sim2 import Sim2
from zfloc_stream.tracking.filter_bank import HypothesisTracker, anchored_state

S = TrackingSettings()


def below(x: float) -> float:
    return float(np.nextafter(x, -np.inf))


def above(x: float) -> float:
    return float(np.nextafter(x, np.inf))


def mode(id=0, weight=0.5, running_score=0.5, hits=1, collapses=0, near_top=False):
    return SimpleNamespace(id=id, weight=weight, running_score=running_score, hits=hits, collapses=collapses, near_top=near_top)


# --- the policy's rules --------------------------------------------------------------------
def test_birth_score_gap():
    s = S.model_copy(update={"birth_score_gap": 0.25})
    assert policy.birth_rule(0, -5.0, 0.5, s) == policy.PolicyRule.BEST_STARTS_A_MODE  # the best always
    assert policy.birth_rule(1, 0.25, 0.5, s) == policy.PolicyRule.BIRTH_GAP
    assert policy.birth_rule(1, below(0.25), 0.5, s) is None


def test_revisit_score_gap():
    s = S.model_copy(update={"revisit_score_gap": 0.25})
    assert policy.revisit_rule(0.25, 0.5, s) == policy.PolicyRule.REVISIT
    assert policy.revisit_rule(below(0.25), 0.5, s) is None


def test_confirm_score_gap():
    s = S.model_copy(update={"confirm_score_gap": 0.25})
    assert policy.near_top(0.25, 0.5, s) and not policy.near_top(below(0.25), 0.5, s)


def test_lost_score_gap():
    assert policy.collapse_rule(1, 0.25, 0.5, True, S.model_copy(update={"lost_score_gap": 0.25})) is None
    assert policy.collapse_rule(1, 0.25, 0.5, True, S.model_copy(update={"lost_score_gap": below(0.25)})) == policy.PolicyRule.BEATEN_BY_RIVAL
    # the round's best itself never collapses; an unmatched mode does when the round found anything
    assert policy.collapse_rule(0, -9.0, 0.5, True, S) is None
    assert policy.collapse_rule(None, 0.0, 0.0, True, S) == policy.PolicyRule.UNSEEN_COLLAPSES
    assert policy.collapse_rule(None, 0.0, 0.0, False, S) is None


@pytest.mark.parametrize("n", [1, 2, 5])
def test_confirm_rounds(n):
    s = S.model_copy(update={"confirm_rounds": n, "confirm_rounds_after_loss": 1})
    assert policy.is_confirmed(mode(hits=n), s) and not policy.is_confirmed(mode(hits=n - 1), s)
    assert policy.rounds_to_track(False, s) == n and policy.rounds_to_track(True, s) == n


@pytest.mark.parametrize("n", [2, 3, 6])
def test_confirm_rounds_after_loss(n):
    s = S.model_copy(update={"confirm_rounds": 2, "confirm_rounds_after_loss": n})
    assert policy.rounds_to_track(True, s) == n and policy.rounds_to_track(False, s) == 2
    leader = mode(weight=0.95, hits=n)
    assert policy.round_status_rule(leader, [leader], None, True, s) == policy.PolicyRule.TRACKING
    leader.hits = n - 1
    assert policy.round_status_rule(leader, [leader], None, True, s) == policy.PolicyRule.WAITING_FOR_CONFIRMATION


def test_ambiguity_ratio():
    leader, rival = mode(0, weight=0.5, hits=5), mode(1, weight=0.25, hits=5)
    assert policy.has_close_rival(leader, [leader, rival], S.model_copy(update={"ambiguity_ratio": 0.5}))
    assert not policy.has_close_rival(leader, [leader, rival], S.model_copy(update={"ambiguity_ratio": above(0.5)}))
    unconfirmed = mode(1, weight=0.5, hits=1)  # only a confirmed rival makes the leader ambiguous
    assert not policy.has_close_rival(leader, [leader, unconfirmed], S)


def test_dominance_weight():
    leader = mode(weight=0.9, hits=5)
    assert not policy.dominates(leader, S.model_copy(update={"dominance_weight": 0.9}))
    assert policy.dominates(leader, S.model_copy(update={"dominance_weight": below(0.9)}))
    s = S.model_copy(update={"dominance_weight": 0.9})
    assert policy.round_status_rule(leader, [leader], None, False, s) == policy.PolicyRule.THIN_EVIDENCE


def test_a_mode_not_yet_tracked_must_be_singled_out_by_the_round():
    leader, rival = mode(0, weight=0.95, hits=5), mode(1, weight=0.05, near_top=True)
    assert policy.round_status_rule(leader, [leader, rival], None, False, S) == policy.PolicyRule.THIN_EVIDENCE
    assert policy.round_status_rule(leader, [leader, rival], 0, False, S) == policy.PolicyRule.TRACKING  # already tracked
    rival.near_top = False
    assert policy.round_status_rule(leader, [leader, rival], None, False, S) == policy.PolicyRule.TRACKING


@pytest.mark.parametrize("n", [1, 3, 4])
def test_lost_rounds(n):
    s = S.model_copy(update={"lost_rounds": n})
    tracked = mode(collapses=n)
    assert policy.loss_rule(tracked, tracked, s) == policy.PolicyRule.COLLAPSED
    tracked.collapses = n - 1
    assert policy.loss_rule(tracked, tracked, s) is None
    assert policy.loss_rule(tracked, mode(1), s) == policy.PolicyRule.OVERTAKEN
    assert policy.loss_rule(None, None, s) == policy.PolicyRule.PRUNED


@pytest.mark.parametrize("n", [1, 3, 5])
def test_rival_established_rounds(n):
    s = S.model_copy(update={"rival_established_rounds": n, "confirm_rounds": 1})
    tracked, rival = mode(0, weight=0.3, hits=9), mode(1, weight=0.7, hits=n)
    assert policy.reported_mode([tracked, rival], tracked, s) == (rival, policy.PolicyRule.OVERTAKEN)
    rival.hits = n - 1
    assert policy.reported_mode([tracked, rival], tracked, s) == (tracked, policy.PolicyRule.TRACKED_KEEPS_ITS_PLACE)


def test_newcomer_score_gap():
    confirmed, newcomer = mode(0, weight=0.3, running_score=0.25, hits=5), mode(1, weight=0.7, running_score=0.5, hits=1)
    s = S.model_copy(update={"newcomer_score_gap": 0.25})
    assert policy.reported_mode([confirmed, newcomer], None, s) == (confirmed, None)
    s = S.model_copy(update={"newcomer_score_gap": below(0.25)})
    assert policy.reported_mode([confirmed, newcomer], None, s) == (newcomer, policy.PolicyRule.NEWCOMER)


def test_pose_jump_chi2():
    s = S.model_copy(update={"pose_jump_chi2": 10.0})
    assert not policy.pose_jumped(10.0, s) and policy.pose_jumped(above(10.0), s)


# --- the filter bank -----------------------------------------------------------------------
@dataclass
class Hyp:
    alignment: Sim2
    score: float


SENSOR_A, SENSOR_B = np.array([5.0, 2.0]), np.array([8.0, 6.0])
BASE = Sim2(1.0, 0.3, (1.0, -2.0))
NOISES = ["process_translation_std_per_frame", "process_angle_deg_per_frame", "process_log_scale_per_frame",
          "process_translation_std_per_m", "process_angle_deg_per_m", "process_log_scale_per_m",
          "measurement_translation_std", "measurement_angle_deg", "measurement_log_scale"]
NO_MERGE = {"merge_translation": 0.0, "merge_angle_deg": 0.0, "merge_log_scale": 0.0}


def shifted(alignment: Sim2, sensor, dq=(0.0, 0.0), dtheta=0.0, dlog_s=0.0) -> Sim2:
    """The alignment whose anchored state about `sensor` differs by (dq, dtheta, dlog_s)."""
    s, theta = alignment.s * np.exp(dlog_s), alignment.theta + dtheta
    q = alignment.apply(sensor) + np.asarray(dq)
    return Sim2(s, theta, q - s * Sim2(1.0, theta).R @ sensor)


def gate_distance(settings: TrackingSettings, z_new: Sim2) -> float:
    """Mahalanobis^2 of a round-2 hypothesis (at SENSOR_B, 3 frames later) to the mode born
    from BASE at SENSOR_A in round 1: the tracker's prediction, written out."""
    s = settings
    meas = np.diag([s.measurement_translation_std**2] * 2 + [np.deg2rad(s.measurement_angle_deg) ** 2, s.measurement_log_scale**2])
    x = anchored_state(BASE, SENSOR_A)
    offset = SENSOR_B - SENSOR_A
    scaled_r = np.exp(x[3]) * Sim2(1.0, x[2]).R
    jac = np.eye(4)
    jac[:2, 2] = scaled_r @ np.array([-offset[1], offset[0]])
    jac[:2, 3] = scaled_r @ offset
    frames, metres = 3, float(np.linalg.norm(offset))
    q = np.diag([frames * s.process_translation_std_per_frame**2 + metres * s.process_translation_std_per_m**2] * 2
                + [frames * np.deg2rad(s.process_angle_deg_per_frame) ** 2 + metres * np.deg2rad(s.process_angle_deg_per_m) ** 2,
                   frames * s.process_log_scale_per_frame**2 + metres * s.process_log_scale_per_m**2])
    x_pred = x.copy()
    x_pred[:2] += scaled_r @ offset
    y = anchored_state(z_new, SENSOR_B) - x_pred
    return float(y @ np.linalg.solve(jac @ meas @ jac.T + q + meas, y))


def modes_after_second_round(settings: TrackingSettings, z_new: Sim2) -> int:
    """1: the round-2 hypothesis gated with the mode (matched); 2: it started its own."""
    tracker = HypothesisTracker(settings)
    tracker.update([Hyp(BASE, 0.5)], SENSOR_A, frame=0)
    tracker.update([Hyp(z_new, 0.5)], SENSOR_B, frame=3)
    return len(tracker.modes)


OFF = shifted(BASE, SENSOR_B, dq=(0.9, -0.4), dtheta=0.03, dlog_s=0.02)  # a hypothesis near the gate's edge
# for each noise, a hypothesis off in the component it widens (beyond the default gate)
OFF_IN = {"translation": shifted(BASE, SENSOR_B, dq=(1.5, 0.0)), "angle": shifted(BASE, SENSOR_B, dtheta=0.3),
          "log_scale": shifted(BASE, SENSOR_B, dlog_s=0.2)}


def test_the_written_out_gate_distance_is_the_trackers():
    s = S.model_copy(update=NO_MERGE)
    d2 = gate_distance(s, OFF)
    assert modes_after_second_round(s.model_copy(update={"gate_chi2": d2 * (1 + 1e-9)}), OFF) == 1
    assert modes_after_second_round(s.model_copy(update={"gate_chi2": d2 * (1 - 1e-9)}), OFF) == 2


@pytest.mark.parametrize("name", NOISES)
def test_each_noise_at_the_value_that_puts_the_hypothesis_on_the_gate(name):
    """Every noise widens the gate: find (bisection) the value at which a hypothesis off in
    that component sits exactly on gate_chi2; just below it starts a mode, just above it is
    matched."""
    base = S.model_copy(update=NO_MERGE)
    off = OFF_IN[next(k for k in OFF_IN if k in name)]
    lo, hi = (1e-4 if name.startswith("measurement") else 0.0), 50.0 * max(getattr(base, name), 1e-3)
    value = lambda v: base.model_copy(update={name: v})  # noqa: E731
    assert gate_distance(value(lo), off) > base.gate_chi2 > gate_distance(value(hi), off)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if gate_distance(value(mid), off) > base.gate_chi2 else (lo, mid)
    assert modes_after_second_round(value(lo * (1 - 1e-6)), off) == 2
    assert modes_after_second_round(value(hi * (1 + 1e-6)), off) == 1


def two_modes_then_one_unseen(settings: TrackingSettings) -> tuple[HypothesisTracker, float]:
    """Round 1: A (score 0.6) and B (0.5), far apart; round 2: only A, fresh 0.7. Returns the
    tracker and B's expected weight after round 2, computed as the tracker defines it."""
    s = settings
    far = Sim2(1.0, 2.0, (40.0, -30.0))
    tracker = HypothesisTracker(s)
    tracker.update([Hyp(BASE, 0.6), Hyp(far, 0.5)], SENSOR_A, frame=0)
    tracker.update([Hyp(BASE, 0.7)], SENSOR_A, frame=5)
    running_a = (1.0 - s.score_smoothing) * 0.6 + s.score_smoothing * 0.7
    running_b = (1.0 - s.score_smoothing) * 0.5 + s.score_smoothing * (0.5 - s.unobserved_penalty)
    logits = s.weight_gain * np.array([running_a, running_b])
    w = np.exp(logits - logits.max())
    w /= w.sum()
    return tracker, float(w[1])


def test_prune_weight():
    _, w_b = two_modes_then_one_unseen(S)
    assert len(two_modes_then_one_unseen(S.model_copy(update={"prune_weight": w_b}))[0].modes) == 2
    assert len(two_modes_then_one_unseen(S.model_copy(update={"prune_weight": above(w_b)}))[0].modes) == 1


@pytest.mark.parametrize("name", ["score_smoothing", "unobserved_penalty", "weight_gain"])
def test_each_weight_setting_at_the_value_that_prunes_the_unseen_mode(name):
    """B's weight falls with each of these; at prune_weight 0.01 find (bisection) the value
    where it equals prune_weight: just below B stays, just above it is pruned."""
    base = S.model_copy(update={"prune_weight": 0.01})
    value = lambda v: base.model_copy(update={name: v})  # noqa: E731
    lo, hi = 1e-3, {"score_smoothing": 1.0, "unobserved_penalty": 10.0, "weight_gain": 1000.0}[name]
    assert two_modes_then_one_unseen(value(lo))[1] > 0.01 > two_modes_then_one_unseen(value(hi))[1]
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if two_modes_then_one_unseen(value(mid))[1] > 0.01 else (lo, mid)
    assert len(two_modes_then_one_unseen(value(lo * (1 - 1e-6)))[0].modes) == 2
    assert len(two_modes_then_one_unseen(value(min(hi * (1 + 1e-6), hi + 1e-9)))[0].modes) == 1


@pytest.mark.parametrize("n", [1, 2, 4])
def test_max_modes(n):
    """n + 1 hypotheses far apart, all within birth_score_gap: max_modes of them stay."""
    hyps = [Hyp(Sim2(1.0, 0.5 * k, (30.0 * k, 0.0)), 0.5 - 0.01 * k) for k in range(n + 1)]
    for limit, kept in ((n + 1, n + 1), (n, n)):
        tracker = HypothesisTracker(S.model_copy(update={"max_modes": limit}))
        tracker.update(hyps, SENSOR_A, frame=0)
        assert len(tracker.modes) == kept


def test_max_modes_never_drops_the_tracked_mode():
    """A round of max_modes far newborns, each scoring above the tracked mode: the lightest
    newborn leaves the full bank, the tracked mode stays (its own rules decide when it goes)."""
    s = S.model_copy(update={"max_modes": 3})
    tracker = HypothesisTracker(s)
    for r in range(3):
        tracker.update([Hyp(BASE, 0.5)], SENSOR_A, frame=5 * r)
    assert tracker.status == "tracking"
    tracked = tracker.tracked_mode.id
    rivals = [Hyp(Sim2(1.0, 0.5 * k, (30.0 * k, 0.0)), 0.6 - 0.01 * k) for k in (1, 2, 3)]
    tracker.update(rivals + [Hyp(BASE, 0.45)], SENSOR_A, frame=15)
    assert len(tracker.modes) == 3 and tracked in [m.id for m in tracker.modes]
    assert tracker.tracked_mode is not None and tracker.tracked_mode.id == tracked


@pytest.mark.parametrize("n", [1, 3, 4])
def test_lost_rounds_drop_a_rival_that_fell_behind(n):
    """FELL_BEHIND (policy.fell_behind): a mode neither tracked nor confirmed leaves the bank
    at lost_rounds collapses in a row, not one before; the tracked mode never (COLLAPSED
    decides), nor a confirmed one (confirm_rounds hits)."""
    s = S.model_copy(update={"lost_rounds": n})
    assert policy.fell_behind(mode(collapses=n, hits=S.confirm_rounds - 1), False, s)
    assert not policy.fell_behind(mode(collapses=n - 1, hits=S.confirm_rounds - 1), False, s)
    assert not policy.fell_behind(mode(collapses=n, hits=S.confirm_rounds - 1), True, s)
    assert not policy.fell_behind(mode(collapses=n, hits=S.confirm_rounds), False, s)


@pytest.mark.parametrize("gap, leaves", [(0.25, False), (below(0.25), True)])
def test_a_rival_beaten_by_more_than_lost_score_gap_leaves_the_bank_after_lost_rounds_rounds(gap, leaves):
    """Two modes born in one round; then every round scores the rival 0.25 below the leader.
    With lost_score_gap just below 0.25 each round is a collapse, and the rival leaves after
    lost_rounds of them (its weight alone would keep it); at 0.25 it stays."""
    s = S.model_copy(update={"lost_score_gap": gap})
    rival = Sim2(1.0, 0.5, (30.0, 0.0))
    tracker = HypothesisTracker(s)
    tracker.update([Hyp(BASE, 0.5), Hyp(rival, 0.45)], SENSOR_A, frame=0)
    assert len(tracker.modes) == 2
    for r in range(1, s.lost_rounds + 1):
        assert len(tracker.modes) == 2  # not before lost_rounds collapses
        tracker.update([Hyp(BASE, 0.5), Hyp(rival, 0.25)], SENSOR_A, frame=5 * r)
        assert min(m.weight for m in tracker.modes) >= s.prune_weight
    assert len(tracker.modes) == (1 if leaves else 2)


def test_runners_up_are_the_unexplained_hypotheses_within_the_revisit_gap():
    """Of a round's hypotheses, those no mode explains and that start none but score within
    revisit_score_gap of the best come back as runners_up, best first; the rest do not."""
    s = S.model_copy(update={"birth_score_gap": 0.1, "revisit_score_gap": 0.25})
    far = [Sim2(1.0, 0.5 * k, (30.0 * k, 0.0)) for k in range(1, 5)]
    tracker = HypothesisTracker(s)
    tracker.update([Hyp(BASE, 0.5), Hyp(far[0], 0.45), Hyp(far[1], 0.3), Hyp(far[2], 0.25), Hyp(far[3], below(0.25))],
                   SENSOR_A, frame=0)
    assert len(tracker.modes) == 2  # the best and the one within birth_score_gap
    assert [tuple(np.asarray(a.t)) for a in tracker.runners_up] == [tuple(np.asarray(f.t)) for f in far[1:3]]
    tracker.update([Hyp(BASE, 0.5)], SENSOR_A, frame=5)  # a round without near misses forgets them
    assert tracker.runners_up == []
    for r in range(2, 5):  # once a mode is tracked, near misses are not looked at again
        tracker.update([Hyp(BASE, 0.5), Hyp(far[1], 0.3)], SENSOR_A, frame=5 * r)
    assert tracker.status == "tracking" and tracker.runners_up == []


@pytest.mark.parametrize("name, delta", [("merge_translation", {"dq": (0.25, 0.0)}),
                                         ("merge_angle_deg", {"dtheta": np.deg2rad(4.0)}),
                                         ("merge_log_scale", {"dlog_s": 0.04})])
def test_merge_limits(name, delta):
    """Two hypotheses of one round implying sensor poses that differ in one component only:
    one mode when that difference is within the limit (<=), two just below it."""
    twin = shifted(BASE, SENSOR_A, **delta)
    d = anchored_state(twin, SENSOR_A) - anchored_state(BASE, SENSOR_A)
    gap = {"merge_translation": float(np.hypot(d[0], d[1])), "merge_angle_deg": abs(d[2]), "merge_log_scale": abs(d[3])}[name]
    limit = np.rad2deg(gap) if name == "merge_angle_deg" else gap
    for setting, modes in ((limit * (1 + 1e-9), 1), (limit * (1 - 1e-9), 2)):
        tracker = HypothesisTracker(S.model_copy(update={name: setting}))
        tracker.update([Hyp(BASE, 0.5), Hyp(twin, 0.49)], SENSOR_A, frame=0)
        assert len(tracker.modes) == modes


@pytest.mark.parametrize("n", [1, 3, 5])
def test_confident_rounds(n):
    """confidently_tracking after exactly confident_rounds tracked rounds of one mode."""
    tracker = HypothesisTracker(S.model_copy(update={"confident_rounds": n}))
    tracked, confident = [], []
    for r in range(12):
        tracker.update([Hyp(BASE, 0.6)], SENSOR_A, frame=5 * r)
        tracked.append(tracker.status == "tracking")
        confident.append(tracker.confidently_tracking)
    first = tracked.index(True)
    assert confident == [r >= first + n - 1 for r in range(12)]


# --- the odometry jump (issue 44) ------------------------------------------------------------
@pytest.mark.parametrize("name", ["odometry_jump_min_step", "odometry_jump_min_turn_deg", "odometry_jump_factor"])
def test_odometry_jump_limits(name):
    """ODOMETRY_JUMP: a step (or turn) beyond min + factor x the recent motion is a jump
    unless the BEV explains the frame's hits; at the limit it is not."""
    s = S.model_copy(update={"odometry_jump_min_step": 1.0, "odometry_jump_min_turn_deg": 10.0, "odometry_jump_factor": 2.0})
    recent_step, recent_turn = 0.25, np.deg2rad(4.0)
    if name == "odometry_jump_min_turn_deg":
        limit = np.deg2rad(10.0) + 2.0 * recent_turn
        cases = [(0.0, limit, False), (0.0, above(limit), True)]
    else:  # the factor and the step floor meet at one boundary: 1.0 + 2.0 * 0.25
        limit = 1.0 + 2.0 * recent_step
        cases = [(limit, 0.0, False), (above(limit), 0.0, True)]
    for step, turn, jumped in cases:
        assert policy.odometry_jumped(step, turn, recent_step, recent_turn, False, s) is jumped
        assert policy.odometry_jumped(step, turn, recent_step, recent_turn, True, s) is False  # the BEV explains it
    # the setting itself moves the boundary
    bigger = s.model_copy(update={name: getattr(s, name) * 2})
    step, turn = (0.0, above(np.deg2rad(10.0) + 2.0 * recent_turn)) if name == "odometry_jump_min_turn_deg" else (above(1.0 + 2.0 * recent_step), 0.0)
    assert not policy.odometry_jumped(step, turn, recent_step, recent_turn, False, bigger)


def test_odometry_jump_watch_judges_a_full_window_asks_the_bev_and_lets_the_next_frame_decide():
    """OdometryJumpWatch: no judgement before odometry_jump_window steps; then a 3 m step
    is suspect only when the frame's hits are not explained (known hits >=
    localizer.monitor_min_points and contradiction < tracking.odometry_jump_contradiction). The
    next frame decides: back near the track, a spike (nothing restarts); going on from
    the suspect frame, a jump. Window 0 never judges."""
    from zfloc_stream.settings.loading import Settings
    from zfloc_stream.stream.odometry_jump import JUMPED, SUSPECT, OdometryJumpWatch

    settings = Settings(tracking={"odometry_jump_window": 3})
    lc, limit = settings.localizer, settings.tracking.odometry_jump_contradiction
    watch = OdometryJumpWatch(settings)

    def walk(k):
        return (0.1 * k, 0.0, 0.0)

    assert [watch.judge(walk(k), 0, 1.0, 100) for k in range(4)] == [None] * 4  # first pose, then 3 steps filling the window
    assert watch.judge((3.3, 0.0, 0.0), lc.monitor_min_points, below(limit), lc.monitor_min_points) is None  # explained
    watch.restart(walk(3))
    for k in range(4, 7):
        assert watch.judge(walk(k), 0, 0.0, 100) is None
    assert watch.judge((3.6, 0.0, 0.0), lc.monitor_min_points, limit, lc.monitor_min_points)[0] == SUSPECT
    assert watch.judge(walk(8), 0, 1.0, 100) is None  # back on the track: a spike
    assert watch.judge((3.8, 0.0, 0.0), lc.monitor_min_points - 1, 0.0, lc.monitor_min_points - 1)[0] == SUSPECT  # too few known hits to explain it
    verdict = watch.judge((3.9, 0.0, 0.0), 0, 1.0, 100)  # going on from the suspect frame
    assert verdict[0] == JUMPED and verdict[1].startswith(policy.PolicyRule.ODOMETRY_JUMP)
    min_turn = settings.tracking.odometry_jump_min_turn_deg  # no turn in the window: the limit is min_turn
    for turn, expected in ((np.deg2rad(min_turn - 0.01), None), (np.deg2rad(min_turn + 0.01), SUSPECT)):  # the exact boundary: above
        watch.restart((0.0, 0.0, 0.0))
        for _ in range(4):
            watch.judge((0.0, 0.0, 0.0), 0, 0.0, 100)
        verdict = watch.judge((0.0, 0.0, turn), 0, 1.0, 100)
        assert (verdict if verdict is None else verdict[0]) == expected
    off = OdometryJumpWatch(Settings(tracking={"odometry_jump_window": 0}))
    assert [off.judge((1e3 * k, 0.0, 0.0), 0, 1.0, 100) for k in range(20)] == [None] * 20


def test_odometry_jump_min_known_share_is_the_seen_part_a_step_needs():
    """A step past the gate is explained only when at least odometry_jump_min_known_share of
    the frame's wall hits land on cells older frames saw (a camera turned 90 deg into rooms
    nobody saw: 49 of 9,885 hits), however few of those contradict them."""
    from zfloc_stream.settings.loading import Settings
    from zfloc_stream.stream.odometry_jump import SUSPECT, OdometryJumpWatch

    settings = Settings(tracking={"odometry_jump_window": 3, "odometry_jump_min_known_share": 0.25})
    lc = settings.localizer
    for hits, expected in ((4 * 200, None), (4 * 200 + 1, SUSPECT)):  # 200 known hits: exactly 0.25, then below
        watch = OdometryJumpWatch(settings)
        for k in range(4):
            watch.judge((0.1 * k, 0.0, 0.0), 0, 0.0, 100)
        assert 200 >= lc.monitor_min_points
        verdict = watch.judge((3.3, 0.0, 0.0), 200, 0.0, hits)
        assert (verdict if verdict is None else verdict[0]) == expected
