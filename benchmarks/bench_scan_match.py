"""Scan matching on the real laser logs: how much of the odometry's per-step error the
scan matcher leaves, and what fusing a scan costs (numbers, not asserts).

Each shared Carmen log, whole, fused into a RollingBEV from drifting odometry (as
benchmarks/eval_real.py makes it: datasets.odometry, times --drift). For every step
between consecutive scans, the relative motion of the plane poses (as fused) is compared
with the true relative motion: translation error (cm) and heading error (deg), for the raw
odometry and after matching. The share of steps whose heading error exceeds 2 deg is what
smears the BEV and moves the pose off (docs/status.md, "Scan matching under cheap
odometry").

    python benchmarks/bench_scan_match.py                       # drift 1 and 3, every log
    python benchmarks/bench_scan_match.py --drift 3 --logs orebro
    python benchmarks/bench_scan_match.py --set bev.scan_match=none
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from eval_real import DATA, LOGS, drift_overrides  # noqa: E402

from zfloc_stream.settings.loading import load_settings  # noqa: E402
from zfloc_stream.io.datasets.carmen import carmen_sequence  # noqa: E402
from zfloc_stream.errors import ZflocError  # noqa: E402
from zfloc_stream.frontend.bev import RollingBEV, plane_pose  # noqa: E402
from zfloc_stream.geometry.sim2 import wrap_angle  # noqa: E402


def relative_steps(poses: np.ndarray) -> np.ndarray:
    """(n - 1, 3): each step's motion (dx, dy in the earlier pose's frame, dyaw)."""
    d = poses[1:, :2] - poses[:-1, :2]
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], wrap_angle(np.diff(poses[:, 2]))])


def step_errors(poses: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per step: translation error (m) and absolute heading error (deg)."""
    e = relative_steps(poses) - relative_steps(truth)
    return np.hypot(e[:, 0], e[:, 1]), np.rad2deg(np.abs(wrap_angle(e[:, 2])))


def describe(translation: np.ndarray, heading: np.ndarray) -> str:
    return (f"{100 * np.median(translation):5.1f} {100 * np.quantile(translation, 0.9):5.1f} | "
            f"{np.median(heading):5.2f} {np.quantile(heading, 0.9):5.2f} {100 * np.mean(heading > 2.0):5.1f}%")


def run(log: str, drift: float, overrides: list[str]) -> str:
    settings = load_settings(overrides=drift_overrides(drift) + overrides).model_copy(update={"seed": 0})
    seq = carmen_sequence(DATA / f"{log}-corrected.log.gz", settings)
    frames = list(seq.frames(0, seq.n_frames))
    truth = np.array([f.ground_truth for f in frames])
    bev = RollingBEV(settings)
    fused, odometry, ms = [], [], []
    for frame in frames:
        t0 = time.perf_counter()
        bev.add(frame)
        ms.append(1e3 * (time.perf_counter() - t0))
        fused.append(bev.plane_pose(frame))
        odometry.append(plane_pose(frame.T_odom_sensor, np.eye(3), "x"))
    raw = describe(*step_errors(np.array(odometry), truth))
    matched = describe(*step_errors(np.array(fused), truth))
    return (f"| {log} | {drift:g} | {len(frames)} | {raw} | {matched} | "
            f"{np.median(ms):.2f} / {np.quantile(ms, 0.99):.2f} |")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", default=",".join(LOGS))
    parser.add_argument("--drift", type=float, action="append", help="odometry drift multiplier (repeatable; default 1 and 3)")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="settings override")
    args = parser.parse_args(argv)
    logs = [name for name in args.logs.split(",") if name]
    missing = [name for name in logs if not (DATA / f"{name}-corrected.log.gz").exists()]
    if missing or not logs:
        parser.error(f"no Carmen log for {', '.join(missing) or '(none named)'} in {DATA} (have: {', '.join(LOGS)})")
    try:  # a bad --set or --drift is the settings' one error line, before any output
        for drift in args.drift or [1.0, 3.0]:
            load_settings(overrides=drift_overrides(drift) + args.set)
    except ZflocError as err:
        parser.error(str(err))
    print("step errors: translation cm (median, 90%) | heading deg (median, 90%, share over 2 deg)\n")
    print("| log | drift | scans | odometry | after scan matching | fusion ms (median / 99%) |")
    print("|---|---|---|---|---|---|")
    for drift in args.drift or [1.0, 3.0]:
        for log in logs:
            print(run(log, drift, args.set), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
