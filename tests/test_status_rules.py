"""Every status rule (tracking/status.py) at its boundary: the smallest input on each side
of its condition, through the one decision (status.decide) on the facts a round and a
frame give it."""

import json
import re

import numpy as np
import pytest

from zfloc_stream.estimate import STATUSES, Status
from zfloc_stream.settings.loading import TrackingSettings
from zfloc_stream.tracking import policy, status
from zfloc_stream.tracking.status import FrameEvidence, Recovery, RoundFacts, Rule, decide, round_facts, vouches

from test_tracking_rules import above, below, mode

S = TrackingSettings()
LOST, INIT, AMBIGUOUS, TRACKING = Status.LOST, Status.INITIALIZING, Status.AMBIGUOUS, Status.TRACKING


def confirmed(id=0, weight=0.95, **kw):
    """A mode the policy would track: confirmed, dominant."""
    return mode(id=id, weight=weight, hits=kw.pop("hits", S.confirm_rounds), **kw)


def facts(leader=None, modes=None, tracked=None, tracked_id=None, was_lost=False, s=S):
    leader = confirmed() if leader is None else leader
    return round_facts(leader, [leader] if modes is None else modes, tracked, tracked_id, was_lost, s)


TRACKED = facts()  # a round that tracks its leader
FRAME = FrameEvidence(consistent=True)  # a frame whose evidence agrees with the pose


# --- the table ----------------------------------------------------------------------------
def test_the_docstring_table_lists_every_rule_in_priority_order():
    table = re.findall(r"^\| ([A-Z_]+) \|", status.__doc__, flags=re.M)
    assert table == [r.name for r in Rule]


def test_a_status_is_the_word_logs_csv_and_users_read():
    assert STATUSES == ("initializing", "tracking", "ambiguous", "lost")
    for s in Status:
        assert s == s.value and f"{s}" == str(s) == s.value and json.dumps(s) == json.dumps(s.value)
        assert type(s.value) is str


def test_decide_is_tracking_on_a_tracked_round_and_a_frame_that_agrees():
    assert decide(TRACKED) == (TRACKING, Rule.TRACKING)
    assert decide(TRACKED, FRAME) == (TRACKING, Rule.TRACKING)


# --- the round's rules ----------------------------------------------------------------------
def test_no_round_and_declared_lost():
    assert decide(RoundFacts()) == (INIT, Rule.NO_ROUND)
    assert decide(RoundFacts(was_lost=True)) == (LOST, Rule.DECLARED_LOST)
    assert decide(RoundFacts(ran=True, was_lost=True, bev_ready=False)).rule is Rule.BEV_NOT_READY


def test_bev_not_ready_reports_initializing_even_after_a_loss():
    for was_lost in (False, True):
        assert decide(RoundFacts(ran=True, was_lost=was_lost, bev_ready=False)) == (INIT, Rule.BEV_NOT_READY)
    assert decide(facts(was_lost=True)).rule is not Rule.BEV_NOT_READY


def test_pruned():
    assert decide(facts(tracked=None, tracked_id=0)) == (LOST, Rule.PRUNED)
    assert decide(facts(tracked=None, tracked_id=None)) == (TRACKING, Rule.TRACKING)


def test_collapsed_at_lost_rounds():
    at = confirmed(collapses=S.lost_rounds)
    assert decide(facts(at, tracked=at, tracked_id=0)) == (LOST, Rule.COLLAPSED)
    short = confirmed(collapses=S.lost_rounds - 1)
    assert decide(facts(short, tracked=short, tracked_id=0)) == (TRACKING, Rule.TRACKING)


def test_overtaken():
    tracked, rival = confirmed(0, weight=0.04), confirmed(1)
    assert decide(facts(rival, [tracked, rival], tracked=tracked, tracked_id=0)) == (LOST, Rule.OVERTAKEN)
    assert decide(facts(tracked, [tracked, rival], tracked=tracked, tracked_id=0)).rule is not Rule.OVERTAKEN


@pytest.mark.parametrize("was_lost, waiting", [(False, INIT), (True, LOST)])
def test_waiting_for_confirmation_until_rounds_to_track_hits(was_lost, waiting):
    needed = policy.rounds_to_track(was_lost, S)
    assert decide(facts(confirmed(hits=needed - 1), was_lost=was_lost)) == (waiting, Rule.WAITING_FOR_CONFIRMATION)
    assert decide(facts(confirmed(hits=needed), was_lost=was_lost)) == (TRACKING, Rule.TRACKING)


def test_ambiguity_at_ambiguity_ratio_of_the_leaders_weight():
    leader = confirmed(0)
    rival = confirmed(1, weight=S.ambiguity_ratio * leader.weight)
    assert decide(facts(leader, [leader, rival], leader, 0)) == (AMBIGUOUS, Rule.AMBIGUITY)
    rival.weight = below(rival.weight)
    assert decide(facts(leader, [leader, rival], leader, 0)) == (TRACKING, Rule.TRACKING)
    assert decide(facts(leader, [leader, rival], None, None)) == (TRACKING, Rule.TRACKING)  # untracked too


@pytest.mark.parametrize("tracked_id, was_lost, thin", [(0, False, AMBIGUOUS), (None, False, INIT), (None, True, LOST)])
def test_thin_evidence_at_dominance_weight(tracked_id, was_lost, thin):
    hits = policy.rounds_to_track(was_lost, S)
    at = confirmed(weight=S.dominance_weight, hits=hits)
    tracked = at if tracked_id is not None else None
    assert decide(facts(at, tracked=tracked, tracked_id=tracked_id, was_lost=was_lost)) == (thin, Rule.THIN_EVIDENCE)
    over = confirmed(weight=above(S.dominance_weight), hits=hits)
    tracked = over if tracked_id is not None else None
    assert decide(facts(over, tracked=tracked, tracked_id=tracked_id, was_lost=was_lost)) == (TRACKING, Rule.TRACKING)


def test_thin_evidence_when_an_untracked_leader_is_not_singled_out():
    leader, rival = confirmed(0), mode(1, weight=0.01, near_top=True)
    assert decide(facts(leader, [leader, rival])) == (INIT, Rule.THIN_EVIDENCE)
    rival.near_top = False
    assert decide(facts(leader, [leader, rival])) == (TRACKING, Rule.TRACKING)


# --- the frame's rules: they only withhold `tracking` ---------------------------------------
AMBIGUOUS_ROUND = facts(confirmed(0), [confirmed(0), confirmed(1, weight=0.9)], None, None)


@pytest.mark.parametrize("recovery, rule", [(Recovery(kidnap_test=True), Rule.KIDNAP_TEST),
                                            (Recovery(odometry_step=True), Rule.ODOMETRY_STEP)])
def test_the_recovery_withholds_tracking_from_a_frame_with_a_pose(recovery, rule):
    assert decide(TRACKED, FRAME, recovery) == (LOST, rule)
    assert decide(TRACKED, FRAME, Recovery()) == (TRACKING, Rule.TRACKING)
    assert decide(TRACKED, None, recovery) == (TRACKING, Rule.TRACKING)  # no pose: nothing to contradict
    assert decide(AMBIGUOUS_ROUND, FRAME, recovery) == (AMBIGUOUS, Rule.AMBIGUITY)  # never upgrades


def test_the_kidnap_test_comes_before_a_doubtful_odometry_step():
    assert decide(TRACKED, FRAME, Recovery(True, True)).rule is Rule.KIDNAP_TEST


def test_the_audits_doubt_makes_a_frame_ambiguous_after_the_frames_own_evidence():
    doubt = Recovery(audit_doubt=True)
    assert decide(TRACKED, FRAME, doubt) == (AMBIGUOUS, Rule.AUDIT_DOUBT)
    assert decide(TRACKED, None, doubt) == (TRACKING, Rule.TRACKING)  # no pose: nothing to doubt
    assert decide(AMBIGUOUS_ROUND, FRAME, doubt) == (AMBIGUOUS, Rule.AMBIGUITY)  # never upgrades
    assert decide(TRACKED, FrameEvidence(consistent=False), doubt).rule is Rule.FRAME_UNEXPLAINED
    assert decide(TRACKED, FrameEvidence(consistent=True, map_explains=False), doubt).rule is Rule.AUDIT_DOUBT
    assert not status.contradicts(FRAME, doubt)  # the pose may be right: confidence at most dominance_weight


def test_frame_unexplained():
    assert decide(TRACKED, FrameEvidence(consistent=False)) == (LOST, Rule.FRAME_UNEXPLAINED)
    assert decide(TRACKED, FrameEvidence(consistent=None)) == (TRACKING, Rule.TRACKING)  # too few hits: no verdict
    assert decide(AMBIGUOUS_ROUND, FrameEvidence(consistent=False)) == (AMBIGUOUS, Rule.AMBIGUITY)


def test_pose_jump_beyond_pose_jump_chi2():
    jumped = FrameEvidence(consistent=True, pose_jumped=policy.pose_jumped(above(S.pose_jump_chi2), S))
    assert decide(TRACKED, jumped) == (LOST, Rule.POSE_JUMP)
    held = FrameEvidence(consistent=True, pose_jumped=policy.pose_jumped(S.pose_jump_chi2, S))
    assert decide(TRACKED, held) == (TRACKING, Rule.TRACKING)


def test_map_unexplained_where_weight_times_the_maps_fit_reaches_dominance_weight():
    share = S.min_explained_share - S.confidence_share_band + 2 * S.confidence_share_band * S.dominance_weight  # weight 1: fit 0.9
    below_share = FrameEvidence(consistent=True, map_explains=policy.map_vouches(share - 1e-9, 1.0, S))
    assert decide(TRACKED, below_share) == (AMBIGUOUS, Rule.MAP_UNEXPLAINED)
    above_share = FrameEvidence(consistent=True, map_explains=policy.map_vouches(share + 1e-9, 1.0, S))
    assert decide(TRACKED, above_share) == (TRACKING, Rule.TRACKING)
    # a frame that contradicts the pose is lost, whatever the map explains
    assert decide(TRACKED, FrameEvidence(consistent=False, map_explains=False)).rule is Rule.FRAME_UNEXPLAINED


def test_prior_doubted():
    assert decide(TRACKED, FRAME, prior_doubted=True) == (AMBIGUOUS, Rule.PRIOR_DOUBTED)
    assert decide(TRACKED, None, prior_doubted=True) == (AMBIGUOUS, Rule.PRIOR_DOUBTED)  # with no pose too
    assert decide(TRACKED, FRAME, prior_doubted=False) == (TRACKING, Rule.TRACKING)
    assert decide(RoundFacts(), None, prior_doubted=True) == (INIT, Rule.NO_ROUND)


def test_a_preview_reports_the_trackers_own_round_status():
    assert decide(TRACKED, FRAME, preview_of=RoundFacts()) == (INIT, Rule.PREVIEW)
    assert decide(TRACKED, FRAME, preview_of=RoundFacts(was_lost=True)) == (LOST, Rule.PREVIEW)
    assert decide(TRACKED, FRAME, preview_of=None) == (TRACKING, Rule.TRACKING)
    assert decide(AMBIGUOUS_ROUND, FRAME, preview_of=RoundFacts()) == (AMBIGUOUS, Rule.AMBIGUITY)
    assert decide(TRACKED, FRAME, prior_doubted=True, preview_of=RoundFacts()).rule is Rule.PRIOR_DOUBTED


def test_only_a_tracking_frame_or_a_tracking_preview_vouches_for_its_confidence():
    assert vouches(decide(TRACKED, FRAME)) and vouches(decide(TRACKED, FRAME, preview_of=RoundFacts()))
    assert not vouches(decide(TRACKED, FRAME, prior_doubted=True))
    assert not vouches(decide(AMBIGUOUS_ROUND, FRAME))


def test_the_tracker_keeps_its_rounds_decision_between_rounds():
    """The bank applies the round's decision (filter_bank._update_status): the facts it keeps
    give the same status at every frame until the next round, after its loss mutations."""
    from zfloc_stream.tracking.filter_bank import HypothesisTracker

    tracker = HypothesisTracker()
    assert tracker.status is INIT and decide(tracker.round_facts).rule is Rule.NO_ROUND
    tracker.declare_lost()
    assert tracker.status is LOST and decide(tracker.round_facts).rule is Rule.DECLARED_LOST
    assert np.isnan(tracker.judge_frame(None, None, None)[1])
