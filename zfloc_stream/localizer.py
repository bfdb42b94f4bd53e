"""The streaming localizer: one object an embedded loop feeds one frame at a time.

    with Localizer(floorplan, settings) as loc:
        for frame in frames:
            est = loc.push(frame)

Each push fuses the frame into the rolling BEV. Every k frames a round runs: primitives
are extracted, the live modes are re-scored and refined first (warm start), fresh minimal
samples are drawn (fewer while one mode is confidently tracked, a full global search while
initializing or lost), and the tracker updates its modes. Between rounds the pose is the
current best alignment applied to the frame's odometry-plane pose, so every frame has one.

Where the round runs (localizer.pipeline): inline, inside the push of the frame i that
starts it and applied there; or pipelined, on one worker beside the stream and applied at
frame i + round_delay exactly (that push waits if the worker is late), never "when it is
ready", so a run is deterministic. online (the default) is inline while no pose exists and
nothing is pending (the first fix lands as early as inline gives it) and pipelined after.
A round works on what it saw at frame i: a copy of the BEV grid, the tracker's warm starts
and search mode, its rng (seeded by i), and at the join the tracker is updated with frame
i's sensor position and index. `delayed` computes
the round inline at frame i and applies it at the same join frame: bit for bit the
pipelined results without a worker. close() (or leaving the `with`) stops the worker;
rounds whose join frame no frame reached are dropped: the last estimate stays the last
state, which is also what a replay of the session reproduces.
"""

from __future__ import annotations

import multiprocessing
import time
from collections import deque
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from . import threads
from .backbones.perception import Perception, needs_backbones
from .config import Settings
from .errors import ZflocError
from .estimate import Alternative, Estimate
from .estimation import localize
from .estimation.ransac import LocalizationResult, alignment_of, model_rows
from .estimation.refine import refine_batch
from .estimation.scoring import floorplan_scorer, scoring_kernels
from .floorplan import Floorplan
from .heap import release_free_heap
from .frames import CameraFrame, LaserFrame
from .frontend.bev import BevSnapshot, RollingBEV
from .observation import BevObservation
from .rng import make_rng
from .sim2 import Sim2
from .tracking import HypothesisTracker


@dataclass(frozen=True)
class RoundJob:
    """What the round started at frame `index` works on, fixed at that frame."""

    index: int
    snapshot: BevSnapshot | None  # None: nothing fused into the grid yet
    warm_start: list[Sim2]
    tracked: bool  # one mode confidently tracked and no global search asked for


@dataclass
class RoundOutcome:
    index: int  # frame the round started at
    observation: BevObservation | None  # None: too little evidence, the round was skipped
    result: LocalizationResult | None  # None: skipped, or the estimator refused the BEV
    skipped: str | None = None  # why the round did not run (Estimate.round_skipped of its join frame)
    timings: dict[str, float] = field(default_factory=dict)  # wall seconds per stage
    cpu_timings: dict[str, float] = field(default_factory=dict)  # CPU seconds per stage (the thread that ran it)
    tracked: bool = False  # the round followed a confidently tracked mode (no global search)


def run_round(floorplan, settings: Settings, job: RoundJob, beside_stream: bool = False) -> RoundOutcome:
    """Primitives + estimation of one round: a pure function of its inputs, so it gives the
    same bits on the caller's thread, a worker thread or a worker process. Afterwards the
    round's freed temporaries go back to the OS (localizer.release_memory). beside_stream:
    the round runs on a worker (estimator.threads' auto leaves the stream's core alone)."""
    with threads.limit(threads.resolve(settings.estimator.threads, beside_stream=beside_stream)):
        out = _run_round(floorplan, settings, job)
    if settings.localizer.release_memory:
        release_free_heap()
    return out


def _run_round(floorplan, settings: Settings, job: RoundJob) -> RoundOutcome:
    cfg = settings
    out = RoundOutcome(job.index, None, None, tracked=job.tracked)
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        obs = None if job.snapshot is None else job.snapshot.observation(make_rng(cfg.seed, "primitives", job.index),
                                                                       circles=len(floorplan.circles) > 0)
        out.skipped = "too little evidence: nothing fused into the BEV yet" if obs is None else lacking_evidence(obs, cfg)
    except ZflocError as err:
        obs, out.skipped = None, f"primitive extraction failed: {err}"
    out.timings["primitives"], out.cpu_timings["primitives"] = time.perf_counter() - t0, time.thread_time() - c0
    if out.skipped is not None:
        return out
    out.observation = obs
    try:
        out.result = localize(
            floorplan,
            obs,
            cfg.estimator,
            make_rng(cfg.seed, "ransac", job.index),
            scale_prior=cfg.estimator.scale_prior,
            warm_start=job.warm_start,
            iterations=cfg.estimator.ransac.tracking_iterations if job.tracked else cfg.estimator.ransac.iterations,
            global_search=not job.tracked,
        )
    except ZflocError as err:  # a round the estimator refuses is skipped, the stream goes on
        out.skipped = f"estimator error: {err}"
        return out
    out.timings.update(out.result.timings)
    out.cpu_timings.update(out.result.cpu_timings)
    return out


def lacking_evidence(obs: BevObservation, settings: Settings) -> str | None:
    """Why the BEV is too thin for a round (None when it is enough)."""
    cfg = settings.localizer
    walls, primitives = len(obs.wall_points), len(obs.lines) + len(obs.circles)
    if walls < cfg.min_wall_points:
        return f"too little evidence: {walls} wall points < localizer.min_wall_points = {cfg.min_wall_points}"
    if primitives < cfg.min_primitives:
        return f"too little evidence: {primitives} lines/circles < localizer.min_primitives = {cfg.min_primitives}"
    return None


# A worker process keeps the floorplan and settings it was started with (sent once).
_PROCESS_STATE: tuple | None = None


def _init_process(floorplan, settings: Settings) -> None:
    global _PROCESS_STATE
    _PROCESS_STATE = (floorplan, settings)


def _process_round(job: RoundJob) -> RoundOutcome:
    return run_round(*_PROCESS_STATE, job, beside_stream=True)


@dataclass
class _Pending:
    job: RoundJob
    join_at: int  # the push index whose estimate first carries the result
    plane_pose: np.ndarray  # frame job.index's sensor pose: the tracker is anchored there
    force_seq: int  # monitor requests seen when it started (a later one stays pending)
    outcome: RoundOutcome | Future


class Localizer:
    def __init__(self, floorplan: Floorplan, settings: Settings | None = None, perception: Perception | None = None):
        """perception: the networks for RGB-only camera frames; by default made from
        settings.backbones when the first such frame arrives (a replay of a session whose
        frames carry depth never loads them)."""
        self.settings = settings or Settings()
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
        self._inconsistent_frames = 0  # consecutive frames the tracked alignment does not explain
        self._consistency_memo = None  # (alignment, wall hits, explained share) of the last _frame_consistent
        self._force_global = False  # the monitor asks the next round for a full global search
        self._force_seq = 0  # how many times it asked (a request made after a round started outlives it)
        self._pending: deque[_Pending] = deque()  # rounds started, not yet applied, oldest first
        self._pool: Executor | None = None
        self.last_round: RoundOutcome | None = None  # the latest applied round, with its stage timings
        self._recent_hits: deque[np.ndarray] = deque(maxlen=max(1, self.settings.localizer.local_frames))
        self._local: tuple[int, Sim2] | None = None  # (mode id, its alignment refined on the recent hits)
        self._local_frame = 0  # frames_fused at the last local refinement
        lc = self.settings.localizer
        if lc.pipeline in ("pipelined", "online") and lc.worker == "process":
            self._executor().submit(int)  # start the process now: it takes a second or two to import

    # ------------------------------------------------------------------------------
    def push(self, frame: CameraFrame | LaserFrame) -> Estimate:
        index = self.frames_pushed
        self.frames_pushed += 1
        timings: dict[str, float] = {}
        plane_pose, skipped = self._fuse(frame, timings)
        if plane_pose is not None:
            self._recent_hits.append(self.bev.last_wall_hits)
            self._monitor()
        # a round due here is applied even on a skipped frame: the join frame is fixed
        reasons = []  # why rounds applied at this frame did not run
        while self._pending and self._pending[0].join_at <= index:
            reasons.append(self._apply(self._pending.popleft(), timings))
        lc = self.settings.localizer
        if plane_pose is not None and self.frames_fused % lc.every_k_frames == 0:
            reasons.append(self._start_round(index, plane_pose, timings))
        elif plane_pose is not None and lc.local_every_k_frames and self.frames_fused % lc.local_every_k_frames == 0:
            t0 = time.perf_counter()
            self._refine_locally()  # follow the drift between rounds too
            timings["local_refinement"] = time.perf_counter() - t0
        round_skipped = "; ".join(r for r in reasons if r) or None
        return self._estimate(index, getattr(frame, "timestamp", float("nan")), plane_pose, timings, skipped, round_skipped)

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
            self.bev.add(frame)
            plane_pose = np.asarray(self.bev.plane_pose(frame), dtype=float)
        except ZflocError as err:  # one bad frame never kills the stream
            return None, str(err)
        self.frames_fused += 1
        timings["fusion"] = time.perf_counter() - t0
        return plane_pose, None

    def close(self) -> None:
        """Stop the worker. Rounds not applied yet are dropped (no frame reached their join
        frame); the worker finishes the one it is running first."""
        self._pending.clear()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self) -> "Localizer":
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
    def _start_round(self, index: int, plane_pose: np.ndarray, timings: dict) -> str | None:
        """Fix what the round at frame `index` sees and run it (inline) or hand it over.
        A BEV with too little evidence skips the round when it is applied: the status
        stays as it is (initializing at first)."""
        lc = self.settings.localizer
        mode = lc.pipeline
        if mode == "online":
            # no pose yet: the round is the user's first fix, it lands in this push; later
            # ones go to the worker. Decided by this frame's state, so a replay decides alike.
            mode = "inline" if self.tracker.best is None and not self._pending else "pipelined"
        t0 = time.perf_counter()
        try:  # a worker gets a copy: the grid changes under it while the stream goes on
            snapshot = self.bev.snapshot(copy=mode == "pipelined")
        except ZflocError:
            snapshot = None
        job = RoundJob(index, snapshot, self.tracker.warm_start(), self.tracker.confidently_tracking and not self._force_global)
        pending = _Pending(job, index + (0 if mode == "inline" else lc.round_delay), plane_pose, self._force_seq, None)
        if mode == "pipelined":
            pending.outcome = self._executor().submit(*self._task(job))
            timings["round_start"] = time.perf_counter() - t0
        else:
            pending.outcome = run_round(self.floorplan, self.settings, job)
        if pending.join_at <= index:
            return self._apply(pending, timings)
        self._pending.append(pending)
        return None

    def _executor(self) -> Executor:
        if self._pool is None:
            if self.settings.localizer.worker == "process":
                # spawn, not fork: the caller may hold threads (the session writer's)
                context = multiprocessing.get_context("spawn")
                self._pool = ProcessPoolExecutor(1, context, _init_process, (self.floorplan, self.settings))
            else:
                self._pool = ThreadPoolExecutor(1, thread_name_prefix="zfloc-round")
        return self._pool

    def _task(self, job: RoundJob) -> tuple:
        if self.settings.localizer.worker == "process":
            return _process_round, job
        return run_round, self.floorplan, self.settings, job, True

    def _apply(self, pending: _Pending, timings: dict) -> str | None:
        """The round's result lands: the tracker updates as of the frame the round started at.
        Returns why the round did not run (None when it did)."""
        outcome = pending.outcome
        if isinstance(outcome, Future):
            t0 = time.perf_counter()
            outcome = outcome.result()  # waits if the worker is late; a bug in it raises here
            timings["round_wait"] = time.perf_counter() - t0
        self.last_round = outcome
        timings.update(outcome.timings)
        if outcome.observation is None:
            return outcome.skipped
        self.last_observation = outcome.observation
        if pending.force_seq == self._force_seq:  # this round did the requested global search
            self._force_global = False
        if outcome.result is None:
            return outcome.skipped
        self.last_result = outcome.result
        t0, c0 = time.perf_counter(), time.thread_time()
        self.tracker.update(outcome.result.hypotheses, pending.plane_pose[:2], pending.job.index)
        self._refine_locally()
        timings["tracking"] = outcome.timings["tracking"] = time.perf_counter() - t0
        outcome.cpu_timings["tracking"] = time.thread_time() - c0
        return None

    def _refine_locally(self) -> None:
        """The best mode's alignment refined on the recent wall hits (see LocalizerSettings):
        started from the last local refinement of the same mode, so it follows the drift."""
        lc, best = self.settings.localizer, self.tracker.best
        hits = [h for h in self._recent_hits if len(h)]
        if lc.local_frames == 0 or best is None or not hits:
            self._local = None
            return
        points = np.concatenate(hits)
        points = points[:: max(1, len(points) // lc.local_max_points)]
        centre = points.mean(axis=0)
        continuing = self._local is not None and self._local[0] == best.id
        start = self._local[1] if continuing else best.alignment
        est = self.settings.estimator
        # (a fixed-scale mode's s is 1 only up to the filter's round-off: keep it out)
        if continuing and est.scale_mode != "fixed" and start.s != best.alignment.s:
            # The local fit keeps the scale fixed (ten frames of hits barely observe it);
            # the rounds measure it on the whole BEV, so the chain takes the mode's scale,
            # about the recent hits' centre (where the local fit put them stays put).
            # Without this the chain kept its first scale forever (office seed 14: 1.015
            # against a true 1.044 for 90 frames, 0.1-0.25 m off).
            s = best.alignment.s
            start = Sim2(s, start.theta, start.apply(centre) - s * start.R @ centre)
        field = floorplan_scorer(self.floorplan, est.scoring).face_field
        refine = est.refine.model_copy(update={"outlier_distance": lc.local_outlier_distance})
        local = alignment_of(refine_batch(field, points, model_rows([start]), refine, "fixed")[0])
        # a step from where it started (the drift of one round), never a jump elsewhere
        shift = float(np.linalg.norm(local.apply(centre) - start.apply(centre)))
        frames = max(1, self.frames_fused - self._local_frame)
        self._local_frame = self.frames_fused
        keep = local.is_finite() and shift <= lc.local_max_step * frames and self._explained(local, points) >= self._explained(start, points)
        if keep:
            self._local = (best.id, local)
        elif not continuing:  # a refused step keeps the last accepted local alignment
            self._local = None

    def _explained(self, alignment: Sim2, points: np.ndarray) -> float:
        """Share of plane-frame wall points within monitor_distance of a floorplan wall."""
        distances = self.floorplan.distance(alignment.apply(points))
        return float(np.mean(distances < self.settings.localizer.monitor_distance))

    def _frame_consistent(self, alignment: Sim2) -> bool | None:
        """Does the alignment explain the last fused frame's wall hits (at least
        monitor_min_consistency of them within monitor_distance of a wall)? None: too few
        hits to judge."""
        cfg = self.settings.localizer
        points = self.bev.last_wall_hits
        if len(points) < cfg.monitor_min_points:
            return None
        cached = self._consistency_memo
        if cached is not None and cached[0] is alignment and cached[1] is points:
            share = cached[2]  # the monitor and the estimate ask about the same frame and alignment
        else:
            share = self._explained(alignment, points[:: max(1, len(points) // cfg.monitor_max_points)])
            self._consistency_memo = (alignment, points, share)
        return bool(share >= cfg.monitor_min_consistency)

    def _monitor(self) -> None:
        """Watch each fused frame against the tracked alignment (see LocalizerSettings)."""
        cfg = self.settings.localizer
        consistent = None if self.tracker.status != "tracking" else self._frame_consistent(self.tracker.best.alignment)
        if consistent is None:
            return
        self._inconsistent_frames = 0 if consistent else self._inconsistent_frames + 1
        if self._inconsistent_frames >= cfg.monitor_frames:
            self._inconsistent_frames = 0
            self._force_global = True
            self._force_seq += 1

    # ------------------------------------------------------------------------------
    def _estimate(self, index, timestamp, plane_pose, timings, skipped=None, round_skipped=None) -> Estimate:
        best = self.tracker.best
        if best is None or plane_pose is None:
            pose = cov = alignment = None
            score = float("nan")
        else:
            local = self._local is not None and self._local[0] == best.id
            alignment = self._local[1] if local else best.alignment
            pose = np.array(alignment.apply_pose(*plane_pose))
            cov = self.tracker.pose_covariance(plane_pose[:2], plane_pose[2], mode=best)
            score = float(best.score)
        # the frame's own evidence (its hits, the pose's step) can withhold `tracking` (tracking.assess_frame)
        consistent = None if alignment is None else self._frame_consistent(alignment)
        status, confidence = self.tracker.assess_frame(alignment, None if plane_pose is None else plane_pose[:2], consistent)
        alternatives = () if plane_pose is None else self.tracker.estimate_alternatives(plane_pose[:2], plane_pose[2])
        if alternatives and pose is not None:  # the reported mode as reported: its locally refined pose
            first = alternatives[0]
            alternatives = (Alternative(alignment, pose, first.weight, first.score),) + alternatives[1:]
        return Estimate(index, float(timestamp), status, pose, cov, alignment, score, alternatives, timings, skipped, round_skipped,
                        confidence)
