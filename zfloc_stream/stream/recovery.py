"""The kidnap test: was the sensor carried off, or does it see what the map lacks?

A run of frames the tracked alignment does not explain (monitor.py) is one or the other:
the sensor sees a room the map leaves out, or clutter; or it is at another place than the
tracked one (carried off, a slipped wheel, a wrong mode that won a round). Only in the
second case does the rest of the BEV show another place than the recent frames, so a
global search on the whole BEV keeps finding the old place: on the Carmen logs spliced at
far-apart places it took 26-87 frames to recover.

A sensor carried off sees a discontinuity, one walking into what the map lacks does not:
the first frame at the new place puts its walls where older frames saw open space
(RollingBEV.last_contradiction, at least localizer.kidnap_contradiction). Only then does
the localizer start a test (else the next round searches globally, as before).

The hypothesis "carried off" gets its own filter bank, fed by global rounds on what the
frames from the run's start on saw alone (the old place among their warm starts, so that
it competes on the same evidence). It must earn `tracking` there by the tracker's own
rules, as after a loss (confirm_rounds_after_loss hits, dominance, no close rival), and
then be a better place (better_place): elsewhere than the tracked one, and explaining the
recent frames as the monitor wants them explained, better than the old place (a test an
audit started: its own round still outscores the old place, audit.py). Then the
localizer adopts the bank and the BEV forgets what only older frames saw. If not within
confirm_rounds_after_loss + 1 rounds, the test ends and nothing is lost: the BEV is as it
was and the tracker's own rounds went on meanwhile. No frame is `tracking` while a test
runs.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..estimate import Status
from ..estimation.local_refinement import LocalRefinement
from ..settings.loading import Settings
from ..settings.localizer import LocalizerSettings
from .monitor import ConsistencyMonitor
from .recent_frames import RecentFrames
from .scheduler import RoundJob, RoundOutcome, ScheduledRound
from ..geometry.sim2 import Sim2
from ..tracking.filter_bank import HypothesisTracker
from ..tracking.mode import Mode


class Verdict(Enum):
    GOES_ON = "goes on"
    CARRIED_OFF = "carried off"  # adopt the test's bank
    NOT_CARRIED_OFF = "not carried off"  # the test ends, nothing changes


@dataclass
class KidnapTest:
    since: int  # BEV stamp of the first frame of the monitor's inconsistent run
    tracker: HypothesisTracker  # its own filter bank
    rounds_left: int
    contradiction: float  # the most any recent frame contradicted the BEV when the test started
    audit: bool = False  # started by an audit (outscored), not by the monitor: adopted when outscored too
    old_id: int | None = None  # the tracked mode whose place it tests
    old_alignment: Sim2 | None = None  # that place, as the tracker last held it (Relocalization.feed)

    @classmethod
    def start(cls, bev_stamp: int, settings: Settings, contradiction: float, since: int | None = None,
              audit: bool = False, old_id: int | None = None) -> "KidnapTest":
        """The test of a run of monitor_frames inconsistent frames ending at bev_stamp (or,
        since given, of the frames from that BEV stamp on: an audit's); contradiction: the
        most a frame of the last localizer.local_frames contradicted what older frames saw
        (RollingBEV.last_contradiction)."""
        bank = HypothesisTracker(settings.tracking)
        bank.declare_lost()  # a new place after a loss needs confirm_rounds_after_loss hits
        since = bev_stamp - settings.localizer.monitor_frames + 1 if since is None else since
        return cls(since, bank, settings.tracking.confirm_rounds_after_loss + 1, contradiction, audit, old_id)

    def job(self, index: int, old: Mode | None) -> RoundJob:
        """The test's round started at frame index: a global search on what the BEV saw since
        self.since, warm-started from its bank and the old place."""
        warm = self.tracker.warm_start() + ([] if old is None else [old.alignment])
        return RoundJob(index, None, warm, False, self.since)

    def feed(self, scheduled: ScheduledRound, outcome: RoundOutcome) -> Mode | None:
        """One of the test's rounds landed: update the bank. Returns the place it tracks,
        None while it tracks none."""
        self.rounds_left -= 1
        if outcome.result is not None:
            self.tracker.update(outcome.result.hypotheses, scheduled.plane_pose[:2], scheduled.job.index)
        return self.tracker.best if self.tracker.status is Status.TRACKING else None

    def verdict(self, better: bool) -> Verdict:
        """After feed: better says whether the place it returned is a better place than the
        old one (Places.better_place)."""
        if better:
            return Verdict.CARRIED_OFF
        if self.rounds_left <= 0 or self.tracker.status is Status.TRACKING:
            return Verdict.NOT_CARRIED_OFF  # nothing else earned tracking (or the old place did)
        return Verdict.GOES_ON


@dataclass(frozen=True)
class Places:
    """What places are judged on while the stream goes on: the tracker (its pose-jump gate
    says what another place is), the monitor (what explaining the frames means), the local
    refinement (a mode's alignment as reported) and the recent frames' hits."""

    tracker: HypothesisTracker
    monitor: ConsistencyMonitor
    local: LocalRefinement
    recent: RecentFrames
    settings: LocalizerSettings

    def better_place(self, found: Sim2, old: Mode, sensor_xy) -> bool:
        """better_place of `found` against the old mode as it is reported: its hits rescaled
        under metric odometry (else the recent hits themselves)."""
        recent, local = self.recent, self.local
        return better_place(found, local.alignment_of_mode(old), old, self.tracker, self.monitor, recent.hits, sensor_xy,
                            [local.frame_hits(h, c, old) for h, c in zip(recent.hits, recent.cameras)]
                            if local.metric_odometry else None)

    def outscored(self, outcome: RoundOutcome, old: Mode, sensor_xy, found: Sim2 | None = None,
                  min_violation: float | None = None) -> bool:
        """outscored: the round (on recent frames alone) scores another place (found, default
        its best) audit_margin above the tracked one as reported, the frames having seen open
        space through min_violation of its walls (default audit_min_violation), and that
        place explains the recent frames' hits as the monitor wants."""
        if outcome.result is None or not outcome.result.hypotheses:
            return False
        found = outcome.result.hypotheses[0].alignment if found is None else found
        if not outscored(outcome.result.hypotheses, self.local.alignment_of_mode(old), old, self.tracker, sensor_xy,
                         self.settings.audit_margin,
                         self.settings.audit_min_violation if min_violation is None else min_violation, found):
            return False
        hits = self.recent.all_hits()
        share = None if hits is None else self.monitor.share(found, hits)
        return share is not None and self.monitor.explains(share, self.monitor.usual_share(old.id))

    def best_at(self, outcome: RoundOutcome, place: Sim2, mode: Mode, sensor_xy):
        """best_at among the round's hypotheses."""
        return best_at(outcome.result.hypotheses, place, mode, self.tracker, sensor_xy)

    def best_here_and_elsewhere(self, outcome: RoundOutcome, place: Sim2, mode: Mode, sensor_xy):
        """(best_at, the best-scored hypothesis beyond the pose-jump gate of `place`) among
        the round's hypotheses, in one pass; None where it kept none."""
        return best_near_and_far(outcome.result.hypotheses, place, mode, self.tracker, sensor_xy)


def better_place(found: Sim2, old: Sim2, old_mode: Mode, tracker: HypothesisTracker, monitor: ConsistencyMonitor,
                 recent_hits: list[np.ndarray], sensor_xy, old_hits: list[np.ndarray] | None = None) -> bool:
    """Is the alignment `found` another place than the tracked `old` (beyond the tracker's
    pose-jump gate, tracker.pose_jumped), explaining the recent frames' wall hits as the
    monitor wants them explained (against the old mode's usual share) and more of them
    than the old place? A short stretch of corridor alone fits many places along it: the
    test's bank can single one out on thin evidence, which these hits then refute.
    old_hits: the same frames' hits as the old (reported) alignment reads them, when that
    differs (LocalRefinement.frame_hits under metric odometry); default recent_hits."""
    if not tracker.pose_jumped(old, found, sensor_xy, old_mode):
        return False
    hits = [h for h in recent_hits if len(h)]
    if not hits:
        return False
    hits = np.concatenate(hits)
    read_by_old = hits if old_hits is None else np.concatenate([h for h in old_hits if len(h)])
    share = monitor.share(found, hits)
    return share is not None and monitor.explains(share, monitor.usual_share(old_mode.id)) and share > monitor.share(old, read_by_old)


def best_at(hypotheses, place: Sim2, mode: Mode, tracker: HypothesisTracker, sensor_xy):
    """The best-scored hypothesis a round kept at `place` (within the tracker's pose-jump
    gate of it, under mode's covariance); None when it kept none there (then the place
    scored below every hypothesis the round kept)."""
    return best_near_and_far(hypotheses, place, mode, tracker, sensor_xy)[0]


def best_near_and_far(hypotheses, place: Sim2, mode: Mode, tracker: HypothesisTracker, sensor_xy):
    """The best-scored hypotheses within and beyond the tracker's pose-jump gate of `place`
    (under mode's covariance), each None when the round kept none there."""
    near, far = [], []
    for h in hypotheses:
        (far if tracker.pose_jumped(place, h.alignment, sensor_xy, mode) else near).append(h)
    return max(near, key=lambda h: h.score, default=None), max(far, key=lambda h: h.score, default=None)


def outscored(hypotheses, old: Sim2, old_mode: Mode, tracker: HypothesisTracker, sensor_xy, gap: float,
              min_violation: float, found: Sim2 | None = None) -> bool:
    """Does a round on the recent frames alone (the audit's) score another place at least
    `gap` above the tracked place `old`, while those frames saw open space through at least
    min_violation of old's walls (its Cv: the old place stops explaining the frames, not
    only matches fewer of them)? found: that place (default: the round's best), which must
    lie beyond the pose-jump gate of old. A place the round kept nothing at counts as
    outscored with its walls seen through.

    Carried whole offices along a corridor of identical offices (built-in 'offices', laser
    seed 1), each frame's hits still land near some wall at the old place (0.92-0.94 of
    them against 0.92 at the true one), but the round puts the true place 0.08-0.2 above
    it, the old place's Cv 0.07-0.18 against 0.000 at every correctly tracked audit. On
    the held-out laser windows a 10-frame round prefers another place by >= 0.1 in 4.6% of
    the audits while tracking (a map lacking what those frames saw); Cv tells them apart."""
    if not hypotheses:
        return False
    found = hypotheses[0].alignment if found is None else found
    if not tracker.pose_jumped(old, found, sensor_xy, old_mode):
        return False
    there, here = best_at(hypotheses, found, old_mode, tracker, sensor_xy), best_at(hypotheses, old, old_mode, tracker, sensor_xy)
    if there is None:
        return False
    return here is None or (there.score >= here.score + gap and here.cv >= min_violation)
