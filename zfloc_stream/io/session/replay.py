"""Replay: re-run the engine on a session's logged inputs.

With check=True every logged output (pose, hypotheses, BEV grid, status without its
timings) is compared with the re-run, frame by frame; the first difference is returned as
a Divergence. Decisions (statuses, modes, hypothesis counts, skips) must match exactly and
numbers within a Tolerance (compare.py); Tolerance.exact compares bit for bit. The
localizer is deterministic: on the recording machine a session replayed with its own
settings matches bit for bit; on another CPU or BLAS the last bits of numbers may differ,
the decisions may not.

Frame range: frames start <= index < stop. With check=True the engine first runs through
frames 0..start-1 unchecked (its state at `start` must be the logged one); without check
a fresh engine starts at `start` (to study a segment on its own).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...settings.loading import Settings, load_settings
from ...errors import SessionLogError
from ...estimate import Estimate
from ...geometry.frame_tree import LEGACY_MAP
from . import schemas as S
from .compare import EXACT, Comparison, Deviation, Divergence, Tolerance, comparable_grid, comparable_status
from .reader import FrameRecord, LoggedOutputs, Session
from .writer import SessionWriter, bev_grid_of


@dataclass
class RunSummary:
    """Per run: how many frames had a pose, the final status, errors where ground truth
    is known, and the mean wall time per frame (total and per stage)."""

    frames: int = 0
    with_pose: int = 0
    final_status: str = "-"
    success: bool | None = None  # every one of the last frames within the success distance
    mean_error: float | None = None  # m, over frames with a pose and ground truth
    final_error: float | None = None  # m, last frame (inf: no pose)
    mean_time: float | None = None  # s per frame, sum of the stage timings
    mean_timings: dict[str, float] = field(default_factory=dict)


@dataclass
class ReplayResult:
    frames: int  # frames replayed (in the requested range)
    checked: int  # frames whose logged outputs were compared
    divergence: Divergence | None
    estimates: list[Estimate]
    logged: RunSummary
    replayed: RunSummary
    out: Path | None = None
    tolerance: Tolerance = EXACT
    deviations: dict[str, Deviation] = field(default_factory=dict)  # per topic, with check=True
    unchecked: list[int] = field(default_factory=list)  # with check: frames replayed without logged outputs (a cut-off end)


# --- settings -------------------------------------------------------------------------------
def replay_settings(session: Session, config: str | Path | None = None, overrides: list[str] | None = None, base: Settings | None = None) -> Settings:
    """The session's logged settings (defaults if it has none; or `base`), then a YAML
    file, then dotted.key=value overrides."""
    base = base or session.settings or Settings()
    return load_settings(config, overrides, base_overrides=base.model_dump())


# --- comparison -----------------------------------------------------------------------------
def logged_map_frame(logged: LoggedOutputs) -> str:
    """The map frame's name as the log spells it: logs from before REP 105 naming say
    `floorplan` (frame_tree.LEGACY_MAP), and their replay is compared under that name."""
    for msg in (logged.pose, logged.hypotheses):
        if msg is not None and msg.frame_id == LEGACY_MAP:
            return LEGACY_MAP
    return S.FRAME_MAP


def compare_outputs(comparison: Comparison, index: int, ns: int, logged: LoggedOutputs, est: Estimate, bev_source) -> Divergence | None:
    """The first difference between what was logged for a frame and the re-run (see
    compare.py: decisions exactly, numbers within comparison.tolerance)."""
    pairs: list[tuple[str, object, object]] = [(S.TOPIC_STATUS, comparable_status(logged.status), comparable_status(S.status_to_json(est)))]
    frame = logged_map_frame(logged)
    replay_pose = None if est.pose is None else S.estimate_pose_to_msg(est, ns, frame)
    if (logged.pose is None) != (replay_pose is None):
        return Divergence(index, S.TOPIC_POSE, "present", logged.pose is not None, replay_pose is not None)
    if replay_pose is not None:
        pairs.append((S.TOPIC_POSE, logged.pose, replay_pose))
    if logged.hypotheses is not None:
        pairs.append((S.TOPIC_HYPOTHESES, logged.hypotheses, S.hypotheses_to_msg(est, ns, frame)))
    if logged.bev is not None:
        grid = bev_grid_of(bev_source)
        if grid is None:
            return Divergence(index, S.TOPIC_BEV, "present", True, False)
        pairs.append((S.TOPIC_BEV, comparable_grid(S.grid_from_msg(logged.bev)), comparable_grid(grid)))
    return comparison.frame(index, pairs)


# --- summaries ------------------------------------------------------------------------------
def summarize_run(estimates: list[Estimate | None], truth: list, settings: Settings) -> RunSummary:
    from ...metrics import is_success, position_errors

    cfg = settings.logging
    done = [e for e in estimates if e is not None]
    out = RunSummary(frames=len(done))
    if not done:
        return out
    out.with_pose = sum(e.pose is not None for e in done)
    out.final_status = done[-1].status
    totals = [sum(e.timings.values()) for e in done if e.timings]
    if totals:
        out.mean_time = float(np.mean(totals))
        stages = sorted({k for e in done for k in e.timings})
        out.mean_timings = {k: float(np.mean([e.timings.get(k, 0.0) for e in done])) for k in stages}
    if len(done) == len(estimates) and truth and all(t is not None for t in truth):
        err = position_errors([e.pose for e in done], np.asarray(truth, dtype=float))
        finite = err[np.isfinite(err)]
        out.mean_error = float(finite.mean()) if finite.size else None
        out.final_error = float(err[-1])
        out.success = is_success(err, cfg.success_distance, cfg.success_last_frames)
    return out


def require_outputs(session: Session) -> None:
    """Refuse early (before any engine work) to check a session that logged no outputs."""
    if session.topics is not None and S.TOPIC_STATUS not in session.topics:
        raise SessionLogError(f"{session.path}: nothing to check: the session holds no logged outputs ({S.TOPIC_STATUS})")


# --- replay ---------------------------------------------------------------------------------
def replay_session(
    session: Session,
    settings: Settings,
    floorplan,
    start: int = 0,
    stop: int | None = None,
    check: bool = False,
    out: str | Path | None = None,
    on_frame: Callable[[int], None] | None = None,
    tolerance: Tolerance = EXACT,
) -> ReplayResult:
    """Re-run the localizer on frames start <= index < stop (see the module docstring)."""
    from ...stream.localizer import Localizer  # the engine is only needed here

    if start < 0 or (stop is not None and stop <= start):
        raise SessionLogError(f"empty frame range: from {start} to {stop}")
    if check:
        require_outputs(session)
    localizer = Localizer(floorplan, settings)
    writer = None
    if out is not None:
        info = {"replay_of": str(session.path), "frames_from": str(start), "frames_to": "end" if stop is None else str(stop)}
        writer = SessionWriter(out, settings, floorplan, metadata=info)
    estimates: list[Estimate] = []
    logged: list[Estimate | None] = []
    truth: list = []
    divergence = None
    checked = 0
    frames = 0
    unchecked: list[int] = []
    comparison = Comparison(tolerance)
    try:
        for rec in session.records(0 if check else start, stop):
            in_range = rec.index >= start
            est = _push(localizer, writer, rec, in_range)
            if on_frame is not None:
                on_frame(rec.index)
            if not in_range:
                continue
            frames += 1
            estimates.append(est)
            logged.append(rec.outputs.estimate)
            truth.append(rec.frame.ground_truth)
            if check and rec.outputs.status is not None:
                checked += 1
                divergence = compare_outputs(comparison, rec.index, rec.stamp_ns, rec.outputs, est, localizer)
                if divergence is not None:
                    break
            elif check:
                unchecked.append(rec.index)
    finally:
        localizer.close()  # the logged pipeline mode may have started a worker
        if writer is not None:
            writer.close()
    if frames == 0:
        raise SessionLogError(f"{session.path}: no frame in the requested range (from {start} to {stop if stop is not None else 'end'})")
    if check and checked == 0:
        raise SessionLogError(f"{session.path}: nothing to check: the session holds no logged outputs ({S.TOPIC_STATUS})")
    return ReplayResult(
        frames=frames,
        checked=checked,
        divergence=divergence,
        estimates=estimates,
        logged=summarize_run(logged, truth, session.settings or settings),
        replayed=summarize_run(estimates, truth, settings),
        out=None if out is None else Path(out),
        tolerance=tolerance,
        deviations=comparison.deviations,
        unchecked=unchecked,
    )


def _push(localizer, writer: SessionWriter | None, rec: FrameRecord, log: bool) -> Estimate:
    if writer is None or not log:
        return localizer.push(rec.frame)
    writer.copy_frame(rec)  # the logged messages as they are: the new file replays the same bits
    est = localizer.push(rec.frame)
    writer.write_estimate(est, localizer)
    return est
