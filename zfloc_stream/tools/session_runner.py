"""Runs the localizer over a frame source and writes the session's outputs in one folder:
trajectory.csv, trajectory.tum (+ groundtruth.tum where the truth is known), session.mcap
and overlay.png; optionally ros2.mcap (ROS 2 messages) and a live Foxglove view."""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from ..settings.loading import Settings
from ..io.drops import DropCounter
from ..errors import InputError
from ..estimate import STATUSES, Estimate
from ..plans.floorplan import Floorplan
from ..metrics import run_rmse
from ..io.overlay import save_overlay
from ..io.session import SessionWriter
from ..io.trajectory_csv import TrajectoryCsvWriter
from ..io.tum import TumStamps, TumWriter
from .cli_support import Progress, prepare_out_dir, print_warning

TUM_NAME = "trajectory.tum"  # beside trajectory.csv unless --tum names another path
TRUTH_TUM_NAME = "groundtruth.tum"  # the reference for evo_ape, same stamps as trajectory.tum
ROS2_NAME = "ros2.mcap"


@dataclass
class ErrorSummary:
    """Position errors of the frames whose truth is known (threshold: success distance)."""

    threshold: float
    frames: int  # frames with ground truth
    posed: int  # of those, frames with a pose
    mean: float
    median: float
    max: float
    rmse: float  # sqrt(mean(error^2)): evo_ape's translation RMSE (ATE, no alignment) on the same frames
    off: int  # posed frames farther than the threshold
    by_status: dict[str, tuple[int, int]]  # status -> (frames within the threshold, frames)


@dataclass
class SessionOutcome:
    estimates: list[Estimate]
    truth: np.ndarray | None  # (N, 3), NaN rows where a frame's truth is unknown; None: no frame had one
    out_dir: Path
    tum_path: Path | None = None
    tum_rows: int = 0
    tum_moved: int = 0  # rows written at a moved stamp (repeated input stamps)
    truth_tum_path: Path | None = None
    ros2_path: Path | None = None
    first_index: int = 0  # input frame number of estimates[0]
    seconds: float = 0.0  # wall time of the frame loop (reading, localizing, writing)
    push_seconds: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))  # per frame: Localizer.push alone
    truth_from_file: int | None = None  # frames whose truth came from --groundtruth (None: no file given)
    truth_kept: int = 0  # frames the file had no pose for that kept the input's own truth

    @property
    def poses(self) -> np.ndarray:
        return np.array([e.pose if e.pose is not None else (np.nan,) * 3 for e in self.estimates]).reshape(-1, 3)

    def errors(self) -> np.ndarray | None:
        """Per frame: position error (inf where no pose, NaN where no truth); None without truth."""
        if self.truth is None:
            return None
        err = np.linalg.norm(self.poses[:, :2] - self.truth[:, :2], axis=1)
        known = np.isfinite(self.truth[:, :2]).all(axis=1)
        return np.where(known, np.where(np.isfinite(err), err, np.inf), np.nan)

    def final_errors(self, last: int = 10) -> np.ndarray | None:
        """Position errors over the last frames (inf where no pose); None unless every one
        of them has ground truth."""
        errors = self.errors()
        if errors is None or not len(errors) or np.isnan(errors[-last:]).any():
            return None
        return errors[-last:]

    def error_summary(self, threshold: float) -> ErrorSummary | None:
        errors = self.errors()
        if errors is None:
            return None
        known = ~np.isnan(errors)
        if not known.any():
            return None
        posed = errors[known & np.isfinite(errors)]
        by_status = {}
        statuses = np.array([e.status for e in self.estimates])
        for status in STATUSES:
            mask = known & (statuses == status)
            if mask.any():
                by_status[status] = (int((errors[mask] <= threshold).sum()), int(mask.sum()))
        stat = (lambda f: float(f(posed))) if posed.size else (lambda f: float("nan"))
        return ErrorSummary(threshold, int(known.sum()), int(posed.size), stat(np.mean), stat(np.median), stat(np.max),
                            stat(lambda v: run_rmse(v, last=v.size)), int((posed > threshold).sum()), by_status)


def _write_rows(csv_writer: TrajectoryCsvWriter, tum_writer: TumWriter, truth_writer: TumWriter, est: Estimate, truth) -> None:
    """One frame's rows in trajectory.csv, trajectory.tum and the ground-truth TUM."""
    csv_writer.write(est)
    tum_writer.write(est)
    truth_writer.write_pose(est.timestamp, truth)


def run_session(
    floorplan: Floorplan,
    frames: Iterable,
    settings: Settings,
    out_dir: str | Path,
    total: int | None = None,
    progress: bool = True,
    description: str = "localizing",
    tum: str | Path | None = None,
    perception=None,
    groundtruth=None,
    first_index: int = 0,
    live=None,
    ros2: bool = False,
) -> SessionOutcome:
    """perception: networks that complete RGB camera frames before they are logged, so the
    session holds their depth and labels and replays without them. groundtruth: a
    groundtruth.GroundTruth that replaces the frames' own truth where it has a pose (looked
    up at input frame number first_index + i and at the trajectory.tum stamp; a frame it
    has none for keeps its own, counted in SessionOutcome.truth_kept). live: a tools.live.LiveServer
    fed every record written to session.mcap. ros2: also write OUT/ros2.mcap."""
    from contextlib import ExitStack

    out_dir = prepare_out_dir(out_dir)
    from ..stream.localizer import Localizer  # here: the compiled kernels (numba) load only once inputs are valid

    localizer = Localizer(floorplan, settings, perception)
    if perception is not None:
        frames = perception.stream(frames)
    estimates: list[Estimate] = []
    truths: list = []
    drops = DropCounter(description)  # frames the localizer refused: warned once per cause
    lookup = TumStamps()  # the stamps trajectory.tum will carry: ground truth is looked up at them
    push_seconds: list[float] = []
    from_file = kept = 0
    t_start = time.perf_counter()
    with ExitStack() as stack:
        stack.enter_context(localizer)  # stops a pipelined round worker, also when a frame source fails
        csv_writer = stack.enter_context(TrajectoryCsvWriter(out_dir / "trajectory.csv"))
        tum_writer = stack.enter_context(TumWriter(out_dir / TUM_NAME if tum is None else tum))
        truth_writer = stack.enter_context(TumWriter(out_dir / TRUTH_TUM_NAME, header="# timestamp tx ty tz qx qy qz qw (ground truth in the floorplan frame; stamps as in trajectory.tum)\n"))
        log = stack.enter_context(SessionWriter(out_dir / "session.mcap", settings, floorplan, listeners=() if live is None else (live,)))
        ros2_writer = None
        if ros2:
            from ..io.ros2_output import Ros2Writer

            ros2_writer = stack.enter_context(Ros2Writer(out_dir / ROS2_NAME, floorplan))
        bar = stack.enter_context(Progress(total, description, "frame", enabled=progress))
        for index, frame in enumerate(frames):
            stamp = lookup.next(frame.timestamp)
            if groundtruth is not None:
                given = groundtruth.at(first_index + index, stamp)
                if given is not None:
                    frame = dataclasses.replace(frame, ground_truth=given)
                    from_file += 1
                elif frame.ground_truth is not None:  # a file that does not cover the frame drops no truth
                    kept += 1
            frame = log.write_frame(index, frame)  # push the frame as logged: replays match bit for bit
            t0 = time.perf_counter()
            est = localizer.push(frame)
            push_seconds.append(time.perf_counter() - t0)
            # the frame's rows once session.mcap holds it: a killed run never shows a frame
            # in trajectory.csv that its log lacks (the log is written on a worker thread)
            log.write_estimate(est, localizer, then=partial(_write_rows, csv_writer, tum_writer, truth_writer, est, frame.ground_truth))
            if ros2_writer is not None:
                ros2_writer.write(stamp, est, frame.ground_truth)
            if est.skipped is not None:
                drops.note(est.skipped, f"frame {index}")
            if est.prior == "contradicted" and (not estimates or estimates[-1].prior != "contradicted"):
                print_warning(f"frame {index}: the frames contradict the initial pose / region (a place outside it explains "
                              "them clearly better, or none inside it does): it is dropped, the search is global")
            estimates.append(est)
            truths.append(frame.ground_truth)
            bar.update()
        seconds = time.perf_counter() - t_start
    drops.summary()
    mismatch = localizer.map_match.verdict()
    if mismatch is not None:
        warnings.warn(mismatch, stacklevel=2)
    truth = None
    if any(t is not None for t in truths):
        truth = np.array([(np.nan,) * 3 if t is None else np.asarray(t, dtype=float)[:3] for t in truths]).reshape(-1, 3)
    truth_tum = out_dir / TRUTH_TUM_NAME
    if truth_writer.rows == 0:
        truth_tum.unlink(missing_ok=True)
    outcome = SessionOutcome(estimates, truth, out_dir, tum_writer.path, tum_writer.rows, tum_writer.moved,
                             truth_tum if truth_writer.rows else None, None if ros2_writer is None else ros2_writer.path,
                             first_index, seconds, np.array(push_seconds), None if groundtruth is None else from_file, kept)
    best = localizer.tracker.best
    obs = localizer.last_observation
    save_overlay(
        out_dir / "overlay.png",
        floorplan,
        outcome.poses,
        truth,
        bev_wall_points=None if obs is None else obs.wall_points,
        alignment=None if best is None else best.alignment,
        title=f"{description}: {len(estimates)} frames, final status {estimates[-1].status if estimates else '-'}",
        statuses=[e.status for e in estimates],
        alignments=[e.alignment for e in estimates],
    )
    return outcome
