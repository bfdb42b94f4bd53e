"""Where a laser window breaks on a plan: per stage, for windows of eval_real.py --plan-style.

For each window (laser, held-out map drawn as a plan; the raster map beside it):
- truth: the Sim2 odometry plane -> floorplan that puts the BEV's frames (their plane poses
  as fused) on their true positions (least squares, rigid: the laser runs at fixed scale),
  refined on the final BEV like any hypothesis;
- score: C, Cc, Cv of that true alignment and of the localizer's winner on the final BEV:
  "score" when the winner scores higher than the truth (the score prefers a wrong alignment),
  "search" when the truth scores higher but no hypothesis of the last round lies within 1 m
  of it (seeding / primitives never proposed it), "tracking" otherwise (proposed, scored
  best, not reported);
- primitives: lines of the plan vs the raster map, BEV lines.

    python -m benchmarks.evaluation.plan_diagnose --rows rows.json            # the failures of a --json run
    python -m benchmarks.evaluation.plan_diagnose --window intel/100/50 --plan-style two-face
    python -m benchmarks.evaluation.plan_diagnose --rows rows.json --set estimator.scoring.violation_weight=0
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from zfloc_stream.estimation.results import alignment_of, model_rows
from zfloc_stream.estimation.field_fit import refine_batch
from zfloc_stream.estimation.scoring import floorplan_scorer, score_hypotheses
from zfloc_stream.geometry.sim2 import Sim2

from benchmarks.evaluation import eval_real


def true_alignment(plane_poses, truth) -> Sim2:
    """Rigid least-squares fit of the plane positions onto the true positions."""
    p = np.array([q[:2] for q in plane_poses], dtype=float)
    t = np.array([q[:2] for q in truth], dtype=float)
    pc, tc = p.mean(axis=0), t.mean(axis=0)
    u, _, vt = np.linalg.svd((p - pc).T @ (t - tc))
    r = (u @ vt).T
    if np.linalg.det(r) < 0:
        vt[-1] *= -1
        r = (u @ vt).T
    theta = float(np.arctan2(r[1, 0], r[0, 0]))
    return Sim2(1.0, theta, tc - r @ pc)


def stage_row(floorplan, localizer, frames, settings) -> dict:
    obs, result = localizer.last_observation, localizer.last_result
    est = settings.estimator
    truth = true_alignment(localizer.plane_poses, [f.ground_truth for f in frames])
    field = floorplan_scorer(floorplan, est.scoring).face_field
    refined = alignment_of(refine_batch(field, obs.wall_points, model_rows([truth]), est.refine, "fixed")[0])
    centre = obs.wall_points.mean(axis=0)
    if np.linalg.norm(refined.apply(centre) - truth.apply(centre)) < 0.5:
        truth = refined
    best = result.best if result is not None else None
    models = [truth] + ([best.alignment] if best is not None else [])
    s = score_hypotheses(floorplan, obs, model_rows(models), est.scoring)
    near = [k for k, h in enumerate(result.hypotheses if result else [])
            if np.linalg.norm(h.alignment.apply(centre) - truth.apply(centre)) < 1.0]
    row = {"truth_C": float(s.total[0]), "truth_Cc": float(s.consistency[0]), "truth_Cv": float(s.violation[0]),
           "win_C": float(s.total[1]) if best else float("nan"), "win_Cc": float(s.consistency[1]) if best else float("nan"),
           "win_Cv": float(s.violation[1]) if best else float("nan"),
           "truth_rank": near[0] if near else None, "hypotheses": len(result.hypotheses) if result else 0,
           "fp_lines": len(floorplan.lines), "bev_lines": len(obs.lines)}
    if best is not None and np.linalg.norm(best.alignment.apply(centre) - truth.apply(centre)) < 1.0:
        row["stage"] = "tracking"  # the last round's winner is right
    elif best is not None and s.total[1] > s.total[0]:
        row["stage"] = "score"
    elif not near:
        row["stage"] = "search"
    else:
        row["stage"] = "tracking"
    return row


def diagnose(log: str, start: int, length: int, style: str, overrides: list[str]) -> dict:
    settings, raster, frames = eval_real.laser_window(log, start, length, overrides)
    plan = eval_real.plan_of(raster, settings, style, log, start, start + length)
    out = {"log": log, "start": start, "length": length}
    for name, fp in (("plan", plan), ("raster", raster)):
        result, localizer = eval_real.localize_frames(fp, frames, settings)
        row = stage_row(fp, localizer, frames, settings)
        out.update({f"{name}_{k}": v for k, v in row.items()}, **{f"{name}_success": result["success"]})
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", type=Path, help="eval_real.py --plan-style --json output: its failed laser windows")
    parser.add_argument("--window", action="append", default=[], metavar="LOG/START/LENGTH")
    parser.add_argument("--plan-style", default="one-face", choices=eval_real.PLAN_STYLES)
    parser.add_argument("--all", action="store_true", help="with --rows: every laser window, not only the failures")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    windows = []
    for w in args.window:
        try:
            log, start, length = w.split("/")
            windows.append((log, int(start), int(length)))
        except ValueError:
            parser.error(f"--window must be LOG/START/LENGTH, got {w!r}")
    if args.rows:
        rows = json.loads(args.rows.read_text())
        windows += [(r["log"], r["start"], r["length"]) for r in rows if r["sensor"] == "laser" and (args.all or not r["success"])]
    if not windows:
        parser.error("no windows: pass --rows or --window")
    found = [diagnose(*w, args.plan_style, args.set) for w in windows]
    print("| window | plan: stage | truth C (Cc / Cv) | winner C (Cc / Cv) | raster: stage | truth C | winner C |")
    print("|---|---|---|---|---|---|---|")
    for r in found:
        print(f"| {r['log']}/{r['start']}/{r['length']} | {r['plan_stage']}{' (ok)' if r['plan_success'] else ''} | "
              f"{r['plan_truth_C']:.3f} ({r['plan_truth_Cc']:.3f} / {r['plan_truth_Cv']:.3f}) | "
              f"{r['plan_win_C']:.3f} ({r['plan_win_Cc']:.3f} / {r['plan_win_Cv']:.3f}) | "
              f"{r['raster_stage']}{' (ok)' if r['raster_success'] else ''} | {r['raster_truth_C']:.3f} | {r['raster_win_C']:.3f} |")
    stages = [r["plan_stage"] for r in found if not r["plan_success"]]
    print(f"\nplan failures by stage: " + ", ".join(f"{s} {stages.count(s)}" for s in ("score", "search", "tracking")))
    if args.json:
        args.json.write_text(json.dumps(found, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
