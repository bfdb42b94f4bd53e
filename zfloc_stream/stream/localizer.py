"""The streaming localizer: one object an embedded loop feeds one frame at a time.

    with Localizer(floorplan, settings) as loc:
        for frame in frames:
            est = loc.push(frame)

A push, top to bottom (_push):

1. fuse the frame into the rolling BEV, its odometry step judged (fusion.py; a jump
   restarts the map and the modes);
2. note it among the recent frames; the monitor judges it against the tracked place
   (monitor.py; a run it does not explain starts a kidnap test, relocalization.py);
3. apply the rounds that land at this frame, at join frames fixed when they started
   (scheduler.py): the tracker's update the filter bank (tracking/), then the local
   refinement follows the tracked mode (estimation/local_refinement.py);
4. every k fused frames, start a round (a RoundJob: what it works on) and beside it the
   kidnap test's or the audit's; between rounds the local refinement follows the drift;
5. decide the frame's status (tracking/status.py) and report it (estimate.Estimate).
"""

from __future__ import annotations

import threading
import time
import warnings
from copy import deepcopy
from dataclasses import replace

import numpy as np

from ..backbones.perception import Perception
from ..settings.loading import Settings
from ..errors import UsageError, ZflocError
from ..estimate import Alternative, Estimate, Status
from ..estimation.local_refinement import LocalRefinement
from ..estimation.scoring import scoring_kernels
from ..plans.floorplan import Floorplan
from ..frames import CameraFrame, LaserFrame
from ..frontend.bev import RollingBEV
from .recovery import KidnapTest, Places, Verdict
from .relocalization import Relocalization
from .map_match import MapMatch
from .monitor import ConsistencyMonitor
from .recent_frames import RecentFrames
from .fusion import Fusion
from .odometry_jump import JUMPED
from ..prior import Prior, PriorWatch
from .scheduler import RoundJob, RoundOutcome, RoundScheduler, ScheduledRound
from ..tracking.filter_bank import HypothesisTracker
from ..tracking import policy
from ..tracking.status import Recovery, Rule


class Localizer:
    """Localizes a stream of frames on one floorplan, online: `push(frame)` fuses a
    camera or laser frame (frames.CameraFrame / frames.LaserFrame, with its odometry
    pose) and returns an estimate.Estimate for it at once: status, pose in the floorplan
    frame, covariance, score, confidence and the rival places. Use it as a context
    manager (or call close()) so a round running on a worker thread is stopped.

    floorplan: plans.floorplan.Floorplan (plans.loading.load_floorplan reads a ROS map YAML, an
    image or a DXF/SVG/GeoJSON drawing). settings: settings.loading.Settings (defaults when None).
    Deterministic for given settings (settings.seed) and frames.
    """

    def __init__(self, floorplan: Floorplan, settings: Settings | None = None, perception: Perception | None = None,
                 prior: Prior | None = None):
        """perception: the networks for RGB-only camera frames; by default made from
        settings.backbones when the first such frame arrives (a replay of a session whose
        frames carry depth never loads them).

        prior: where the first pushed frame is, as the caller knows it (prior.Prior: a pose
        with standard deviations, a region, or both; AMCL's initial pose). It replaces
        settings.prior's (so `self.settings` records it, and a session log with it); None:
        settings.prior's, by default none (a global search). set_initial_pose gives one at
        any later time."""
        self.settings = settings or Settings()
        if prior is not None:
            if not isinstance(prior, Prior):
                raise ZflocError(f"Localizer: prior must be a zfloc_stream.prior.Prior, got {type(prior).__name__}")
            self.settings = self.settings.model_copy(update={"prior": self.settings.prior.model_copy(update=prior.settings_update())})
        self.floorplan = floorplan
        # the scorer backend (scoring.backend: the compiled FloorplanScorer or torch's) is
        # chosen and built once, here: a missing [torch] extra or a bad device is one error
        # now, not at the first round; rounds find it in the per-floorplan cache
        scoring_kernels(floorplan, self.settings.estimator.scoring)
        self.bev = RollingBEV(self.settings)
        self.fusion = Fusion(self.bev, self.settings, perception)  # fusion.py: frames into the BEV, odometry steps judged
        self.tracker = HypothesisTracker(self.settings.tracking)
        self.frames_pushed = 0
        self.last_result = None  # LocalizationResult of the latest round, for logging
        self.last_observation = None  # BevObservation of the latest round, for overlays
        self.last_round: RoundOutcome | None = None  # the latest applied round, with its stage timings
        self.rounds = RoundScheduler(floorplan, self.settings)
        self.monitor, self.local = self._place_checks()
        self.map_match = MapMatch(floorplan, self.settings.localizer, self.settings.tracking)
        if self.settings.localizer.odometry_scale == "metric" and not self.local.metric_odometry:
            # measured: monocular camera windows at a free scale 60% against 92% at the prior
            warnings.warn(f"localizer.odometry_scale 'metric' applies at estimator.scale_mode 'prior' only: at "
                          f"'{self.settings.estimator.scale_mode}' the depth and the odometry share one scale, so a depth "
                          f"network's scale error goes uncorrected", stacklevel=2)
        self.recent = RecentFrames(self.settings.localizer.local_frames)  # what the last local_frames fused frames left
        self.relocalization = Relocalization(self.settings)  # the kidnap test and the audit (relocalization.py)
        self._preview: HypothesisTracker | None = None  # reported while the tracker has no pose (_show_preview)
        self.last_rule: Rule | None = None  # why the latest estimate has its status (tracking/status.py)
        self.odometry_jumps = 0  # odometry jumps found (odometry_jump.py): each restarted the map and the hypotheses
        self._jumped_at = -1  # frame of the latest odometry jump: rounds started before it are dropped
        self._push_lock = threading.Lock()  # held by the running push: a second thread's push is refused
        self._closed = False

        self._prior = PriorWatch.of(prior if prior is not None else Prior.from_settings(self.settings.prior), self.settings)
        self._reset_at = 0  # rounds started before this frame were for a tracker set_prior replaced: dropped

    # ------------------------------------------------------------------------------
    def push(self, frame: CameraFrame | LaserFrame) -> Estimate:
        """Fuse the frame, watch it against the tracked alignment, apply the rounds due at
        this frame, start a round every k fused frames, decide its status, report.

        One thread feeds a localizer: its frames are one stream, in order. A push that
        starts while another thread's push runs raises UsageError at once (the running one
        is untouched); so does a push after close(). The frame's arrays may be reused by
        the caller as soon as push returns: what the localizer keeps, it copies."""
        if self._closed:
            raise UsageError("Localizer.push after close(): its round worker is stopped; make a new Localizer")
        if not self._push_lock.acquire(blocking=False):
            raise UsageError("Localizer.push while another thread's push is running: one thread feeds a localizer, "
                             "its frames in order")
        try:
            if self._closed:  # closed by another thread while this push waited to start
                raise UsageError("Localizer.push after close(): its round worker is stopped; make a new Localizer")
            return self._push(frame)
        finally:
            self._push_lock.release()

    def _push(self, frame: CameraFrame | LaserFrame) -> Estimate:
        """One frame, top to bottom (the module docstring's steps 1-5)."""
        index = self.frames_pushed
        self.frames_pushed += 1
        timings: dict[str, float] = {}
        plane_pose, skipped = self.fusion.fuse(frame, timings)
        step = None if plane_pose is None else self.fusion.judge_step(plane_pose)  # (SUSPECT or JUMPED, why) or None
        if step is not None and step[0] == JUMPED:
            plane_pose = self._restart_after_jump(frame, index)
        if plane_pose is not None:
            self._note_frame(index, plane_pose)
        # a round due here is applied even on a skipped frame: the join frame is fixed
        reasons = [None if step is None else step[1], *self._apply_landed(index, timings)]
        if plane_pose is not None:
            reasons += self._start_rounds(index, plane_pose, timings)
        return self._estimate(index, getattr(frame, "timestamp", float("nan")), plane_pose, timings, skipped,
                              "; ".join(r for r in reasons if r) or None, suspect=step is not None)

    def _note_frame(self, index: int, plane_pose: np.ndarray) -> None:
        """A fused frame: a pending prior describes it, it joins the recent frames, and the
        monitor judges it against the tracked place (as reported: the local refinement's);
        a run it does not explain raises the alarm: a kidnap test, or a global search."""
        self._prior.bind(index, plane_pose)
        self.recent.add(self.bev.last_wall_hits, plane_pose[:2], self.bev.last_contradiction)
        tracked = self.tracker.best if self.tracker.status is Status.TRACKING else None
        if self.monitor.wants_global_search(None if tracked is None else tracked.id,
                                            None if tracked is None else self.local.alignment_of_mode(tracked),
                                            self.local.frame_hits(self.bev.last_wall_hits, plane_pose[:2], tracked)):
            if not self.relocalization.alarm(self.bev.stamp, self.recent.contradiction, tracked.id):
                self.rounds.request_global_search()

    def _restart_after_jump(self, frame, index: int) -> np.ndarray:
        """The odometry jumped (policy.PolicyRule.ODOMETRY_JUMP): the map and every alignment
        belong to the odometry frame before it. The BEV starts again from this frame, the
        tracker is lost with no mode (a new one needs confirm_rounds_after_loss hits), rounds
        started before are dropped, an active prior is released; gravity stays. Returns the
        frame's plane pose in the restarted map."""
        plane_pose = self.fusion.restart(frame)
        self._restart(lost=True)
        self._prior.release()
        self.recent.clear()
        self._jumped_at = index
        self.odometry_jumps += 1
        return plane_pose

    # ------------------------------------------------------------------------------
    def set_initial_pose(self, x: float, y: float, theta: float, sigma_xy: float = 1.0,
                         sigma_theta: float = np.radians(15.0), region=None) -> None:
        """AMCL's /initialpose: the next pushed frame is at (x, y, theta) in the floorplan
        (metres, radians), with these standard deviations (region: also inside this
        polygon). The hypotheses restart from it (set_prior)."""
        self.set_prior(Prior.at(x, y, theta, sigma_xy, sigma_theta, region))

    def set_region(self, region) -> None:
        """The next pushed frame lies inside this region: a polygon ((N, 2) vertices, m) or a
        box (x0, y0, x1, y1). The hypotheses restart from it (set_prior)."""
        self.set_prior(Prior.within(region))

    def set_prior(self, prior: Prior | None) -> None:
        """Replace the prior at any time (None: none, a global search). As AMCL's
        /initialpose, the hypotheses restart: the tracker, a running kidnap test and the
        rounds in flight are dropped; the BEV (what odometry has fused) stays. The prior
        describes the next pushed frame. A prior given here is not in self.settings (a
        session log records the construction's prior only)."""
        if prior is not None and not isinstance(prior, Prior):
            raise ZflocError(f"set_prior: prior must be a zfloc_stream.prior.Prior or None, got {type(prior).__name__}")
        self._prior = PriorWatch.of(prior, self.settings)
        self._restart()
        self._reset_at = self.frames_pushed

    def _restart(self, lost: bool = False) -> None:
        """Drop every hypothesis and what followed them (the preview, a kidnap test, the audit's doubt, the
        monitor, the local refinement): a new prior, one the frames contradicted, or (lost) an odometry jump,
        after which the tracker reports `lost` and a new mode needs confirm_rounds_after_loss hits."""
        if lost:
            self.tracker.declare_lost()
        else:
            self.tracker = HypothesisTracker(self.settings.tracking)
        self._preview = None
        self.relocalization.reset()
        self.monitor, self.local = self._place_checks()

    def _place_checks(self) -> tuple[ConsistencyMonitor, LocalRefinement]:
        """A new monitor and local refinement: what follows the tracked place, from scratch."""
        return (ConsistencyMonitor(self.floorplan, self.settings.localizer),
                LocalRefinement(self.floorplan, self.settings.localizer, self.settings.estimator))

    @property
    def prior(self) -> str | None:
        """The prior's state (Estimate.prior): None, pending, active, released or contradicted."""
        return self._prior.state

    @property
    def perception(self) -> Perception | None:
        """The networks for RGB-only camera frames (None until a frame first needs them)."""
        return self.fusion.perception

    @property
    def frames_fused(self) -> int:
        return self.fusion.frames_fused

    @property
    def kidnap_tests(self) -> int:
        """Kidnap tests the monitor started (the tracked place stopped explaining the frames)."""
        return self.relocalization.tests

    @property
    def kidnaps_found(self) -> int:
        """Kidnap tests adopted: another place was tracked."""
        return self.relocalization.found

    @property
    def audit_tests(self) -> int:
        """Kidnap tests an audit started (audit.py; not in kidnap_tests)."""
        return self.relocalization.audit.tests

    @property
    def kidnap_test(self) -> KidnapTest | None:
        """The running kidnap test (recovery.py), None when none runs."""
        return self.relocalization.test

    def close(self) -> None:
        """Stop the round worker (scheduler.RoundScheduler.close); later pushes raise
        UsageError. Closing twice is harmless."""
        self._closed = True
        self.rounds.close()

    def __enter__(self) -> "Localizer":
        if self._closed:
            raise UsageError("a closed Localizer cannot be entered again: make a new Localizer")
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------------------
    def _start_rounds(self, index: int, plane_pose: np.ndarray, timings: dict) -> list[str | None]:
        """Start the rounds due at this frame (RoundScheduler.due): the tracker's, and beside
        it the kidnap test's or the audit's (relocalization.py); an inline one lands at once.
        Between rounds the local refinement follows the drift every local_every_k_frames
        fused frames. Returns why the rounds that landed did not run."""
        previewed = self._preview is not None and self._preview.best is not None
        mode = self.rounds.due(self.frames_fused, self.tracker.best is not None, previewed)
        if mode is None:
            k = self.settings.localizer.local_every_k_frames
            if k and self.frames_fused % k == 0:
                self._refine_locally(timings)
            return []
        self._start_round(mode, self._tracking_job(index), plane_pose, timings)
        beside = None if mode == "preview" else self.relocalization.job(index, self.tracker, self.local, self.bev.stamp)
        if beside is not None:
            self._start_round(mode, beside, plane_pose, timings)
        return self._apply_landed(index, timings)

    def _tracking_job(self, index: int) -> RoundJob:
        """The tracker's round: on the whole BEV, warm-started from the live modes; narrowed to a confidently
        tracked mode unless a global search is asked for or a prior is active (checked against elsewhere)."""
        prior = self._prior.for_round
        tracked = self.tracker.confidently_tracking and not self.rounds.global_search_wanted and prior is None
        return RoundJob(index, None, self.tracker.warm_start(), tracked, prior=prior, revisit=tuple(self.tracker.runners_up))

    def _start_round(self, mode: str, job: RoundJob, plane_pose: np.ndarray, timings: dict) -> None:
        """Start the round `job` describes on what the BEV holds now (since job.since), where
        `mode` says; one leaving this thread gets a copy of the grid, which changes under it
        (round_start: the time to hand it over). A BEV too thin to trust skips the round."""
        t0 = time.perf_counter()
        copy = self.rounds.on_worker(mode)
        try:
            snapshot = self.bev.snapshot(copy=copy, since=job.since)
        except ZflocError:
            snapshot = None
        self.rounds.start(mode, replace(job, snapshot=snapshot), plane_pose)
        if copy:
            timings["round_start"] = time.perf_counter() - t0

    def _places(self) -> Places:
        """What a kidnap test and an audit judge places on, as things are now."""
        return Places(self.tracker, self.monitor, self.local, self.recent, self.settings.localizer)

    def _audit_round(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """An audit's round landed: if it scores another place audit_margin above the tracked
        one on the recent frames (audit.py), a kidnap test starts on them, this round its first."""
        old = self.tracker.tracked_mode
        if self.relocalization.test is not None or old is None:
            return None  # a test already runs, or nothing is tracked any more: nothing to audit
        if outcome.result is None:
            return outcome.skipped
        if self.relocalization.audit_starts_test(scheduled, outcome, old, self._places(), self.bev.stamp,
                                                 self.recent.contradiction):
            return self._kidnap_round(scheduled, outcome, timings)
        return None

    def _apply_landed(self, index: int, timings: dict) -> list[str | None]:
        """Apply the rounds whose join frame is this one (RoundScheduler.landed), oldest
        first; for each, why it did not run (None: it did)."""
        return [self._apply(scheduled, outcome, timings) for scheduled, outcome in self.rounds.landed(index, timings)]

    def _apply(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """A round lands: the tracker updates as of the frame the round started at, then the
        local refinement follows the tracked mode. Returns why the round did not run (None
        when it did)."""
        if not scheduled.job.audit:  # an audit is a side check, not the round the estimate reports on
            self.last_round = outcome
        if scheduled.job.index < self._jumped_at:
            return "round started before an odometry jump: dropped"
        if scheduled.job.index < self._reset_at:
            return "round started before the prior was set: dropped"
        if scheduled.preview:
            return self._show_preview(scheduled, outcome, timings)
        if scheduled.job.audit:
            if scheduled.job.index < self.relocalization.adopted_at:
                return "round started before a kidnap was found: dropped"
            return self._audit_round(scheduled, outcome, timings)
        if scheduled.job.since:
            return self._kidnap_round(scheduled, outcome, timings)
        if scheduled.job.index < self.relocalization.adopted_at:
            return "round started before a kidnap was found: dropped"
        if outcome.observation is None:
            return outcome.skipped
        self.last_observation = outcome.observation
        if outcome.result is None:
            return outcome.skipped
        self.last_result = outcome.result
        t0, c0 = time.perf_counter(), time.thread_time()
        weighed = self._prior.weigh(outcome.result.hypotheses)
        if weighed.contradicted:  # the tracker's modes were weighed by the prior: it starts over on the evidence
            self._restart()
        self.tracker.update(weighed.hypotheses, scheduled.plane_pose[:2], scheduled.job.index, head_start=weighed.head_start)
        tracked = self.tracker.tracked_mode
        self._prior.after_round(None if tracked is None else tracked.alignment, 0 if tracked is None else tracked.tracked_rounds)
        timings["tracking"] = outcome.timings["tracking"] = time.perf_counter() - t0
        outcome.cpu_timings["tracking"] = time.thread_time() - c0
        if self.tracker.best is not None:
            self._preview = None  # the tracker's own pose from now on
        self._refine_locally(timings, outcome)
        self._kidnap_found(self.relocalization.left_behind(self.tracker, scheduled), timings, outcome)
        return None

    def _show_preview(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """A preview round landed (scheduler.py): what a copy of the tracker makes of it is
        reported while the tracker has no pose; the round of this frame, on all its frames,
        updates the tracker itself when it lands."""
        if outcome.result is None:
            self._preview = None  # each preview replaces the last, one that found nothing too
            return outcome.skipped
        self.last_observation, self.last_result = outcome.observation, outcome.result
        t0 = time.perf_counter()
        self._preview = deepcopy(self.tracker)
        weighed = self._prior.weigh(outcome.result.hypotheses, judge=False)  # one round on fewer frames: no verdict
        self._preview.update(weighed.hypotheses, scheduled.plane_pose[:2], scheduled.job.index, head_start=weighed.head_start)
        timings["tracking"] = outcome.timings["tracking"] = time.perf_counter() - t0
        return None

    # ------------------------------------------------------------------------------
    def _kidnap_round(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """A kidnap test's round landed: adopt its bank, go on, or end the test (why the round did not count)."""
        test = self.relocalization.test
        verdict = self.relocalization.feed(scheduled, outcome, self.tracker.best, self._places())
        if verdict is None:
            return "kidnap test over: its last round is dropped"
        if outcome.result is not None:
            self.last_observation, self.last_result = outcome.observation, outcome.result
        if verdict is Verdict.CARRIED_OFF:
            self.tracker = test.tracker
            self._kidnap_found(test.since, timings, outcome)
            return None
        if verdict is Verdict.NOT_CARRIED_OFF:  # no better place: the tracker keeps its modes, unless they left it
            self._kidnap_found(self.relocalization.left_behind(self.tracker, scheduled), timings, outcome)
            return "kidnap test ended: no other place earned tracking"
        return outcome.skipped

    def _kidnap_found(self, since: int | None, timings: dict, outcome: RoundOutcome) -> None:
        """A kidnap found (since: a BEV stamp; None: none): the BEV forgets what frames before it saw."""
        if since is not None:
            self.bev.forget_before(since)
            self.monitor, self.local = self._place_checks()
            self._refine_locally(timings, outcome)

    def _refine_locally(self, timings: dict, outcome: RoundOutcome | None = None) -> None:
        t0, c0 = time.perf_counter(), time.thread_time()
        self.local.update(self.tracker.best, self.recent.hits, self.frames_fused, self.recent.cameras, self.tracker.pose_jumped)
        timings["local_refinement"] = time.perf_counter() - t0
        if outcome is not None:
            outcome.timings["local_refinement"] = timings["local_refinement"]
            outcome.cpu_timings["local_refinement"] = time.thread_time() - c0

    # ------------------------------------------------------------------------------
    def _estimate(self, index, timestamp, plane_pose, timings, skipped=None, round_skipped=None, suspect=False) -> Estimate:
        shown = self._preview if self._preview is not None and self.tracker.best is None else self.tracker
        best = shown.best
        pose = cov = alignment = None
        score = float("nan")
        if best is not None and plane_pose is not None:
            alignment, score = self.local.alignment_of_mode(best), float(best.score)
            pose, cov = np.array(alignment.apply_pose(*plane_pose)), shown.pose_covariance(plane_pose[:2], plane_pose[2], mode=best)
        # one decision (tracking/status.py): the frame's evidence, a kidnap test, a doubtful step, the audit's doubt may withhold it
        consistent = None if alignment is None else self.monitor.frame_consistent(
            alignment, self.local.frame_hits(self.bev.last_wall_hits, plane_pose[:2], best), best.id)
        explained = self.map_match.share(alignment, self.last_observation)  # does the map explain the BEV at all?
        (status, self.last_rule), confidence = shown.judge_frame(
            alignment, None if plane_pose is None else plane_pose[:2], consistent, explained,
            Recovery(self.relocalization.test is not None, suspect, shown is self.tracker and self.relocalization.doubts(best)),
            self._prior.doubted, None if shown is self.tracker else self.tracker.round_facts)
        # no place the map explains, none tracked: the prior's own pose stands in (AMCL's initial pose)
        unexplained = alignment is None or not policy.map_explains(explained, self.settings.tracking)
        held = self._prior.stand_in(plane_pose, self.settings.estimator) \
            if unexplained and plane_pose is not None and self.tracker.tracked_mode is None else None
        if held is not None:
            (alignment, pose, cov, confidence), score, self.last_rule = held, float("nan"), Rule.PRIOR_POSE
            status, explained = Status.LOST if status is Status.LOST else Status.INITIALIZING, None  # no place to judge the map by
        self.map_match.note(explained, status)
        alternatives = () if plane_pose is None else shown.estimate_alternatives(plane_pose[:2], plane_pose[2])
        if alternatives and pose is not None and held is None:  # the reported mode as reported: its locally refined pose
            alternatives = (Alternative(alignment, pose, alternatives[0].weight, alternatives[0].score),) + alternatives[1:]
        return Estimate(index, float(timestamp), status, pose, cov, alignment, score, alternatives, timings, skipped, round_skipped,
                        confidence, self._prior.state)
