"""trajectory.csv: one row per pushed frame (public contract, docs/inputs.md).

Rows are flushed as they are written so a crash loses at most the frame in flight.
Columns: frame, timestamp, x, y, theta, scale, score, n_hypotheses, status, confidence.
Before the first hypothesis x, y, theta, scale, score and confidence are empty. New
columns are only ever appended (readers index by name or by the first nine positions).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..estimate import Estimate

COLUMNS = ("frame", "timestamp", "x", "y", "theta", "scale", "score", "n_hypotheses", "status", "confidence")


def _num(value: float) -> str:
    return "" if value is None or not np.isfinite(value) else repr(float(value))


def estimate_row(est: Estimate) -> list[str]:
    x, y, theta = (None, None, None) if est.pose is None else est.pose
    return [
        str(est.frame),
        repr(float(est.timestamp)),
        _num(x),
        _num(y),
        _num(theta),
        _num(est.scale),
        _num(est.score),
        str(est.n_hypotheses),
        est.status,
        _num(est.confidence),
    ]


class TrajectoryCsvWriter:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._file = open(self.path, "w", newline="")
        self._writer = csv.writer(self._file)
        self._writer.writerow(COLUMNS)
        self._file.flush()

    def write(self, est: Estimate) -> None:
        self._writer.writerow(estimate_row(est))
        self._file.flush()

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def read_trajectory_csv(path: str | Path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
