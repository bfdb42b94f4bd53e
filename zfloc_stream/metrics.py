"""Success rate and RMSE under the F3Loc protocol (paper section 4).

A run (one chunk of L frames) succeeds at threshold X when EVERY one of its last
`last` (10) frames has position error <= X. "<=": an error exactly on the threshold is a
success (F3Loc's code uses a strict "<"; on real-valued errors the two differ only on a
set of measure zero, and "<=" makes "within X m" read literally). A frame without a pose
(the localizer had no hypothesis yet) has infinite error: it fails every threshold.

Per run, RMSE = sqrt(mean of squared position errors over the last frames); infinite
when one of them has no pose. Over runs (as F3Loc): RMSE_succ = mean of the run RMSEs of
the runs that succeeded at the reference threshold (1 m); RMSE_all = mean of the run
RMSEs of every run that had a pose on all its last frames; runs without are counted in
`n_no_pose` instead of making RMSE_all infinite. Empty means are NaN.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from .errors import InputError

EVAL_FRAMES = 10  # F3Loc: the final 10 frames decide a run
REFERENCE_THRESHOLD = 1.0  # m, the threshold RMSE_succ refers to


def position_errors(estimated, truth) -> np.ndarray:
    """(n,) planar distance between (n, >=2) estimates and truth; inf where an estimate is
    missing (None or NaN row)."""
    truth = np.asarray(truth, dtype=float)
    est = np.array([(np.nan, np.nan) if e is None else np.asarray(e, dtype=float)[:2] for e in estimated], dtype=float).reshape(-1, 2)
    if truth.ndim != 2 or truth.shape[1] < 2 or len(truth) != len(est):
        raise InputError(f"need one truth (x, y, ...) per estimate: {len(est)} estimates, truth shape {truth.shape}")
    err = np.linalg.norm(est - truth[:, :2], axis=1)
    return np.where(np.isfinite(err), err, np.inf)


def _tail(errors, last: int) -> np.ndarray:
    errors = np.asarray(errors, dtype=float).reshape(-1)
    if errors.size == 0:
        raise InputError("no frame to evaluate")
    if np.isnan(errors).any():
        raise InputError("position errors contain NaN (use inf for a missing pose)")
    return errors[-last:]


def is_success(errors, threshold: float, last: int = EVAL_FRAMES) -> bool:
    """All of the last `last` errors <= threshold (a run shorter than `last` uses all)."""
    return bool((_tail(errors, last) <= threshold).all())


def run_rmse(errors, last: int = EVAL_FRAMES) -> float:
    tail = _tail(errors, last)
    return float(np.sqrt(np.mean(tail**2)))


@dataclass(frozen=True)
class RunMetrics:
    success: dict[float, bool]  # threshold -> success
    rmse: float  # over the last frames; inf when a pose is missing there
    max_error: float  # worst of the last frames
    final_error: float  # the last frame's error


def evaluate_run(errors, thresholds: Iterable[float] = (1.0, 0.5), last: int = EVAL_FRAMES) -> RunMetrics:
    tail = _tail(errors, last)
    return RunMetrics(
        success={float(t): is_success(tail, t, last) for t in thresholds},
        rmse=run_rmse(tail, last),
        max_error=float(tail.max()),
        final_error=float(tail[-1]),
    )


@dataclass(frozen=True)
class Summary:
    n_runs: int
    success_rate: dict[float, float]  # threshold -> fraction in [0, 1]
    rmse_succ: float
    rmse_all: float
    n_no_pose: int  # runs left out of rmse_all (a last frame without pose)

    def as_dict(self) -> dict:
        d = asdict(self)
        d["success_rate"] = {str(k): v for k, v in self.success_rate.items()}
        return d


def _mean(values) -> float:
    values = np.asarray(values, dtype=float)
    return float(values.mean()) if values.size else float("nan")


def summarize(
    successes: Sequence[dict[float, bool]],
    rmses: Sequence[float],
    thresholds: Iterable[float] = (1.0, 0.5),
    reference: float = REFERENCE_THRESHOLD,
) -> Summary:
    """SR per threshold and RMSE_succ / RMSE_all over runs (see the module docstring)."""
    thresholds = [float(t) for t in thresholds]
    rmses = np.asarray(rmses, dtype=float).reshape(-1)
    if len(successes) != rmses.size:
        raise InputError(f"{len(successes)} success records but {rmses.size} RMSEs")
    n = rmses.size
    rate = {t: (sum(bool(s[t]) for s in successes) / n if n else float("nan")) for t in thresholds}
    ok = np.array([bool(s[reference]) for s in successes], dtype=bool) if n else np.zeros(0, bool)
    finite = np.isfinite(rmses)
    return Summary(
        n_runs=n,
        success_rate=rate,
        rmse_succ=_mean(rmses[ok & finite]),
        rmse_all=_mean(rmses[finite]),
        n_no_pose=int((~finite).sum()),
    )
