"""The summary `zfloc-stream run` / `demo` print at the end, for a robot user: how the run
went (frames per status, the first `tracking` frame, the final status, score and
confidence), how fast (frames/s, push latency), and, with ground truth, how far off
(RMSE, mean, median, max, and success over the last frames)."""

from __future__ import annotations

import numpy as np

from ..metrics import EVAL_FRAMES, is_success
from .session_runner import SessionOutcome

# what a score means, printed beside it (estimation/scoring.py: C = Cc - Cv in [-1, 1])
SCORE_MEANING = "of 1 = every wall seen on a plan wall and no plan wall across floor seen free; <= 0 = no support"


def _status_lines(outcome: SessionOutcome) -> list[str]:
    estimates = outcome.estimates
    last = estimates[-1]
    if last.pose is None:
        lines = [f"final status: {last.status}, no pose yet ({len(estimates)} frames: too few for a first estimate)"]
    else:
        lines = [f"final status: {last.status}, confidence {last.confidence:.2f}, score {last.score:.3f} ({SCORE_MEANING}), "
                 f"scale {last.scale:.3f}"]
    statuses = [e.status for e in estimates]
    counts = {s: statuses.count(s) for s in dict.fromkeys(("initializing", "tracking", "ambiguous", "lost", *statuses))}
    first = next((i for i, s in enumerate(statuses) if s == "tracking"), None)
    where = ("never tracking" if first is None else
             f"first tracking at frame {outcome.first_index + first} ({first + 1} frames into the run, t = {estimates[first].timestamp:.3f} s)")
    lines.append("frames by status: " + ", ".join(f"{s} {n}" for s, n in counts.items()) + f"; {where}")
    if len(outcome.push_seconds) and outcome.seconds > 0:
        p50, p99 = np.percentile(outcome.push_seconds, [50, 99]) * 1e3
        lines.append(f"speed: {len(estimates)} frames in {outcome.seconds:.1f} s = {len(estimates) / outcome.seconds:.1f} frames/s "
                     f"(reading and writing included); push latency p50 {p50:.1f} ms, p99 {p99:.1f} ms")
    return lines


def _error_lines(outcome: SessionOutcome, threshold: float) -> list[str]:
    summary = outcome.error_summary(threshold)
    if summary is None:
        return []
    n = len(outcome.estimates)
    lines = []
    if summary.posed:
        lines.append(f"position error over {summary.posed} posed frames with ground truth: RMSE {summary.rmse:.2f} m, "
                     f"mean {summary.mean:.2f} m, median {summary.median:.2f} m, max {summary.max:.2f} m; "
                     f"{summary.off} frames more than {threshold:g} m off"
                     + (f"; {summary.frames - summary.posed} frames without a pose" if summary.frames > summary.posed else ""))
    else:
        lines.append(f"position error: no pose yet on any of the {summary.frames} frames with ground truth")
    lines.append(f"frames within {threshold:g} m by status: "
                 + ", ".join(f"{status} {k}/{m}" for status, (k, m) in summary.by_status.items()))
    tail = outcome.final_errors(EVAL_FRAMES)
    last = outcome.estimates[-1]
    if tail is not None and last.pose is not None:
        ok = is_success(tail, threshold)
        missing = int((~np.isfinite(tail)).sum())
        worst = f"last-{len(tail)} max {tail.max():.3f} m" if not missing else f"{missing} of the last {len(tail)} frames without a pose"
        lines.append(f"final position error: {tail[-1]:.3f} m; {worst}; success@{threshold:g}m: {'yes' if ok else 'no'}")
    elif tail is None:
        # the success rule needs the truth on each of the last frames: say what is there instead
        errors = outcome.errors()
        k = min(EVAL_FRAMES, n)
        have = int((~np.isnan(errors[-k:])).sum())
        known = np.flatnonzero(~np.isnan(errors))
        i = int(known[-1])
        lines.append(f"success@{threshold:g}m: not computed: it needs ground truth on each of the last {k} frames, "
                     f"{have} of them have it; last frame with ground truth: {outcome.first_index + i}, error "
                     + (f"{errors[i]:.3f} m" if np.isfinite(errors[i]) else "- (no pose)"))
    return lines


def report_lines(outcome: SessionOutcome, threshold: float) -> list[str]:
    """The summary's lines (none for a run without frames). threshold: the success distance."""
    if not outcome.estimates:
        return []
    return _status_lines(outcome) + _error_lines(outcome, threshold)
