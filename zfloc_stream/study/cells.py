"""One cell of a study: a fresh Localizer on the chunk's frames, the last study.eval_frames
frames scored. A pure function of the cell and the overrides, so results do not depend
on where or in which order cells run."""

from __future__ import annotations

import time
import traceback
from dataclasses import asdict
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..settings.loading import Settings
from ..errors import InputError, ZflocError
from ..metrics import evaluate_run, position_errors
from .plan import Cell, cell_settings


@lru_cache(maxsize=8)
def _open_cached(spec: str, settings_json: str):
    from ..io.datasets import open_dataset

    return open_dataset(spec, Settings.model_validate_json(settings_json))


def threshold_key(t: float) -> str:
    return f"success_{t:g}m"


def run_cell(cell: Cell, overrides: dict | None = None) -> dict:
    """Localize one chunk with one seed; a row of results. Never raises: a failure is
    reported in the row's `error` field."""
    from ..stream.localizer import Localizer

    overrides = overrides or {}
    row = asdict(cell)
    row["key"] = cell.key
    t0 = time.perf_counter()
    try:
        data_settings = cell_settings(overrides, cell.seed)
        seq = _open_cached(cell.dataset, data_settings.model_dump_json())[cell.sequence]
        if seq.name != cell.sequence_name:
            raise InputError(f"dataset {cell.dataset}: sequence {cell.sequence} is {seq.name!r}, expected {cell.sequence_name!r}")
        settings = cell_settings(overrides, cell.seed, seq.settings_overrides)
        study = settings.study
        poses, truth, status = [], [], None
        with Localizer(seq.floorplan_for(cell.start, cell.stop), settings) as localizer:
            for frame in seq.frames(cell.start, cell.stop):
                est = localizer.push(frame)
                poses.append(est.pose)
                truth.append(np.full(3, np.nan) if frame.ground_truth is None else frame.ground_truth)
                status = est.status
        truth = np.asarray(truth, dtype=float)
        if not np.isfinite(truth[-study.eval_frames :, :2]).all():
            raise InputError(f"{cell.key}: ground truth missing in the last {study.eval_frames} frames")
        errors = position_errors(poses, truth)
        run = evaluate_run(errors, study.thresholds, study.eval_frames)
        tail = errors[-study.eval_frames :]
        row.update({threshold_key(t): ok for t, ok in run.success.items()})
        row.update(
            rmse=run.rmse,
            max_error=run.max_error,
            final_error=run.final_error,
            frames_with_pose=int(np.isfinite(tail).sum()),
            final_status=status,
            error=None,
        )
    except Exception as err:  # noqa: BLE001 (a failing chunk is reported, the study goes on)
        detail = str(err) if isinstance(err, ZflocError) else f"{type(err).__name__}: {err} [{_where(err)}]"
        row.update(error=detail)
    row["seconds"] = time.perf_counter() - t0
    return row


def _where(err: Exception) -> str:
    frames = traceback.extract_tb(err.__traceback__)
    return f"{Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else "?"
