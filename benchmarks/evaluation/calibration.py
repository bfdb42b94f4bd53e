"""Is Estimate.confidence calibrated? A reliability table from eval_real.py --json files
(issue 43: a threshold on the confidence must mean the same thing on every map).

Reads any mix of eval_real.py --json outputs: right-map windows (laser, camera, plan
style) and --wrong-map runs (every frame on another building's map is wrong: its rows
carry no error, so no frame of them is within 1 m). For each confidence level, the frames
at or above it and the share within 1 m of the truth, over all frames and per status.

    python -m benchmarks.evaluation.calibration laser.json camera.json wrong.json
    python -m benchmarks.evaluation.calibration --levels 0.5,0.9 --by-file laser.json wrong.json

The issue's bar: of all frames with confidence >= 0.9, at least 99% within 1 m.

--scenes: no shared data needed; every built-in scene (camera and laser, seeds 0..N-1) run
on its own map and on the next scene's map (a wrong map: no frame counts as within 1 m),
the rows written to --json and read like the others:

    python -m benchmarks.evaluation.calibration --scenes 2 --json scenes.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from concurrent.futures import ProcessPoolExecutor

import numpy as np

from zfloc_stream.estimate import STATUSES
from zfloc_stream.metrics import position_errors

LEVELS = (0.5, 0.7, 0.8, 0.9, 0.95, 0.99)


def frames_of(rows: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(status, within 1 m, confidence) of every frame of the rows; a frame without a pose
    or without an error (a wrong map) is not within 1 m, its confidence nan if missing."""
    status, within, confidence = [], [], []
    for r in rows:
        status += list(r.get("frame_status", []))
        within += [v is not None and v < 1.0 for v in r.get("frame_errors", [])]
        confidence += [np.nan if v is None else v for v in r.get("frame_confidence", [])]
    return np.array(status, dtype=object), np.array(within, dtype=bool), np.array(confidence, dtype=float)


def _cell(within: np.ndarray) -> str:
    return f"{len(within)}: {100.0 * within.mean():.1f}%" if len(within) else "0"


def reliability_table(rows: list[dict], levels=LEVELS) -> str:
    """Confidence level -> frames at or above it, share within 1 m; then per status."""
    status, within, confidence = frames_of(rows)
    lines = ["| confidence >= | frames: within 1 m | " + " | ".join(STATUSES) + " |", "|---" * (len(STATUSES) + 2) + "|"]
    for level in levels:
        mine = confidence >= level  # nan never reaches a level
        cells = [_cell(within[mine & (status == name)]) for name in STATUSES]
        lines.append(f"| {level:g} | {_cell(within[mine])} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def bins_table(rows: list[dict], edges=(0.0, 0.5, 0.7, 0.8, 0.9, 0.95, 0.99, 1.0)) -> str:
    """Confidence bin -> frames in it, share within 1 m (the calibration curve itself)."""
    _, within, confidence = frames_of(rows)
    lines = ["| confidence bin | frames | within 1 m |", "|---|---|---|"]
    for lo, hi in zip(edges[:-1], edges[1:]):
        mine = (confidence >= lo) & ((confidence < hi) if hi < 1.0 else (confidence <= hi))
        share = f"{100.0 * within[mine].mean():.1f}%" if mine.any() else "-"
        lines.append(f"| [{lo:g}, {hi:g}{')' if hi < 1.0 else ']'} | {int(mine.sum())} | {share} |")
    lines.append(f"| nan (no pose) | {int(np.isnan(confidence).sum())} | - |")
    return "\n".join(lines)


SCENE_FRAMES = 60


def scene_row(scene: str, map_of: str, sensor: str, seed: int) -> dict:
    """One built-in scene's simulated walk localized on map_of's floorplan (the same scene: the
    right map; another: a wrong one, every frame's error None)."""
    from zfloc_stream.settings.loading import Settings
    from zfloc_stream.sim import SimSettings, build_scene
    from zfloc_stream.sim.simulator import LaserSimSettings, simulate, simulate_laser
    from zfloc_stream.stream.localizer import Localizer

    world = build_scene(scene, seed=seed)
    frames = list(simulate(world, SimSettings(), seed=seed, n_frames=SCENE_FRAMES) if sensor == "camera"
                  else simulate_laser(world, LaserSimSettings(), seed=seed, n_frames=SCENE_FRAMES))
    with Localizer(world.floorplan if map_of == scene else build_scene(map_of, seed=seed).floorplan, Settings()) as loc:
        estimates = [loc.push(f) for f in frames]
    errors = position_errors([e.pose for e in estimates], np.array([f.ground_truth for f in frames]))
    right = map_of == scene
    return {"kind": f"scene {sensor}", "input": f"{scene}/{seed}", "map": map_of,
            "frame_status": [str(e.status) for e in estimates],
            "frame_errors": [float(v) if right and np.isfinite(v) else None for v in errors],
            "frame_confidence": [float(e.confidence) for e in estimates]}


def scene_rows(seeds: int, workers: int = 2) -> list[dict]:
    from zfloc_stream.sim import SCENES

    names = list(SCENES)
    jobs = [(scene, m, sensor, seed) for seed in range(seeds) for sensor in ("camera", "laser") for i, scene in enumerate(names)
            for m in (scene, names[(i + 1) % len(names)])]
    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(scene_row, *zip(*jobs)))


def read_rows(path: Path) -> list[dict]:
    rows = json.loads(path.read_text())
    return rows["rows"] if isinstance(rows, dict) and "rows" in rows else rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("files", nargs="*", type=Path, help="eval_real.py --json outputs (windows or --wrong-map runs)")
    parser.add_argument("--levels", default=",".join(map(str, LEVELS)))
    parser.add_argument("--by-file", action="store_true", help="also one table per file")
    parser.add_argument("--scenes", type=int, metavar="SEEDS", help="first run the built-in scenes on their own and the next scene's map")
    parser.add_argument("--json", type=Path, help="with --scenes: write its rows here")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args(argv)
    levels = [float(v) for v in args.levels.split(",") if v]
    if not args.files and not args.scenes:
        parser.error("give eval_real.py --json files, or --scenes")
    every = {path: read_rows(path) for path in args.files}
    if args.scenes:
        rows = scene_rows(args.scenes, args.workers)
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        every[Path("built-in scenes on their own maps")] = [r for r in rows if r["input"].split("/")[0] == r["map"]]
        every[Path("built-in scenes on the next scene's map")] = [r for r in rows if r["input"].split("/")[0] != r["map"]]
    if args.by_file:
        for path, rows in every.items():
            print(f"### {path}\n\n{reliability_table(rows, levels)}\n\n{bins_table(rows)}\n")
    everything = [r for rows in every.values() for r in rows]
    print(f"### all {len(every)} inputs\n\n{reliability_table(everything, levels)}\n\n{bins_table(everything)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
