"""Every round of a laser window, plan beside raster map: what each round saw and chose.

plan_diagnose.py judges the final BEV; a short window (#15: success needs frames 5-14
within 1 m) is decided by its first rounds. For each round that lands (the preview and
every tracker round), on that round's own BEV:
- truth: the rigid fit of the plane poses fused so far onto their true positions,
  refined on the round's BEV (plan_diagnose.true_alignment), and its C (Cc / Cv);
- the round's winner and runner-up (C, Cc / Cv, metres off the truth at the BEV's centre);
- truth_rank: the first hypothesis within 1 m of the truth (None: never proposed);
- the frame's reported pose error after the round landed.

    python -m benchmarks.evaluation.round_diagnose --window aces/0/15 --window orebro/0/15
    python -m benchmarks.evaluation.round_diagnose --rows rows.json --lengths 15   # failures of a --plan-style run
    python -m benchmarks.evaluation.round_diagnose --camera --window intel/810/100
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from zfloc_stream import Localizer
from zfloc_stream.estimation.field_fit import refine_batch
from zfloc_stream.estimation.results import alignment_of, model_rows
from zfloc_stream.estimation.scoring import floorplan_scorer, score_hypotheses

from benchmarks.evaluation import eval_real
from benchmarks.evaluation.plan_diagnose import true_alignment


def _off(a, b, centre) -> float:
    return float(np.linalg.norm(a.apply(centre) - b.apply(centre)))


def rounds_of(floorplan, frames, settings) -> tuple[list[dict], list[float]]:
    """Push the frames; one row per landed round (see the module docstring), and the
    per-frame position errors."""
    localizer = Localizer(floorplan, settings)
    landed: list = []
    apply = localizer._apply

    def recording(scheduled, outcome, timings):
        why = apply(scheduled, outcome, timings)
        landed.append((scheduled, outcome, localizer.frames_pushed))
        return why

    localizer._apply = recording
    estimates, plane_poses = [], []
    for f in frames:
        estimates.append(localizer.push(f))
        plane_poses.append(localizer.bev.plane_pose(f))
    localizer.close()
    truth_xy = np.array([f.ground_truth[:2] for f in frames])
    errors = [float(np.linalg.norm(np.asarray(e.pose[:2]) - t)) if e.pose is not None else float("nan")
              for e, t in zip(estimates, truth_xy)]
    est = settings.estimator
    field = floorplan_scorer(floorplan, est.scoring).face_field
    rows = []
    for scheduled, outcome, pushed in landed:
        obs, result = outcome.observation, outcome.result
        k = scheduled.job.index
        row = {"round": k, "lands": pushed - 1, "preview": scheduled.preview, "audit": scheduled.job.audit,
               "skipped": outcome.skipped}
        if obs is None or result is None or k < 2:
            rows.append(row)
            continue
        truth = true_alignment(plane_poses[: k + 1], [f.ground_truth for f in frames[: k + 1]])
        centre = obs.wall_points.mean(axis=0)
        refined = alignment_of(refine_batch(field, obs.wall_points, model_rows([truth]), est.refine, "fixed")[0])
        if _off(refined, truth, centre) < 0.5:
            truth = refined
        hyps = result.hypotheses
        models = [truth] + [h.alignment for h in hyps[:2]]
        s = score_hypotheses(floorplan, obs, model_rows(models), est.scoring)
        near = [i for i, h in enumerate(hyps) if _off(h.alignment, truth, centre) < 1.0]
        row.update(wall_points=len(obs.wall_points), bev_lines=len(obs.lines), hypotheses=len(hyps),
                   truth_C=float(s.total[0]), truth_Cc=float(s.consistency[0]), truth_Cv=float(s.violation[0]),
                   truth_rank=near[0] if near else None,
                   truth_solver=hyps[near[0]].solver if near else None,
                   error_after=errors[pushed - 1])
        for j, name in ((1, "win"), (2, "second")):
            if len(hyps) >= j:
                row.update({f"{name}_C": float(s.total[j]), f"{name}_Cc": float(s.consistency[j]),
                            f"{name}_Cv": float(s.violation[j]), f"{name}_off": _off(hyps[j - 1].alignment, truth, centre),
                            f"{name}_solver": hyps[j - 1].solver})
        rows.append(row)
    return rows, errors


def camera_window(log: str, start: int, length: int, overrides=(), seed: int = 0):
    """(settings, floorplan, frames) of eval_real.py's camera window (run_window, camera=True)."""
    settings = eval_real.load_settings(overrides=[*eval_real.CAMERA_RIG, *overrides]).model_copy(update={"seed": seed})
    seq = eval_real.carmen_sequence(eval_real.DATA / f"{log}-corrected.log.gz", settings)
    truth = seq.ground_truth[start : start + length]
    frames = eval_real.simulate(eval_real.world_of(log), eval_real.camera_settings(None), seed=seed + start, trajectory=truth).frames
    return settings, seq.floorplan_for(start, start + length), frames


def diagnose(log: str, start: int, length: int, style: str, overrides: list[str], camera: bool = False, seed: int = 0) -> dict:
    window = camera_window if camera else eval_real.laser_window
    settings, raster, frames = window(log, start, length, overrides, seed)
    plan = eval_real.plan_of(raster, settings, style, log, start, start + length)
    out = {"log": log, "start": start, "length": length}
    for name, fp in (("plan", plan), ("raster", raster)):
        rows, errors = rounds_of(fp, frames, settings)
        out[name] = {"rounds": rows, "errors": errors,
                     "success": bool(np.all(np.isfinite(errors[-10:])) and np.nanmax(errors[-10:]) < 1.0)}
    return out


def _fmt(r: dict) -> str:
    if "truth_C" not in r:
        return f"  round {r['round']:>3} (lands {r['lands']}){' preview' if r['preview'] else ''}: skipped {r['skipped']}"
    parts = [f"  round {r['round']:>3} (lands {r['lands']}){' preview' if r['preview'] else ''}{' audit' if r['audit'] else ''}:",
             f"pts {r['wall_points']:>5} lines {r['bev_lines']:>3} hyps {r['hypotheses']:>2}",
             f"truth {r['truth_C']:.3f} ({r['truth_Cc']:.3f}/{r['truth_Cv']:.3f}) rank {r['truth_rank']} {r['truth_solver']}"]
    for name in ("win", "second"):
        if f"{name}_C" in r:
            parts.append(f"{name} {r[f'{name}_C']:.3f} ({r[f'{name}_Cc']:.3f}/{r[f'{name}_Cv']:.3f}) "
                         f"{r[f'{name}_off']:.1f} m {r[f'{name}_solver']}")
    parts.append(f"err {r['error_after']:.2f}")
    return " | ".join(parts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rows", type=Path, help="eval_real.py --plan-style --json output: its failed laser windows")
    parser.add_argument("--lengths", default="", help="with --rows: only these lengths")
    parser.add_argument("--all", action="store_true", help="with --rows: every laser window, not only the failures")
    parser.add_argument("--window", action="append", default=[], metavar="LOG/START/LENGTH")
    parser.add_argument("--plan-style", default="one-face", choices=eval_real.PLAN_STYLES)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--seed", type=int, default=0, help="eval_real.py's --seed (odometry noise, the localizer's seed)")
    parser.add_argument("--camera", action="store_true", help="eval_real.py's camera windows instead of laser")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    windows = []
    for w in args.window:
        log, start, length = w.split("/")
        windows.append((log, int(start), int(length)))
    if args.rows:
        lengths = {int(v) for v in args.lengths.split(",") if v}
        rows = json.loads(args.rows.read_text())
        windows += [(r["log"], r["start"], r["length"]) for r in rows if r["sensor"] == ("camera" if args.camera else "laser")
                    and (args.all or not r["success"]) and (not lengths or r["length"] in lengths)]
    if not windows:
        parser.error("no windows: pass --rows or --window")
    found = []
    for w in windows:
        d = diagnose(*w, args.plan_style, args.set, args.camera, args.seed)
        found.append(d)
        for name in ("plan", "raster"):
            print(f"{d['log']}/{d['start']}/{d['length']} {name}: {'ok' if d[name]['success'] else 'FAIL'}; errors "
                  + " ".join(f"{e:.1f}" for e in d[name]["errors"]))
            for r in d[name]["rounds"]:
                print(_fmt(r))
        sys.stdout.flush()
    print(summary(found))
    if args.json:
        args.json.write_text(json.dumps(found, indent=1, default=str))
    return 0


def first_round_stage(r: dict) -> str:
    """What decided a window's first tracker round (frame 4): "right" (its winner within
    1 m of the truth), "search" (the truth scores above the winner but no hypothesis lies
    within 1 m of it: never proposed), "score" (a wrong place scores above the truth)."""
    if r.get("win_off", float("inf")) < 1.0:
        return "right"
    return "search" if r["truth_C"] >= r.get("win_C", -np.inf) else "score"


def summary(found: list[dict]) -> str:
    """One row per window: its first tracker round on the plan and on the raster map."""
    lines = ["| window | map | success | first round: stage | truth C (Cc / Cv) | winner C (Cc / Cv), m off | runner-up C |",
             "|---|---|---|---|---|---|---|"]
    for d in found:
        for name in ("plan", "raster"):
            first = next((r for r in d[name]["rounds"] if not r["preview"] and not r["audit"] and "truth_C" in r), None)
            if first is None:
                lines.append(f"| {d['log']}/{d['start']}/{d['length']} | {name} | {d[name]['success']} | no round | | | |")
                continue
            win = (f"{first['win_C']:.3f} ({first['win_Cc']:.3f} / {first['win_Cv']:.3f}), {first['win_off']:.1f}"
                   if "win_C" in first else "-")
            lines.append(f"| {d['log']}/{d['start']}/{d['length']} | {name} | {d[name]['success']} | {first_round_stage(first)} | "
                         f"{first['truth_C']:.3f} ({first['truth_Cc']:.3f} / {first['truth_Cv']:.3f}) | {win} | "
                         f"{first.get('second_C', float('nan')):.3f} |")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
