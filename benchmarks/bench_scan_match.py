"""Scan matching on the real laser logs: how much of the odometry's per-step error the
scan matcher leaves, and what fusing a scan costs (numbers, not asserts).

Each shared Carmen log, whole, fused into a RollingBEV from drifting odometry (as
benchmarks/evaluation/eval_real.py makes it: datasets.odometry, times --drift). For every step
between consecutive scans, the relative motion of the plane poses (as fused) is compared
with the true relative motion: translation error (cm) and heading error (deg), for the raw
odometry and after matching. The share of steps whose heading error exceeds 2 deg is what
smears the BEV and moves the pose off (docs/status.md, "Scan matching under cheap
odometry").

    python -m benchmarks.bench_scan_match                       # drift 1 and 3, every log
    python -m benchmarks.bench_scan_match --drift 3 --logs orebro
    python -m benchmarks.bench_scan_match --set bev.scan_match=none
"""

from __future__ import annotations

import time

import numpy as np

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.io.datasets.carmen import carmen_sequence
from zfloc_stream.errors import ZflocError
from zfloc_stream.frontend.bev import RollingBEV, plane_pose
from zfloc_stream.geometry.sim2 import wrap_angle

from benchmarks.evaluation.eval_real import DATA, LOGS, drift_overrides
from benchmarks.harness import Benchmark


def relative_steps(poses: np.ndarray) -> np.ndarray:
    """(n - 1, 3): each step's motion (dx, dy in the earlier pose's frame, dyaw)."""
    d = poses[1:, :2] - poses[:-1, :2]
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(np.diff(poses[:, 2]))])


def step_errors(poses: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per step: translation error (m) and absolute heading error (deg)."""
    e = relative_steps(poses) - relative_steps(truth)
    return np.hypot(e[:, 0], e[:, 1]), np.rad2deg(np.abs(wrap_angle(e[:, 2])))


def describe(prefix: str, translation: np.ndarray, heading: np.ndarray) -> dict:
    return {f"{prefix}_cm": 100 * float(np.median(translation)), f"{prefix}_cm_p90": 100 * float(np.quantile(translation, 0.9)),
            f"{prefix}_deg": float(np.median(heading)), f"{prefix}_deg_p90": float(np.quantile(heading, 0.9)),
            f"{prefix}_over_2deg_pct": 100 * float(np.mean(heading > 2.0))}


def run(log: str, drift: float, overrides: list[str], scans: int | None = None) -> dict:
    settings = load_settings(overrides=drift_overrides(drift) + overrides).model_copy(update={"seed": 0})
    seq = carmen_sequence(DATA / f"{log}-corrected.log.gz", settings)
    frames = list(seq.frames(0, seq.n_frames if scans is None else min(scans, seq.n_frames)))
    truth = np.array([f.ground_truth for f in frames])
    bev = RollingBEV(settings)
    fused, odometry, ms = [], [], []
    for frame in frames:
        t0 = time.perf_counter()
        bev.add(frame)
        ms.append(1e3 * (time.perf_counter() - t0))
        fused.append(bev.plane_pose(frame))
        odometry.append(plane_pose(frame.T_odom_sensor, np.eye(3), "x"))
    return {"log": log, "drift": drift, "scans": len(frames), **describe("odometry", *step_errors(np.array(odometry), truth)),
            **describe("matched", *step_errors(np.array(fused), truth)),
            "fusion_ms": float(np.median(ms)), "fusion_ms_p99": float(np.quantile(ms, 0.99))}


def main(argv=None) -> int:
    bench = Benchmark("scan_match", __doc__, settings=True)
    parser = bench.parser
    parser.add_argument("--logs", default=",".join(LOGS))
    parser.add_argument("--drift", type=float, action="append", help="odometry drift multiplier (repeatable; default 1 and 3)")
    args = bench.parse(argv)
    scans = None
    if args.quick:  # the first 30 scans of intel, drift 1
        args.logs, args.drift, scans = "intel", [1.0], 30
    logs = [name for name in args.logs.split(",") if name]
    missing = [name for name in logs if not (DATA / f"{name}-corrected.log.gz").exists()]
    if missing or not logs:
        parser.error(f"no Carmen log for {', '.join(missing) or '(none named)'} in {DATA} (have: {', '.join(LOGS)})")
    try:  # a bad --set or --drift is the settings' one error line, before any output
        for drift in args.drift or [1.0, 3.0]:
            load_settings(overrides=drift_overrides(drift) + args.set)
    except ZflocError as err:
        parser.error(str(err))
    columns = ["log", "drift", "scans"]
    for prefix, label in (("odometry", "odometry"), ("matched", "after scan matching")):
        columns += [(f"{prefix}_cm", f"{label} cm"), (f"{prefix}_cm_p90", "90%"), (f"{prefix}_deg", "deg"), (f"{prefix}_deg_p90", "90%"),
                    (f"{prefix}_over_2deg_pct", "% over 2 deg")]
    table = bench.table(columns + [("fusion_ms", "fusion ms"), ("fusion_ms_p99", "99%")],
                        title="step errors: translation cm (median, 90%), heading deg (median, 90%, share over 2 deg)")
    for drift in args.drift or [1.0, 3.0]:
        for log in logs:
            table.add(**run(log, drift, args.set, scans))
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
