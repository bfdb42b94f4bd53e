"""The status of a frame: one decision (`decide`), one table.

`decide` is the only place that says which estimate.Status a frame gets. It reads what the
filter bank's latest round established (RoundFacts: the policy's verdicts on the bank's
numbers then, kept by the bank until its next round), what the frame's own evidence says
about the reported pose (FrameEvidence), the recovery (Recovery: a running kidnap test, a
doubtful odometry step), whether the caller's prior is in doubt, and, while a preview is
reported, the tracker's own round. It changes nothing: the filter bank applies a round's
decision to its modes (filter_bank.py), the localizer reports a frame's.

The rules in priority order, the first that holds decides; a round's rules give the
round's status, a frame's rules only ever withhold `tracking` from one frame:

| rule | status | holds when |
|---|---|---|
| NO_ROUND | initializing | no round ran since the bank (re)started |
| DECLARED_LOST | lost | no round since the localizer dropped every mode (an odometry jump; a kidnap test's own bank) |
| BEV_NOT_READY | initializing | the round's BEV was too small to trust |
| PRUNED | lost | the tracked mode left the bank (pruned, merged away) |
| COLLAPSED | lost | the tracked mode collapsed lost_rounds rounds in a row |
| OVERTAKEN | lost | an established rival is reported instead of the tracked mode |
| WAITING_FOR_CONFIRMATION | initializing (lost after a loss) | the leader has fewer than rounds_to_track hits |
| AMBIGUITY | ambiguous | another confirmed mode holds >= ambiguity_ratio of the leader's weight |
| THIN_EVIDENCE | ambiguous if a mode is tracked, else as waiting | the leader holds <= dominance_weight, or (untracked) the round did not single it out |
| TRACKING | tracking | one confirmed mode dominates (a frame's rules below may still withhold it) |
| KIDNAP_TEST | lost | a kidnap test runs: the run of frames the monitor saw contradicts the pose (recovery.py) |
| ODOMETRY_STEP | lost | the frame's odometry step is one the sensor cannot have made (odometry_jump.py) |
| FRAME_UNEXPLAINED | lost | the monitor finds the frame's wall hits unexplained by the pose (monitor.py) |
| POSE_JUMP | lost | the reported pose moved beyond pose_jump_chi2 since the last frame |
| AUDIT_DOUBT | ambiguous | the latest audit scored the reported place below audit_doubt_share of its usual audit score and another place at least as high, or a kidnap test on it ended without adopting another place, and no audit has cleared it since (stream/audit.py) |
| MAP_UNEXPLAINED | ambiguous | the mode's weight times the map's fit to the latest BEV (policy.map_fit) is at most dominance_weight |
| PRIOR_DOUBTED | ambiguous | the prior holds, but the frames favour a place outside it (prior.py) |
| PRIOR_POSE | initializing (lost stays lost) | the prior's own pose is reported: no place the map explains (prior.PriorWatch.stand_in; set by the localizer) |
| PREVIEW | the tracker's round status | a preview (one round on fewer frames) is reported: never a promise |

The rules on the bank's numbers are tracking/policy.py's (one setting each, boundary-tested
in tests/test_tracking_rules.py); tests/test_status_rules.py tests each rule here at its
boundary.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import NamedTuple, Sequence

from . import policy
from ..estimate import Status
from ..settings.tracking import TrackingSettings


class Rule(StrEnum):
    """Why a frame has its status; members in priority order (the table above)."""

    # the round's (kept until the next round)
    NO_ROUND = "no round yet"
    DECLARED_LOST = "declared lost"
    BEV_NOT_READY = "BEV not ready"
    PRUNED = policy.PolicyRule.PRUNED
    COLLAPSED = policy.PolicyRule.COLLAPSED
    OVERTAKEN = policy.PolicyRule.OVERTAKEN
    WAITING_FOR_CONFIRMATION = policy.PolicyRule.WAITING_FOR_CONFIRMATION
    AMBIGUITY = policy.PolicyRule.AMBIGUITY
    THIN_EVIDENCE = policy.PolicyRule.THIN_EVIDENCE
    TRACKING = policy.PolicyRule.TRACKING
    # the frame's (withhold `tracking` from one frame)
    KIDNAP_TEST = "kidnap test running"
    ODOMETRY_STEP = "odometry step in doubt"
    FRAME_UNEXPLAINED = "frame unexplained"
    POSE_JUMP = policy.PolicyRule.POSE_JUMP
    AUDIT_DOUBT = "audit doubts the place"
    MAP_UNEXPLAINED = policy.PolicyRule.MAP_UNEXPLAINED
    PRIOR_DOUBTED = "prior doubted"
    PRIOR_POSE = "prior's own pose"
    PREVIEW = "preview"


class Decision(NamedTuple):
    status: Status
    rule: Rule


@dataclass(frozen=True)
class RoundFacts:
    """What a filter bank's latest round established, as the status rules read it.
    The defaults: no round since the bank started."""

    ran: bool = False  # a round ran since the bank (re)started
    was_lost: bool = False  # the bank lost its tracked mode (or was declared lost) and has tracked none since
    bev_ready: bool = True  # the round's BEV was large enough to trust
    tracked: bool = False  # a mode was tracked going into the round
    loss: str | None = None  # policy.loss_rule of the tracked mode (None: kept, or none tracked)
    confirmation: str | None = None  # policy.round_status_rule, when no tracked mode was lost


def round_facts(leader: policy.ModeNumbers | None, modes: Sequence[policy.ModeNumbers], tracked: policy.ModeNumbers | None,
                tracked_id: int | None, was_lost: bool, s: TrackingSettings) -> RoundFacts:
    """The facts of a round that found the bank's modes as given: leader, the reported mode
    (policy.reported_mode); tracked, the mode of tracked_id while it is in the bank."""
    loss = None if tracked_id is None else policy.loss_rule(tracked, leader, s)
    confirmation = None if loss else policy.round_status_rule(leader, modes, tracked_id, was_lost, s)
    return RoundFacts(True, was_lost, True, tracked_id is not None, loss, confirmation)


@dataclass(frozen=True)
class FrameEvidence:
    """What one frame says about its reported pose (HypothesisTracker.judge_frame)."""

    consistent: bool | None = None  # monitor.frame_consistent on its wall hits (None: too few to judge)
    pose_jumped: bool = False  # policy.pose_jumped on the reported pose's step
    map_explains: bool = True  # policy.map_vouches on the latest BEV and the mode's weight


@dataclass(frozen=True)
class Recovery:
    """The recovery's state at a frame."""

    kidnap_test: bool = False  # a kidnap test runs (recovery.KidnapTest)
    odometry_step: bool = False  # the odometry-jump watch doubts the frame's step (odometry_jump.py)
    audit_doubt: bool = False  # the audit doubts the reported place (stream/audit.py)


NO_RECOVERY = Recovery()


def contradicts(frame: FrameEvidence, recovery: Recovery = NO_RECOVERY) -> bool:
    """The frame's evidence (or the recovery) contradicts its pose: then its confidence is
    0, and a `tracking` round reports it `lost`."""
    return recovery.kidnap_test or recovery.odometry_step or frame.consistent is False or frame.pose_jumped


def decide(round: RoundFacts, frame: FrameEvidence | None = None, recovery: Recovery = NO_RECOVERY,
           prior_doubted: bool = False, preview_of: RoundFacts | None = None) -> Decision:
    """The status of a frame and the rule that gave it (the table above). round: the
    latest round of the bank whose mode is reported. frame: None when no pose is reported
    (no mode yet, or the frame was not fused; then the frame's own rules do not apply).
    preview_of: the tracker's own round, while a preview's bank is reported."""
    waiting = Status.LOST if round.was_lost else Status.INITIALIZING
    if not round.ran:
        return Decision(waiting, Rule.DECLARED_LOST if round.was_lost else Rule.NO_ROUND)
    if not round.bev_ready:
        return Decision(Status.INITIALIZING, Rule.BEV_NOT_READY)
    if round.loss:
        return Decision(Status.LOST, Rule(round.loss))
    rule = Rule(round.confirmation)
    if rule is Rule.WAITING_FOR_CONFIRMATION:
        return Decision(waiting, rule)
    if rule is Rule.AMBIGUITY:
        # a tracked mode stays the one reported (hysteresis) while a rival is only as good
        return Decision(Status.AMBIGUOUS, rule)
    if rule is Rule.THIN_EVIDENCE:
        # a tracked mode keeps its place, an untracked one waits
        return Decision(Status.AMBIGUOUS if round.tracked else waiting, rule)
    if frame is not None:
        if recovery.kidnap_test:
            return Decision(Status.LOST, Rule.KIDNAP_TEST)
        if recovery.odometry_step:
            return Decision(Status.LOST, Rule.ODOMETRY_STEP)
        if frame.consistent is False:
            return Decision(Status.LOST, Rule.FRAME_UNEXPLAINED)
        if frame.pose_jumped:
            return Decision(Status.LOST, Rule.POSE_JUMP)
        if recovery.audit_doubt:
            return Decision(Status.AMBIGUOUS, Rule.AUDIT_DOUBT)
        if not frame.map_explains:
            return Decision(Status.AMBIGUOUS, Rule.MAP_UNEXPLAINED)
    if prior_doubted:
        return Decision(Status.AMBIGUOUS, Rule.PRIOR_DOUBTED)
    if preview_of is not None:
        return Decision(decide(preview_of).status, Rule.PREVIEW)
    return Decision(Status.TRACKING, Rule.TRACKING)


def vouches(decision: Decision) -> bool:
    """May the frame's confidence exceed dominance_weight? Only when its pose is vouched
    for: a `tracking` frame, or one whose preview bank would be (PREVIEW: the status is
    the tracker's, the confidence the reported bank's)."""
    return decision.status is Status.TRACKING or decision.rule is Rule.PREVIEW
