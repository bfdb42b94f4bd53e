"""SR@1m on real buildings: held-out windows of the shared Carmen laser logs (issue 9).

For every log in ../shared/data/carmen/ and every length L, `--windows` windows of L scans
spread evenly along the log (they may overlap on short logs). Each window:

- floorplan: map-from-log of the same log leaving the window and heldout_margin (25)
  scans either side out, so every wall seen comes from other passes (clutter, missing rooms);
- odometry: the true relative motion with realistic drift (datasets.odometry: per step
  2% of the step + 5 mm per axis, 2% of the turn + 0.3 deg), from a random origin;
- zfloc-stream: a fresh Localizer pushed the window's frames (what `run` writes to
  trajectory.csv, frame by frame);
- reference: exact correlative SE(2) search (0.1 m / 2 deg grid + LM, known scale) on all
  the window's wall points at once (zfloc_stream.estimation.correlative);
- success (F3Loc): all of the last 10 frames within 1 m. A failure is attributed to "no
  pose" (a last-10 frame without pose), "lost" (final status lost) or "wrong mode".

    python benchmarks/eval_real.py                         # 5 logs x 5 lengths x 8 windows
    python benchmarks/eval_real.py --logs intel --lengths 20,50 --windows 3 --workers 2
    python benchmarks/eval_real.py --no-reference --set tracking.weight_gain=10
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from zfloc_stream.config import load_settings
from zfloc_stream.datasets.carmen import carmen_sequence, load_log
from zfloc_stream.estimation.correlative import correlative_search
from zfloc_stream.localizer import Localizer
from zfloc_stream.metrics import is_success, position_errors

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "carmen"
LOGS = ["intel", "aces", "belgioioso", "fhw", "orebro"]
LENGTHS = [15, 20, 35, 50, 100]


def window_starts(n_scans: int, length: int, count: int) -> list[int]:
    return sorted({int(round(s)) for s in np.linspace(0, n_scans - length, count)})


def laser_points(frame) -> np.ndarray:
    """Wall hits of a LaserFrame in the odometry plane."""
    ok = frame.valid
    a = frame.angles[ok]
    r = frame.ranges[ok]
    local = np.column_stack([r * np.cos(a), r * np.sin(a)])
    T = frame.T_odom_sensor
    return local @ T[:2, :2].T + T[:2, 3]


def run_window(log: str, start: int, length: int, seed: int, overrides: list[str], reference: bool) -> dict:
    path = DATA / f"{log}-corrected.log.gz"
    base = {"estimator": {"scale_mode": "fixed"}}
    settings = load_settings(overrides=overrides, base_overrides=base).model_copy(update={"seed": seed})
    seq = carmen_sequence(path, settings)
    stop = start + length
    floorplan = seq.floorplan_for(start, stop)
    frames = list(seq.frames(start, stop))
    truth = np.array([f.ground_truth for f in frames])
    row = {"log": log, "start": start, "length": length, "seed": seed}

    t0 = time.perf_counter()
    localizer = Localizer(floorplan, settings)
    estimates = [localizer.push(f) for f in frames]
    row["seconds"] = time.perf_counter() - t0
    errors = position_errors([e.pose for e in estimates], truth)
    row["success"] = is_success(errors, 1.0)
    row["final_error"] = float(errors[-1])
    row["final_status"] = estimates[-1].status
    first = next((i for i, e in enumerate(estimates) if e.pose is not None), None)
    row["first_pose_frame"] = first
    if row["success"]:
        row["cause"] = ""
    elif not np.isfinite(errors[-10:]).all():
        row["cause"] = "no pose"
    elif estimates[-1].status == "lost":
        row["cause"] = "lost"
    else:
        row["cause"] = "wrong mode"

    if reference:
        t0 = time.perf_counter()
        points = np.concatenate([laser_points(f) for f in frames])
        best = correlative_search(floorplan, points)[0]
        odom = [f.T_odom_sensor for f in frames]
        poses = [np.array(best.alignment.apply_pose(T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0]))) for T in odom]
        ref_errors = position_errors(poses, truth)
        row["ref_seconds"] = time.perf_counter() - t0
        row["ref_success"] = is_success(ref_errors, 1.0)
        row["ref_final_error"] = float(ref_errors[-1])
    return row


def _pct(values) -> str:
    return f"{100 * np.mean(values):.0f}%" if len(values) else "-"


def table(rows: list[dict], lengths: list[int], reference: bool) -> str:
    by_len = defaultdict(list)
    for r in rows:
        by_len[r["length"]].append(r)
    head = "| method | " + " | ".join(f"#{L}" for L in lengths) + " | all | median s/window |"
    lines = [head, "|---" * (len(lengths) + 3) + "|"]
    ours = [_pct([r["success"] for r in by_len[L]]) for L in lengths]
    lines.append(f"| zfloc-stream (online) | {' | '.join(ours)} | {_pct([r['success'] for r in rows])} | "
                 f"{np.median([r['seconds'] for r in rows]):.2f} |")
    if reference:
        ref = [_pct([r["ref_success"] for r in by_len[L]]) for L in lengths]
        lines.append(f"| exact correlative search (batch) | {' | '.join(ref)} | {_pct([r['ref_success'] for r in rows])} | "
                     f"{np.median([r['ref_seconds'] for r in rows]):.2f} |")
    lines += ["", "| building | " + " | ".join(f"#{L}" for L in lengths) + " | windows | failures: no pose / lost / wrong mode |",
              "|---" * (len(lengths) + 3) + "|"]
    for log in dict.fromkeys(r["log"] for r in rows):
        mine = [r for r in rows if r["log"] == log]
        cells = [_pct([r["success"] for r in mine if r["length"] == L]) for L in lengths]
        causes = [sum(r["cause"] == c for r in mine) for c in ("no pose", "lost", "wrong mode")]
        lines.append(f"| {log} | {' | '.join(cells)} | {len(mine)} | {causes[0]} / {causes[1]} / {causes[2]} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", default=",".join(LOGS))
    parser.add_argument("--lengths", default=",".join(map(str, LENGTHS)))
    parser.add_argument("--windows", type=int, default=8, help="windows per log and length")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-reference", action="store_true", help="skip the brute-force reference")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="settings override")
    parser.add_argument("--json", type=Path, help="write every window's row here")
    args = parser.parse_args(argv)
    logs = [s for s in args.logs.split(",") if s]
    lengths = [int(v) for v in args.lengths.split(",")]
    jobs = []
    for log in logs:
        n = len(load_log(DATA / f"{log}-corrected.log.gz", load_settings()))
        for length in lengths:
            jobs += [(log, s, length, args.seed, args.set, not args.no_reference) for s in window_starts(n, length, args.windows)]
    t0 = time.perf_counter()
    if args.workers > 1:
        with ProcessPoolExecutor(args.workers) as pool:
            rows = list(pool.map(run_window, *zip(*jobs)))
    else:
        rows = [run_window(*job) for job in jobs]
    print(table(rows, lengths, not args.no_reference))
    print(f"\n{len(rows)} windows in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
