"""SR@1m vs sequence length on the built-in scenes (the issue-4 table).

Each seed simulates one sequence of max(lengths) frames and runs the online localizer once.
Because the localizer is causal, the estimate at frame L-1 of that run is exactly what a
run on the first L frames alone would report, so SR at length L is read off the prefix:
success = all of frames L-10 .. L-1 within 1 m (F3Loc protocol, zfloc_stream.metrics).

    python benchmarks/eval_scenes.py --scenes apartment --seeds 20
    python benchmarks/eval_scenes.py --scenes rooms,apartment,office,symmetric,hall --seeds 20 --workers 2
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from zfloc_stream.config import load_settings
from zfloc_stream.localizer import Localizer
from zfloc_stream.metrics import is_success, position_errors, run_rmse
from zfloc_stream.sim import build_scene
from zfloc_stream.sim.simulator import SimSettings, simulate


def run_one(scene_name: str, seed: int, n_frames: int, overrides: list[str]) -> dict:
    settings = load_settings(overrides=overrides).model_copy(update={"seed": seed})
    scene = build_scene(scene_name, seed=seed)
    sequence = simulate(scene, SimSettings(), seed=seed, n_frames=n_frames)
    with Localizer(scene.floorplan, settings) as localizer:  # closing stops an online round worker
        t0 = time.perf_counter()
        estimates = [localizer.push(frame) for frame in sequence]
        seconds = time.perf_counter() - t0
    errors = position_errors([e.pose for e in estimates], sequence.poses)
    return {"scene": scene_name, "seed": seed, "errors": errors, "seconds": seconds,
            "statuses": [e.status for e in estimates]}


def table(results: list[dict], lengths: list[int]) -> str:
    lines = ["| scene | " + " | ".join(f"SR@1m #{n}" for n in lengths) + " | RMSE_succ #100 | RMSE_all #100 | s/frame |",
             "|---|" + "---|" * (len(lengths) + 3)]
    for scene in dict.fromkeys(r["scene"] for r in results):
        runs = [r for r in results if r["scene"] == scene]
        cells = []
        for n in lengths:
            ok = [is_success(r["errors"][:n], 1.0) for r in runs]
            cells.append(f"{100 * np.mean(ok):.0f}%")
        n = max(lengths)
        rmse = np.array([run_rmse(r["errors"][:n]) for r in runs])
        ok = np.array([is_success(r["errors"][:n], 1.0) for r in runs])
        succ = f"{np.sqrt(np.mean(rmse[ok] ** 2)):.2f}" if ok.any() else "-"
        finite = np.isfinite(rmse)
        all_ = f"{np.sqrt(np.mean(rmse[finite] ** 2)):.2f}" if finite.any() else "-"
        per_frame = sum(r["seconds"] for r in runs) / (len(runs) * n)
        cells += [succ, all_, f"{per_frame * 1000:.0f} ms"]
        lines.append(f"| {scene} ({len(runs)} seeds) | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", default="apartment")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--lengths", default="15,20,35,50,100")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--set", action="append", default=[], help="settings override key=value")
    args = ap.parse_args()
    lengths = [int(v) for v in args.lengths.split(",")]
    jobs = [(s, seed, max(lengths), args.set) for s in args.scenes.split(",") for seed in range(args.seeds)]
    with ProcessPoolExecutor(args.workers) as pool:
        results = list(pool.map(run_one, *zip(*jobs)))
    for r in results:
        fails = [n for n in lengths if not is_success(r["errors"][:n], 1.0)]
        if fails:
            print(f"  {r['scene']} seed {r['seed']}: fails at {fails}; final err {r['errors'][-1]:.2f} m, status {r['statuses'][-1]}")
    print(table(results, lengths))


if __name__ == "__main__":
    main()
