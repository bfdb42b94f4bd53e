"""Where and when a localization round runs (localizer.pipeline), and what it computes.

A round started at frame i works on what the stream had at frame i (a RoundJob: a
snapshot of the BEV grid, the tracker's warm starts and search mode; its rng is seeded by
i), and is applied at a fixed join frame, never "when it is ready", so a run replays bit
for bit:

- inline: run inside the push of frame i and applied there;
- pipelined: run on one worker (a thread, or a process: localizer.worker) beside the
  stream and applied at frame i + round_delay exactly (that push waits if the worker is
  late);
- online (the default): pipelined; while no pose exists and nothing is pending, a
  preview round starts one fused frame before each k-th frame, on the worker, and lands
  in the k-th frame's push, so the first fix is reported where inline gives it and no
  push runs a whole round (localizer.first_fix_preview; without it, when the preview
  gave no pose, or when the frame before was not fused, the k-th frame's round runs
  inline);
- delayed: computed inline at frame i, applied at pipelined's join frame (pipelined's
  results without a worker).

The scheduler also keeps the consistency monitor's request for a global search: the next
round started searches globally, and the request is cleared only when a round started
after it lands (a request made while a round is in flight outlives that round).
"""

from __future__ import annotations

import multiprocessing
import time
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..runtime import threads
from ..settings.loading import Settings
from ..errors import UsageError, ZflocError
from ..estimation import localize
from ..estimation.results import LocalizationResult
from ..frontend.bev_snapshot import BevSnapshot
from ..runtime.heap import limit_arenas, release_free_heap
from ..observation import BevObservation
from ..prior import BoundPrior
from ..runtime.rng import make_rng
from ..geometry.sim2 import Sim2


@dataclass(frozen=True)
class RoundJob:
    """What the round started at frame `index` works on, fixed at that frame. The localizer
    describes it and adds the snapshot of its BEV as it starts it (Localizer._start_round)."""

    index: int
    snapshot: BevSnapshot | None  # None: nothing fused into the grid yet
    warm_start: list[Sim2]
    tracked: bool  # one mode confidently tracked and no global search asked for
    since: int = 0  # a kidnap test: the snapshot holds only what frames from this BEV stamp on saw (0: not a test)
    prior: BoundPrior | None = None  # the caller's pose prior, while it is active (prior.py): its global search uses it
    audit: bool = False  # the audit's round (localizer.audit_frames): a global search on the frames since `since`
    revisit: tuple[Sim2, ...] = ()  # the previous round's runners-up (HypothesisTracker.runners_up), scored again


@dataclass
class RoundOutcome:
    index: int  # frame the round started at
    observation: BevObservation | None  # None: too little evidence, the round was skipped
    result: LocalizationResult | None  # None: skipped, or the estimator refused the BEV
    skipped: str | None = None  # why the round did not run (Estimate.round_skipped of its join frame)
    timings: dict[str, float] = field(default_factory=dict)  # wall seconds per stage
    cpu_timings: dict[str, float] = field(default_factory=dict)  # CPU seconds per stage (the thread that ran it)
    tracked: bool = False  # the round followed a confidently tracked mode (no global search)


@dataclass
class ScheduledRound:
    job: RoundJob
    join_at: int  # the push index whose estimate first carries the result
    plane_pose: np.ndarray  # frame job.index's sensor pose: the tracker is anchored there
    request: int  # global-search requests made before it started (a later one stays pending)
    outcome: RoundOutcome | Future | None = None
    preview: bool = False  # a preview of the next k-th frame's round: reported, never tracked


def run_round(floorplan, settings: Settings, job: RoundJob) -> RoundOutcome:
    """Primitives + estimation of one round: a pure function of its inputs, so it gives the
    same bits on the caller's thread, a worker thread or a worker process. Afterwards the
    freed temporaries go back to the OS once they have piled up (localizer.release_memory)."""
    with threads.limit(threads.resolve(settings.estimator.threads)):
        out = _compute_round(floorplan, settings, job)
    if settings.localizer.release_memory:
        release_free_heap(int(settings.localizer.release_memory_growth * 2**20))
    return out


# A round that starts from nothing (no live mode to warm-start from: the stream's first
# rounds, or every mode gone) draws each BEV minimal sample against at least this fraction
# of its floorplan matches (estimator.ransac.match_fraction: 0.03). On a drawn plan the
# correlative seeds miss the true place of a first round: the BEV's clutter, which the plan
# leaves out, matches nothing there, and wrong places match more points (aces 425 #15, frame
# 4: 70 of 116 points at the truth, 100-106 at the ten best peaks), so the minimal solvers
# alone must propose it (round_diagnose.py).
FIRST_FIX_MATCH_FRACTION = 0.1


def round_estimator_settings(settings: Settings, job: RoundJob):
    """The estimator's settings for this round: FIRST_FIX_MATCH_FRACTION for a round with
    no warm start outside a kidnap test or audit."""
    est = settings.estimator
    if job.warm_start or job.since or est.ransac.match_fraction >= FIRST_FIX_MATCH_FRACTION:
        return est
    return est.model_copy(update={"ransac": est.ransac.model_copy(update={"match_fraction": FIRST_FIX_MATCH_FRACTION})})


def _compute_round(floorplan, settings: Settings, job: RoundJob) -> RoundOutcome:
    cfg = settings
    out = RoundOutcome(job.index, None, None, tracked=job.tracked)
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        # a plan without pillars cannot match a BEV circle: its pillar clustering is skipped
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
            round_estimator_settings(cfg, job),
            make_rng(cfg.seed, "ransac", job.index),
            scale_prior=cfg.estimator.scale_prior,
            warm_start=job.warm_start,
            revisit=job.revisit,
            iterations=cfg.estimator.ransac.tracking_iterations if job.tracked else cfg.estimator.ransac.iterations,
            global_search=not job.tracked,
            prior=job.prior,
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
_process_state: tuple | None = None


def _init_process(floorplan, settings: Settings) -> None:
    global _process_state
    _process_state = (floorplan, settings)


def _process_round(job: RoundJob) -> RoundOutcome:
    return run_round(*_process_state, job)


class RoundScheduler:
    """Runs rounds where localizer.pipeline says and hands them back at their join frames
    (see the module docstring)."""

    def __init__(self, floorplan, settings: Settings):
        self.floorplan = floorplan
        self.settings = settings
        self._scheduled: deque[ScheduledRound] = deque()  # started, not yet applied, oldest first
        self._pool: Executor | None = None
        self._closed = False  # close() stopped the worker for good
        self._global_wanted = False  # the monitor asked the next round for a global search
        self._requests = 0  # how many times it asked
        self._previewed = 0  # the k-th fused frame whose round a preview started ahead of
        lc = settings.localizer
        # before the worker thread (or the round's helper threads) take arenas of their own
        limit_arenas(lc.malloc_arenas)
        if lc.pipeline in ("pipelined", "online") and lc.worker == "process":
            self._executor().submit(int)  # start the process now: it takes a second or two to import

    @property
    def in_flight(self) -> int:
        """Rounds started and not yet applied."""
        return len(self._scheduled)

    @property
    def global_search_wanted(self) -> bool:
        return self._global_wanted

    @property
    def global_search_requests(self) -> int:
        """How many times the monitor asked for a global search."""
        return self._requests

    def request_global_search(self) -> None:
        self._global_wanted = True
        self._requests += 1

    def due(self, fused: int, has_pose: bool, previewed: bool = False) -> str | None:
        """The round, if any, that starts at the frame that makes `fused` fused frames:
        where it runs (self.mode's inline, pipelined or delayed, or "preview": on the
        worker, landing at the next frame), or None. Rounds belong to every k-th fused
        frame; the online mode previews one while there is no pose (module docstring), and
        a preview it returns is remembered until that k-th frame.
        has_pose: the tracker has one; previewed: a preview's pose is reported."""
        lc = self.settings.localizer
        k = lc.every_k_frames
        if fused % k == 0:
            # a preview gave this frame a pose: its own round goes to the worker. A preview
            # without one (too little evidence on one frame fewer) leaves the round inline,
            # so the first pose never comes later than inline gives it
            return "pipelined" if self._previewed == fused and previewed else self.mode(has_pose)
        if (lc.pipeline == "online" and lc.first_fix_preview and (fused + 1) % k == 0
                and not has_pose and not self._scheduled):
            self._previewed = fused + 1
            return "preview"
        return None

    @staticmethod
    def on_worker(mode: str) -> bool:
        """Does a round started in `mode` (self.due(...)) leave this thread? Then its snapshot
        must be a copy: the grid changes under it while the stream goes on."""
        return mode in ("pipelined", "preview")

    def start(self, mode: str, job: RoundJob, plane_pose: np.ndarray) -> None:
        """Start the job's round where `mode` (self.due(...)) says; `landed` returns it at
        its join frame."""
        delay = {"inline": 0, "preview": 1}.get(mode, self.settings.localizer.round_delay)
        scheduled = ScheduledRound(job, job.index + delay, plane_pose, self._requests, preview=mode == "preview")
        if self.on_worker(mode):
            scheduled.outcome = self._executor().submit(*self._task(job))
        else:
            scheduled.outcome = run_round(self.floorplan, self.settings, job)
        self._scheduled.append(scheduled)

    def mode(self, has_pose: bool) -> str:
        """Where a round starting at its k-th frame runs: inline, pipelined or delayed.
        Decided by the state at its start frame, so a replay decides alike."""
        mode = self.settings.localizer.pipeline
        if mode == "online":
            # no pose yet and no preview: the round is the user's first fix, it lands in this
            # push; later ones go to the worker
            mode = "inline" if not has_pose and not self._scheduled else "pipelined"
        return mode

    def landed(self, index: int, timings: dict) -> Iterator[tuple[ScheduledRound, RoundOutcome]]:
        """The rounds whose join frame is `index` or earlier, oldest first, each with its
        outcome (waiting for the worker if it is late: timings["round_wait"]). A round that
        ran clears the global-search request it answered."""
        while self._scheduled and self._scheduled[0].join_at <= index:
            scheduled = self._scheduled.popleft()
            outcome = scheduled.outcome
            if isinstance(outcome, Future):
                t0 = time.perf_counter()
                outcome = outcome.result()  # waits if the worker is late; a bug in it raises here
                timings["round_wait"] = time.perf_counter() - t0
            timings.update(outcome.timings)
            if outcome.observation is not None and scheduled.request == self._requests:
                self._global_wanted = False  # this round did the requested global search
            yield scheduled, outcome

    def close(self) -> None:
        """Stop the worker. Rounds not applied yet are dropped (no frame reached their join
        frame); the worker finishes the one it is running first."""
        self._scheduled.clear()
        self._closed = True
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def _executor(self) -> Executor:
        if self._closed:  # a worker started now would never be stopped
            raise UsageError("a round was started after the localizer was closed")
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
        return run_round, self.floorplan, self.settings, job
