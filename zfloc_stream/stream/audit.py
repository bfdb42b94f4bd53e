"""The audit (localizer.audit_frames): is the tracked place still the best one for what the
recent frames saw alone?

The monitor (monitor.py) catches a tracked place that stops explaining the frames. A wrong
place can go on explaining them: carried whole offices along a corridor of identical
offices, each frame's hits still land near some wall at the old place. So at every round
tick while a mode is tracked and no kidnap test runs, a global search runs on what the
last audit_frames frames saw alone, warm-started from the tracked place (so that it
competes on the same evidence). When it scores another place audit_margin above the
tracked one, on frames that saw open space through the tracked place's walls
(recovery.outscored; none asked when the round also scores the tracked place below
audit_doubt_share of its usual audit score, _seen_through), a kidnap test starts on the
audited frames (recovery.py), this round its first; it adopts a place only while its
rounds still find the old place outscored (its walls seen through, always), by a place
scoring at least monitor_relative_share of the old mode's usual audit score (explains).

The audit's doubt (localizer.audit_doubt_share): an audit that scores the tracked place
below audit_doubt_share of its usual audit score (or keeps nothing there) while it scores
another place within audit_margin of it withholds `tracking` from that place until an audit no
longer finds so; so does a
kidnap test on it that ended without adopting another place (its frames were not
explained, and the tracker's rounds on the whole BEV still favour the old place out of
habit: the old frames). Carried whole offices along the built-in `offices` corridor, the
old place's audits fell to 0.59-0.80 of usual while it was still reported `tracking`.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..geometry.sim2 import Sim2
from ..settings.localizer import LocalizerSettings
from ..tracking.mode import Mode
from .recovery import Places
from .scheduler import RoundJob, RoundOutcome

# the usual audit score needs this many audits of the mode: the median of three outlasts
# one odd audit, and audits come every round tick only while no kidnap test runs (on the
# offices corridor a mode re-tracked after a kidnap had 3-4 of them before the next cut)
USUAL_MIN_AUDITS = 3


class Audit:
    def __init__(self, settings: LocalizerSettings):
        self.settings = settings
        self.tests = 0  # kidnap tests an audit started
        # the tracked mode's scores in the audits that did not outscore it (explains), and its id
        self._usual: deque[float] = deque(maxlen=settings.monitor_reference_frames)
        self._mode: int | None = None
        self._doubted: int | None = None  # the mode whose place is in doubt (doubts)

    def due(self, tracked: Mode | None, bev_stamp: int) -> bool:
        """Does this round tick (with no kidnap test running) also audit the tracked place?
        While a mode is tracked (even if a rival makes it `ambiguous` now) and the BEV holds
        audit_frames frames."""
        n = self.settings.audit_frames
        return n > 0 and tracked is not None and bev_stamp >= n

    def job(self, index: int, bev_stamp: int, tracked: Sim2 | None) -> RoundJob:
        """The audit's round: a global search on what the last audit_frames frames saw alone,
        warm-started from the tracked place as reported."""
        since = bev_stamp - self.settings.audit_frames + 1
        return RoundJob(index, None, [] if tracked is None else [tracked], False, since, audit=True)

    def outscores(self, outcome: RoundOutcome, old: Mode, sensor_xy, places: Places) -> bool:
        """An audit's round landed on the tracked mode `old`: does it score another place
        audit_margin above it (Places.outscored, with the violation _seen_through asks)? If
        not, its score at the old place joins the mode's usual audit score."""
        if old.id != self._mode:
            self._usual.clear()
            self._mode = old.id
        place = places.local.alignment_of_mode(old)
        here, there = places.best_here_and_elsewhere(outcome, place, old, sensor_xy)
        if places.outscored(outcome, old, sensor_xy, min_violation=self._seen_through(here)):
            return True
        self._doubted = old.id if self.falls_short(None if here is None else here.score,
                                                   None if there is None else there.score) else None
        if here is not None:
            self._usual.append(here.score)
        return False

    def falls_short(self, score: float | None, elsewhere: float | None) -> bool:
        """Does an audit that scored the tracked mode's place `score` (None: it kept
        nothing there) and the best place elsewhere `elsewhere` (beyond the pose-jump gate;
        None: none) doubt it: below audit_doubt_share of the mode's usual audit score (known
        after USUAL_MIN_AUDITS audits) while another place fits those frames about as well
        (within audit_margin: the tracked place is not ahead by the gap that would start a
        test the other way)? A drop alone is a map that lacks what the frames saw: on the
        shared laser windows it made 8% of the correct `tracking` frames ambiguous. An exact
        tie rule let a tie decide: carried along the offices corridor (camera seed 1), the old
        place scored 0.731 at 0.78 of its usual level against look-alikes at 0.730, and was
        `tracking` again 17 m off."""
        if self.settings.audit_doubt_share <= 0 or elsewhere is None:
            return False
        if score is None:
            return True
        return self._below_usual(score) and elsewhere >= score - self.settings.audit_margin

    def _below_usual(self, score: float) -> bool:
        """Did an audit score the tracked place below audit_doubt_share of its usual audit
        score (known after USUAL_MIN_AUDITS audits; audit_doubt_share 0: never)?"""
        share = self.settings.audit_doubt_share
        return share > 0 and len(self._usual) >= USUAL_MIN_AUDITS and score < share * float(np.median(self._usual))

    def _seen_through(self, here) -> float:
        """How much of the tracked place's walls the audited frames must have seen open space
        through (its Cv) for another place audit_margin above it to start a kidnap test:
        audit_min_violation, or none when the round scores the place (here: its best
        hypothesis there; None: none) below audit_doubt_share of its usual audit score: it
        stopped fitting what it used to fit while another place fits it better. A camera sees
        little open space through walls: carried along the offices corridor (camera seed 1,
        second cut) the old place's Cv stayed 0.00 while its audits fell to 0.74 of usual and
        the true place led by 0.16; no test started and the kidnap was never found. Only the
        start: adopting a place still asks audit_min_violation (explains); asked there too,
        a camera plan lacking what the frames saw (aces 340 #100) handed the track to a
        place 25-33 m off."""
        return 0.0 if here is not None and self._below_usual(here.score) else self.settings.audit_min_violation

    def doubt(self, mode_id: int | None) -> None:
        """A kidnap test on the tracked mode mode_id ended without adopting another
        place: its place is in doubt until an audit scores it at its usual level again."""
        if self.settings.audit_doubt_share > 0:
            self._doubted = mode_id

    def doubts(self, mode_id: int | None) -> bool:
        """Is the place of the mode mode_id (the reported one) in doubt?"""
        return mode_id is not None and mode_id == self._doubted

    def forget(self) -> None:
        """The modes were replaced (a kidnap test's bank adopted, a restart): their ids
        start again, no place is in doubt."""
        self._doubted = None
        self._usual.clear()
        self._mode = None

    def explains(self, outcome: RoundOutcome, old: Mode, sensor_xy, found: Sim2, places: Places) -> bool:
        """An audit's test adopts `found` only while its round still finds the old place
        outscored (Places.outscored) and scores found at least monitor_relative_share of the
        old mode's usual audit score (the median over its audits that did not outscore it;
        a relative level, as the monitor's). Without it, recent frames that see what the map
        lacks score the old place far below its usual level and a weak place a few metres
        off, barely better, would be adopted."""
        if not places.outscored(outcome, old, sensor_xy, found) or old.id != self._mode or not self._usual:
            return False
        there = places.best_at(outcome, found, old, sensor_xy)
        return there is not None and there.score >= self.settings.monitor_relative_share * float(np.median(self._usual))
