"""Runs the localizer over a frame source and writes the session's outputs:
trajectory.csv, session.mcap and overlay.png in one output folder."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..config import Settings
from ..estimate import Estimate
from ..floorplan import Floorplan
from ..overlay import save_overlay
from ..session import SessionWriter
from ..trajectory_csv import TrajectoryCsvWriter
from ..tum import TumWriter

TUM_NAME = "trajectory.tum"  # beside trajectory.csv unless --tum names another path


@dataclass
class SessionOutcome:
    estimates: list[Estimate]
    truth: np.ndarray | None  # (N, 3) where every frame had ground truth
    out_dir: Path
    tum_path: Path | None = None

    @property
    def poses(self) -> np.ndarray:
        return np.array([e.pose if e.pose is not None else (np.nan,) * 3 for e in self.estimates]).reshape(-1, 3)

    def final_errors(self, last: int = 10) -> np.ndarray | None:
        """Position errors over the last frames (inf where no pose), None without truth."""
        if self.truth is None:
            return None
        err = np.linalg.norm(self.poses[-last:, :2] - self.truth[-last:, :2], axis=1)
        return np.where(np.isfinite(err), err, np.inf)


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
) -> SessionOutcome:
    """perception: networks that complete RGB camera frames before they are logged, so the
    session holds their depth and labels and replays without them."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    from ..localizer import Localizer  # here: the compiled kernels (numba) load only once inputs are valid

    localizer = Localizer(floorplan, settings, perception)
    if perception is not None:
        frames = perception.stream(frames)
    estimates: list[Estimate] = []
    truths: list = []
    with (
        localizer,  # stops a pipelined round worker, also when a frame source fails
        TrajectoryCsvWriter(out_dir / "trajectory.csv") as csv_writer,
        TumWriter(out_dir / TUM_NAME if tum is None else tum) as tum_writer,
        SessionWriter(out_dir / "session.mcap", settings, floorplan) as log,
    ):
        for index, frame in enumerate(tqdm(frames, total=total, desc=description, disable=not progress, unit="frame")):
            frame = log.write_frame(index, frame)  # push the frame as logged: replays match bit for bit
            est = localizer.push(frame)
            log.write_estimate(est, localizer)
            csv_writer.write(est)
            tum_writer.write(est)
            estimates.append(est)
            truths.append(frame.ground_truth)
    truth = None if any(t is None for t in truths) or not truths else np.array(truths, dtype=float)
    outcome = SessionOutcome(estimates, truth, out_dir, tum_writer.path)
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
    )
    return outcome
