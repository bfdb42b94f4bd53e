"""The streaming localizer: one object an embedded loop feeds one frame at a time.

    with Localizer(floorplan, settings) as loc:
        for frame in frames:
            est = loc.push(frame)

Each push fuses the frame into the rolling BEV. Every k frames a round runs: primitives
are extracted, the live modes are re-scored and refined first (warm start), fresh minimal
samples are drawn (fewer while one mode is confidently tracked, a full global search while
initializing or lost), and the tracker updates its modes. Between rounds the pose is the
current best alignment applied to the frame's odometry-plane pose, so every frame has one.

Where and when a round runs (inline, on a worker, joined at fixed frames):
round_scheduler.py. The consistency monitor (monitor.py) watches each fused frame against
the tracked alignment; when it stops explaining them, a kidnap test (kidnap_recovery.py) asks
whether the sensor is at another place, on what those frames saw alone. The local
refinement (estimation/local_refinement.py) follows the tracked mode's drift on the recent
frames' wall hits.
"""

from __future__ import annotations

import threading
import time
import warnings
from collections import deque
from copy import deepcopy

import numpy as np

from ..backbones.perception import Perception, needs_backbones
from ..settings.loading import Settings
from ..errors import UsageError, ZflocError
from ..estimate import Alternative, Estimate, Status
from ..estimation.local_refinement import LocalRefinement
from ..estimation.scoring import scoring_kernels
from ..plans.floorplan import Floorplan
from ..frames import CameraFrame, LaserFrame
from ..frontend.bev import RollingBEV
from .recovery import KidnapTest, Verdict, best_at, better_place, outscored
from .map_match import MapMatch
from .monitor import ConsistencyMonitor
from .odometry_jump import JUMPED, OdometryJumpWatch
from ..prior import Prior, PriorWatch
from .scheduler import RoundJob, RoundOutcome, RoundScheduler, ScheduledRound
from ..geometry.sim2 import Sim2
from ..tracking.filter_bank import HypothesisTracker, Mode
from ..tracking.status import Recovery, Rule


class Localizer:
    """Localizes a stream of frames on one floorplan, online: `push(frame)` fuses a
    camera or laser frame (frames.CameraFrame / frames.LaserFrame, with its odometry
    pose) and returns an estimate.Estimate for it at once: status, pose in the floorplan
    frame, covariance, score, confidence and the rival places. Use it as a context
    manager (or call close()) so a round running on a worker thread is stopped.

    floorplan: floorplan.Floorplan (plan_loading.load_floorplan reads a ROS map YAML, an
    image or a DXF/SVG/GeoJSON drawing). settings: config.Settings (defaults when None).
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
        self.perception = perception
        self.floorplan = floorplan
        # the scorer backend (scoring.backend: the compiled FloorplanScorer or torch's) is
        # chosen and built once, here: a missing [torch] extra or a bad device is one error
        # now, not at the first round; rounds find it in the per-floorplan cache
        scoring_kernels(floorplan, self.settings.estimator.scoring)
        self.bev = RollingBEV(self.settings)
        self.tracker = HypothesisTracker(self.settings.tracking)
        self.frames_pushed = 0
        self.frames_fused = 0
        self.last_result = None  # LocalizationResult of the latest round, for logging
        self.last_observation = None  # BevObservation of the latest round, for overlays
        self.last_round: RoundOutcome | None = None  # the latest applied round, with its stage timings
        self.rounds = RoundScheduler(floorplan, self.settings)
        self.monitor = ConsistencyMonitor(floorplan, self.settings.localizer)
        self.map_match = MapMatch(floorplan, self.settings.localizer, self.settings.tracking)
        self.local = LocalRefinement(floorplan, self.settings.localizer, self.settings.estimator)
        if self.settings.localizer.odometry_scale == "metric" and not self.local.metric_odometry:
            # measured: monocular camera windows at a free scale 60% against 92% at the prior
            warnings.warn(f"localizer.odometry_scale 'metric' applies at estimator.scale_mode 'prior' only: at "
                          f"'{self.settings.estimator.scale_mode}' the depth and the odometry share one scale, so a depth "
                          f"network's scale error goes uncorrected", stacklevel=2)
        self._recent_hits: deque[np.ndarray] = deque(maxlen=max(1, self.settings.localizer.local_frames))
        self._recent_contradiction: deque[float] = deque(maxlen=self._recent_hits.maxlen)  # RollingBEV._contradiction per frame
        self._recent_cameras: deque[np.ndarray] = deque(maxlen=self._recent_hits.maxlen)  # each recent frame's plane position
        self._kidnap: KidnapTest | None = None  # the running kidnap test (kidnap_recovery.py)
        self.kidnap_tests = 0  # kidnap tests started (the monitor saw the tracked place stop explaining the frames)
        self.kidnaps_found = 0  # of them, adopted: another place was tracked
        self.audit_tests = 0  # kidnap tests an audit started (localizer.audit_frames: a better place for the recent frames)
        # the tracked mode's scores in the audits that did not outscore it (_audit_explains), and its id
        self._audit_usual: deque[float] = deque(maxlen=self.settings.localizer.monitor_reference_frames)
        self._audit_mode: int | None = None
        self._adopted_at = -1  # frame whose kidnap round was adopted last
        self._preview: HypothesisTracker | None = None  # reported while the tracker has no pose (_show_preview)
        self.last_rule: Rule | None = None  # why the latest estimate has its status (tracking/status.py)
        self.jumps = OdometryJumpWatch(self.settings)  # odometry steps the sensor cannot have made (odometry_jump.py)
        self.odometry_jumps = 0  # of them, found: each restarted the map and the hypotheses
        self._jumped_at = -1  # frame of the latest odometry jump: rounds started before it are dropped
        self._bev_fused_before = 0  # RollingBEV.frames_fused before the latest add (_judge_step)
        self._push_lock = threading.Lock()  # held by the running push: a second thread's push is refused
        self._closed = False

        self._prior = self._watch(prior if prior is not None else Prior.from_settings(self.settings.prior))
        self._reset_at = 0  # rounds started before this frame were for a tracker set_prior replaced: dropped

    # ------------------------------------------------------------------------------
    def push(self, frame: CameraFrame | LaserFrame) -> Estimate:
        """Fuse the frame, watch it against the tracked alignment, apply the rounds due at
        this frame, start a round every k fused frames, report.

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
        index, lc = self.frames_pushed, self.settings.localizer
        self.frames_pushed += 1
        timings: dict[str, float] = {}
        plane_pose, skipped = self._fuse(frame, timings)
        verdict = None if plane_pose is None else self._judge_step(plane_pose)
        if verdict is not None and verdict[0] == JUMPED:
            plane_pose = self._restart_after_jump(frame, index)
        jump = None if verdict is None else verdict[1]
        if plane_pose is not None:
            self._prior.bind(index, plane_pose)  # the frame a pending prior describes
            self._recent_hits.append(self.bev.last_wall_hits)
            self._recent_cameras.append(plane_pose[:2])
            self._recent_contradiction.append(self.bev.last_contradiction)
            # only a tracked alignment is watched, as reported (the local refinement's)
            tracked = self.tracker.best if self.tracker.status is Status.TRACKING else None
            if self.monitor.wants_global_search(None if tracked is None else tracked.id,
                                                None if tracked is None else self.local.alignment_of_mode(tracked),
                                                self.local.frame_hits(self.bev.last_wall_hits, plane_pose[:2], tracked)):
                self._start_kidnap_test()
        # a round due here is applied even on a skipped frame: the join frame is fixed
        reasons = [jump] + [self._apply(*landed, timings) for landed in self.rounds.landed(index, timings)]
        previewed = self._preview is not None and self._preview.best is not None
        mode = None if plane_pose is None else self.rounds.due(self.frames_fused, self.tracker.best is not None, previewed)
        if mode is not None:
            self.rounds.start(mode, lambda copy: self._round_job(index, copy), plane_pose, timings)
            if self._kidnap is not None and mode != "preview":  # the tracker goes on meanwhile: nothing is lost if the test fails
                self.rounds.start(mode, lambda copy: self._kidnap_job(index, copy), plane_pose, timings)
            elif mode != "preview" and self._audits():
                self.rounds.start(mode, lambda copy: self._audit_job(index, copy), plane_pose, timings)
            reasons += [self._apply(*landed, timings) for landed in self.rounds.landed(index, timings)]
        elif plane_pose is not None and lc.local_every_k_frames and self.frames_fused % lc.local_every_k_frames == 0:
            self._refine_locally(timings)  # follow the drift between rounds too
        round_skipped = "; ".join(r for r in reasons if r) or None
        return self._estimate(index, getattr(frame, "timestamp", float("nan")), plane_pose, timings, skipped, round_skipped,
                              suspect=verdict is not None)

    def _fuse(self, frame, timings: dict) -> tuple[np.ndarray | None, str | None]:
        """Fuse one frame: its plane pose, or None and why it was skipped."""
        t0 = time.perf_counter()
        if self._wants_backbones(frame):
            frame = self._perceive(frame)
            timings["backbones"] = time.perf_counter() - t0
            t0 = time.perf_counter()
        if isinstance(frame, CameraFrame) and frame.depth is None:
            if self.perception is not None and self.perception.depth is not None:
                return None, f"depth network gave no depth within backbones.max_depth ({self.settings.backbones.max_depth} m)"
            return None, "camera frame has an RGB image but no depth (name a depth network: backbones.depth_model / run --depth-model)"
        try:
            self._bev_fused_before = self.bev.frames_fused
            self.bev.add(frame)
            plane_pose = np.asarray(self.bev.plane_pose(frame), dtype=float)
        except ZflocError as err:  # one bad frame never kills the stream
            return None, str(err)
        self.frames_fused += 1
        timings["fusion"] = time.perf_counter() - t0
        return plane_pose, None

    def _judge_step(self, plane_pose: np.ndarray) -> tuple[str, str] | None:
        """The odometry-jump watch's verdict on this frame's step (odometry_jump.py):
        None, or (SUSPECT or JUMPED, why). Judged on a frame fused alone (a camera frame
        that waited for gravity is fused with the buffer: its step and hits are not its
        own), else recent motion starts again."""
        if self.bev.frames_fused != self._bev_fused_before + 1:
            self.jumps.restart(plane_pose)
            return None
        return self.jumps.judge(plane_pose, self.bev.last_known_hits, self.bev.last_contradiction, len(self.bev.last_wall_hits))

    def _restart_after_jump(self, frame, index: int) -> np.ndarray:
        """The odometry jumped (tracking_policy.ODOMETRY_JUMP): the map and every
        alignment belong to the odometry frame before the jump. The BEV starts again from
        this frame, the tracker is lost with no mode (a new one needs
        confirm_rounds_after_loss hits), rounds started before are dropped, an active prior
        is released (it was bound in the cleared map); gravity stays.
        Returns the frame's plane pose in the restarted map."""
        self.bev.clear_map()
        self.bev.add(frame)  # it was fused once already: the same frame cannot fail now
        plane_pose = np.asarray(self.bev.plane_pose(frame), dtype=float)
        self.jumps.restart(plane_pose)
        self._restart(lost=True)
        self._prior.release()  # it was bound in the cleared map
        for recent in (self._recent_hits, self._recent_contradiction, self._recent_cameras):
            recent.clear()
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
        self._prior = self._watch(prior)
        self._restart()
        self._reset_at = self.frames_pushed

    def _watch(self, prior: Prior | None) -> PriorWatch:
        return PriorWatch(prior, self.settings.prior, self.settings.tracking.confirm_rounds, self.settings.tracking.weight_gain)

    def _restart(self, lost: bool = False) -> None:
        """Drop every hypothesis and what followed them (the preview, a kidnap test, the
        monitor, the local refinement): a new prior, one the frames contradicted, or (lost)
        an odometry jump, after which the tracker reports `lost` and a new mode needs
        confirm_rounds_after_loss hits (HypothesisTracker.declare_lost)."""
        if lost:
            self.tracker.declare_lost()
        else:
            self.tracker = HypothesisTracker(self.settings.tracking)
        self._preview, self._kidnap = None, None
        self.monitor = ConsistencyMonitor(self.floorplan, self.settings.localizer)
        self.local = LocalRefinement(self.floorplan, self.settings.localizer, self.settings.estimator)

    @property
    def prior(self) -> str | None:
        """The prior's state (Estimate.prior): None, pending, active, released or contradicted."""
        return self._prior.state

    @property
    def kidnap_test(self) -> KidnapTest | None:
        """The running kidnap test (kidnap_recovery.py), None when none runs."""
        return self._kidnap

    def close(self) -> None:
        """Stop the round worker (round_scheduler.RoundScheduler.close); later pushes raise
        UsageError. Closing twice is harmless."""
        self._closed = True
        self.rounds.close()

    def __enter__(self) -> "Localizer":
        if self._closed:
            raise UsageError("a closed Localizer cannot be entered again: make a new Localizer")
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _wants_backbones(self, frame) -> bool:
        """Does a network have work on this frame? Asked of the perception when there is
        one, else of the settings (which would make one)."""
        if self.perception is not None:
            return self.perception.wants(frame)
        return needs_backbones(frame, self.settings.backbones)

    def _perceive(self, frame: CameraFrame) -> CameraFrame:
        """Network depth / labels for one frame. A model that cannot be loaded raises
        (BackboneError): that is the run's setup, not one bad frame."""
        if self.perception is None:
            self.perception = Perception.from_settings(self.settings.backbones)
        return frame if self.perception is None else self.perception.complete([frame])[0]

    # ------------------------------------------------------------------------------
    def _round_job(self, index: int, copy: bool) -> RoundJob:
        """What the round started at this frame sees (copy: it leaves this thread, and the
        grid changes under it while the stream goes on). A BEV with too little evidence
        skips the round when it is applied: the status stays as it is."""
        try:
            snapshot = self.bev.snapshot(copy=copy)
        except ZflocError:
            snapshot = None
        # an active prior keeps the rounds global: each one checks it against the best place elsewhere
        prior = self._prior.for_round
        tracked = self.tracker.confidently_tracking and not self.rounds.global_search_wanted and prior is None
        return RoundJob(index, snapshot, self.tracker.warm_start(), tracked, prior=prior)

    def _audits(self) -> bool:
        """Does this round tick also audit the tracked place (localizer.audit_frames)? While
        a mode is tracked (even if a rival makes it `ambiguous` now), no kidnap test runs,
        and the BEV holds audit_frames frames."""
        n = self.settings.localizer.audit_frames
        return n > 0 and self._kidnap is None and self.tracker.tracked_mode is not None and self.bev.stamp >= n

    def _audit_job(self, index: int, copy: bool) -> RoundJob:
        """The audit's round: a global search on what the last audit_frames frames saw alone,
        warm-started from the tracked place (so that it competes on the same evidence)."""
        since = self.bev.stamp - self.settings.localizer.audit_frames + 1
        try:
            snapshot = self.bev.snapshot(copy=copy, since=since)
        except ZflocError:
            snapshot = None
        tracked = self.tracker.tracked_mode
        warm = [] if tracked is None else [self.local.alignment_of_mode(tracked)]
        return RoundJob(index, snapshot, warm, False, since, audit=True)

    def _better_place(self, found: Sim2, old: Mode, sensor_xy) -> bool:
        """kidnap_recovery.better_place of `found` against the old mode as it is reported: its
        hits rescaled under metric odometry (else the recent hits themselves)."""
        return better_place(found, self.local.alignment_of_mode(old), old, self.tracker, self.monitor, list(self._recent_hits),
                            sensor_xy, [self.local.frame_hits(h, c, old) for h, c in zip(self._recent_hits, self._recent_cameras)]
                            if self.local.metric_odometry else None)

    def _outscored(self, outcome: RoundOutcome, old: Mode, sensor_xy, found: Sim2 | None = None) -> bool:
        """kidnap_recovery.outscored: the round (on recent frames alone) scores another place
        (found, default its best) audit_margin above the tracked one as reported, and that
        place explains the recent frames' hits as the monitor wants."""
        if outcome.result is None or not outcome.result.hypotheses:
            return False
        found = outcome.result.hypotheses[0].alignment if found is None else found
        lc = self.settings.localizer
        if not outscored(outcome.result.hypotheses, self.local.alignment_of_mode(old), old, self.tracker, sensor_xy,
                         lc.audit_margin, lc.audit_min_violation, found):
            return False
        hits = [h for h in self._recent_hits if len(h)]
        share = None if not hits else self.monitor.share(found, np.concatenate(hits))
        return share is not None and self.monitor.explains(share, self.monitor.usual_share(old.id))

    def _audit_explains(self, outcome: RoundOutcome, old: Mode, sensor_xy, found: Sim2) -> bool:
        """An audit's test adopts `found` only while its round still finds the old place
        outscored (_outscored) and scores found at least monitor_relative_share of the old
        mode's usual audit score (the median over its audits that did not outscore it; a
        relative level, as the monitor's). In the held-out laser window aces 291 #100 the
        recent frames saw what the map lacks: the old place fell from 0.78-0.84 to -0.06
        and a place 4-8 m off, at 0.15, was adopted."""
        if not self._outscored(outcome, old, sensor_xy, found) or old.id != self._audit_mode or not self._audit_usual:
            return False
        there = best_at(outcome.result.hypotheses, found, old, self.tracker, sensor_xy)
        return there is not None and there.score >= self.settings.localizer.monitor_relative_share * float(np.median(self._audit_usual))

    def _audit_round(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """An audit's round landed: if it scores another place audit_margin above the
        tracked one on the recent frames (_outscored), a kidnap test starts on the audited
        frames, this round its first."""
        old = self.tracker.tracked_mode
        if self._kidnap is not None or old is None:
            return None  # a test already runs, or nothing is tracked any more: nothing to audit
        if outcome.result is None:
            return outcome.skipped
        if old.id != self._audit_mode:
            self._audit_usual.clear()
            self._audit_mode = old.id
        if not self._outscored(outcome, old, scheduled.plane_pose[:2]):
            here = best_at(outcome.result.hypotheses, self.local.alignment_of_mode(old), old, self.tracker, scheduled.plane_pose[:2])
            if here is not None:
                self._audit_usual.append(here.score)
            return None
        self._kidnap = KidnapTest.start(self.bev.stamp, self.settings, max(self._recent_contradiction, default=0.0),
                                        since=scheduled.job.since, audit=True)
        self.audit_tests += 1  # not in kidnap_tests: those the monitor started
        return self._kidnap_round(scheduled, outcome, timings)

    def _kidnap_job(self, index: int, copy: bool) -> RoundJob:
        """The kidnap test's round: a global search on what the frames since its run saw."""
        try:
            snapshot = self.bev.snapshot(copy=copy, since=self._kidnap.since)
        except ZflocError:
            snapshot = None
        return self._kidnap.job(index, snapshot, self.tracker.best)

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
            if scheduled.job.index < self._adopted_at:
                return "round started before a kidnap was found: dropped"
            return self._audit_round(scheduled, outcome, timings)
        if scheduled.job.since:
            return self._kidnap_round(scheduled, outcome, timings)
        if scheduled.job.index < self._adopted_at:
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
        return None

    def _show_preview(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """A preview round landed (round_scheduler.py): what a copy of the tracker makes of
        it is reported while the tracker itself has no pose. The tracker never sees it: the
        round of this frame, on all of its frames, updates the tracker when it lands."""
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
    def _start_kidnap_test(self) -> None:
        """The monitor saw the tracked place stop explaining the frames. If a recent frame
        contradicted what older frames saw, test whether the sensor was carried off
        (kidnap_recovery.py); else it walked into what the map lacks, and the next round
        searches globally on the whole BEV."""
        contradiction = max(self._recent_contradiction, default=0.0)
        if self._kidnap is not None and not self._kidnap.audit:
            return
        if contradiction >= self.settings.localizer.kidnap_contradiction:
            # the monitor's test replaces an audit's: its frames start after the discontinuity
            # (the apartment carried off: the audit's test, on frames from 5 before the cut,
            # adopted nothing; the monitor's, started 2 frames later, adopts 20 frames after the cut)
            self._kidnap = KidnapTest.start(self.bev.stamp, self.settings, contradiction)
            self.kidnap_tests += 1
        else:
            self.rounds.request_global_search()

    def _kidnap_round(self, scheduled: ScheduledRound, outcome: RoundOutcome, timings: dict) -> str | None:
        """A kidnap test's round landed: adopt its bank (the BEV forgets what only older
        frames saw), go on, or end the test. Returns why the round did not count."""
        test, old = self._kidnap, self.tracker.best
        if test is None or test.since != scheduled.job.since:
            return "kidnap test over: its last round is dropped"
        if outcome.result is not None:
            self.last_observation, self.last_result = outcome.observation, outcome.result
        # a place explaining more of the recent hits; one an audit started also needs its own
        # round to still find the old place outscored, by a place that explains the test's
        # frames about as well as the tracked mode explained its BEV (audit_explains)
        verdict = test.feed(scheduled, outcome, lambda found: old is None or (
            self._better_place(found.alignment, old, scheduled.plane_pose[:2])
            and (not test.audit or self._audit_explains(outcome, old, scheduled.plane_pose[:2], found.alignment))))
        if verdict is Verdict.CARRIED_OFF:
            self.tracker, self._kidnap = test.tracker, None
            self.kidnaps_found += 1
            self._adopted_at = scheduled.job.index  # rounds started before this worked for the old place
            self.bev.forget_before(test.since)
            self.monitor = ConsistencyMonitor(self.floorplan, self.settings.localizer)
            self.local = LocalRefinement(self.floorplan, self.settings.localizer, self.settings.estimator)
            self._refine_locally(timings, outcome)
            return None
        if verdict is Verdict.NOT_CARRIED_OFF:
            # the test's global searches found no better place: the frames saw what the map
            # lacks, and the tracker, which went on meanwhile, keeps its modes
            self._kidnap = None
            return "kidnap test ended: no other place earned tracking"
        return outcome.skipped

    def _refine_locally(self, timings: dict, outcome: RoundOutcome | None = None) -> None:
        t0, c0 = time.perf_counter(), time.thread_time()
        self.local.update(self.tracker.best, self._recent_hits, self.frames_fused, self._recent_cameras)
        timings["local_refinement"] = time.perf_counter() - t0
        if outcome is not None:
            outcome.timings["local_refinement"] = timings["local_refinement"]
            outcome.cpu_timings["local_refinement"] = time.thread_time() - c0

    # ------------------------------------------------------------------------------
    def _estimate(self, index, timestamp, plane_pose, timings, skipped=None, round_skipped=None, suspect=False) -> Estimate:
        shown = self._preview if self._preview is not None and self.tracker.best is None else self.tracker
        best = shown.best
        if best is None or plane_pose is None:
            pose = cov = alignment = None
            score = float("nan")
        else:
            alignment = self.local.alignment_of_mode(best)
            pose = np.array(alignment.apply_pose(*plane_pose))
            cov = shown.pose_covariance(plane_pose[:2], plane_pose[2], mode=best)
            score = float(best.score)
        # the frame's own evidence (its hits, the pose's step) can withhold `tracking`; so can the
        # run of frames the monitor saw, until the kidnap test ends, and an odometry step the
        # sensor cannot have made (odometry_jump.py); one decision (tracking/status.py)
        consistent = None if alignment is None else self.monitor.frame_consistent(
            alignment, self.local.frame_hits(self.bev.last_wall_hits, plane_pose[:2], best), best.id)
        explained = self.map_match.share(alignment, self.last_observation)  # does the map explain the BEV at all?
        (status, self.last_rule), confidence = shown.judge_frame(
            alignment, None if plane_pose is None else plane_pose[:2], consistent, explained,
            Recovery(kidnap_test=self._kidnap is not None, odometry_step=suspect), self._prior.doubted,
            None if shown is self.tracker else self.tracker.round_facts)
        self.map_match.note(explained, status)
        alternatives = () if plane_pose is None else shown.estimate_alternatives(plane_pose[:2], plane_pose[2])
        if alternatives and pose is not None:  # the reported mode as reported: its locally refined pose
            first = alternatives[0]
            alternatives = (Alternative(alignment, pose, first.weight, first.score),) + alternatives[1:]
        return Estimate(index, float(timestamp), status, pose, cov, alignment, score, alternatives, timings, skipped, round_skipped,
                        confidence, self._prior.state)
