"""Loading time of a large building's plan: a DXF of ~1,500 wall segments and its raster
(~5,000 x 5,000 cells), as a user's `run --floorplan` would load them (numbers, not asserts).

The building (seeded, drawn as an architect would): a 248 x 240 m floor, bands of rooms
of random widths along corridors, every wall a LINE, doors as gaps, the long corridor walls
drawn in pieces (one per room, so the loader's collinear merge has work), pillars as
CIRCLEs in the corridors. The raster is the same plan drawn at 0.05 m (a ROS map YAML +
PNG). Timed: Floorplan.load of each (primitives, distance field, line neighbours:
everything a floorplan computes on construction), then the RANSAC per-plan tables
(correspondences.floorplan_matches) on first use and again (cached with the plan).

    python -m benchmarks.bench_plan_load                 # goal: DXF <= 5 s, raster <= 3 s
    python -m benchmarks.bench_plan_load --keep plan/    # keep the generated files
    python -m benchmarks.bench_plan_load --set floorplan.max_triplets=500000
    python -m benchmarks.bench_plan_load --large 300 --log fhw   # issue 43: a 300 x 300 m raster
    python -m benchmarks.bench_plan_load --large 300 --vector    # the same floor as a DXF
    python -m benchmarks.bench_plan_load --honest                # issue 44: large honest drawings

--large S: a S x S m floor of the same kind drawn at 0.05 m (a raster of (S/0.05)^2 cells),
loaded with the default settings as a ROS map (pooled to floorplan.max_cells when larger):
load time of the plan and of the estimator's tables on first use, and the process's peak
memory (ru_maxrss, the whole process: imports, kernels, the image). --log L: the floor is
instead the whole-log maps of the shared Carmen logs (../shared/data/carmen/) tiled over
it, L's own map once in its corner (large_plan), and L's first --frames scans (drifting
odometry, fixed scale) are played on the whole plan: `tracking` frames and their error.

--honest: issue 44's large but honest drawings (benchmarks/inputs/plan_bombs.py, fixed seeds): a DXF of
100,000 short LINEs scattered in a 50 m square (scatter), a DXF of 100,000 LINE pieces of
walls on a 2 m grid in a 50 m square (pieces), one SVG path of 200,000 segments (path200k).
Each is loaded (load_floorplan, default settings) in a fresh process, so its peak RSS is
its own: wall and CPU seconds of the load, then of the estimator's RANSAC tables on first
use (floorplan_matches), and the process's peak RSS. Goal: load <= 10 s, peak <= 2 GiB.
--families picks some, --size scales their counts (--size 0.1: 10,000 lines).

--quick: the default measurement on a 40 x 34 m floor (two bands of rooms).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import ezdxf
import numpy as np

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.estimation.correspondences import floorplan_matches
from zfloc_stream.plans.floorplan import Floorplan, write_ros_map
from zfloc_stream.plans.loading import load_floorplan
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.plans.vector import load_vector_floorplan

from benchmarks.harness import ROOT, Benchmark
from benchmarks.inputs import plan_bombs
from benchmarks.shared_data import SHARED_DATA

WIDTH, HEIGHT = 248.0, 240.0  # m
BAND = 17.0  # m: rooms 6.5 m deep either side of a 4 m corridor
DOOR = 1.0  # m


def building_segments(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(segments (N, 2, 2), pillars (M, 3)) of the generated floor, in metres."""
    rng = make_rng(seed, "bench-plan-load")
    segs = [((0, 0), (WIDTH, 0)), ((WIDTH, 0), (WIDTH, HEIGHT)), ((WIDTH, HEIGHT), (0, HEIGHT)), ((0, HEIGHT), (0, 0))]
    pillars = []
    y0 = 0.0
    while y0 + BAND <= HEIGHT:
        corridor = (y0 + 6.5, y0 + 10.5)
        for side, (wall_y, far_y) in enumerate(((corridor[0], y0), (corridor[1], y0 + BAND))):
            x = 0.0
            while x < WIDTH - 1e-9:
                w = min(float(rng.uniform(8.0, 16.0)), WIDTH - x)
                if w < 2.5:  # a sliver at the end joins the last room
                    segs.append(((x, wall_y), (WIDTH, wall_y)))
                    break
                door = x + float(rng.uniform(0.5, w - DOOR - 0.5))
                segs.append(((x, wall_y), (door, wall_y)))  # corridor wall in pieces, a door gap
                segs.append(((door + DOOR, wall_y), (x + w, wall_y)))
                if x + w < WIDTH - 1e-9:
                    segs.append(((x + w, wall_y), (x + w, far_y)))  # partition
                x += w
        if y0 + BAND < HEIGHT - 1e-9:
            segs.append(((0, y0 + BAND), (WIDTH, y0 + BAND)))  # back wall between bands
        pillars += [(x, (corridor[0] + corridor[1]) / 2, 0.25) for x in np.arange(20.0, WIDTH - 10, 30.0)]
        y0 += BAND
    return np.array(segs, dtype=float), np.array(pillars, dtype=float).reshape(-1, 3)


def write_dxf(segments: np.ndarray, pillars: np.ndarray, path: Path) -> Path:
    doc = ezdxf.new(units=6)  # metres
    msp = doc.modelspace()
    for a, b in segments:
        msp.add_line(tuple(a), tuple(b), dxfattribs={"layer": "WALLS"})
    for x, y, r in pillars:
        msp.add_circle((x, y), r, dxfattribs={"layer": "COLUMNS"})
    doc.saveas(path)
    return path


def timed(fn):
    """(value, (wall seconds, CPU seconds of this process)): on a shared machine the CPU time
    is the fairer figure (threads of numpy / OpenCV add to it, waiting for a core does not)."""
    t0, c0 = time.perf_counter(), time.process_time()
    value = fn()
    return value, (time.perf_counter() - t0, time.process_time() - c0)


def large_plan(size: float, seed: int, out: Path, settings, log: str | None, vector: bool = False):
    """(map YAML, the Carmen log's path or None) of a size x size m floor at 0.05 m: rooms
    along corridors (building_segments), or with `log` the whole-log maps of the shared
    Carmen logs tiled over it (real walls and clutter everywhere, as one map of a large
    building would have): the log's own map once, at its own coordinates in the corner,
    the other logs' maps (turned by quarter turns in turn) filling the rest row by row.
    vector: the rooms-and-corridors floor as a DXF instead (drawn on coarser cells past
    floorplan.max_cells)."""
    global WIDTH, HEIGHT
    res, margin = 0.05, 1.0
    n = int(round((size + 2 * margin) / res))
    img = np.zeros((n, n), dtype=bool)
    origin = np.array([-margin, -margin])
    if log is None:
        WIDTH = HEIGHT = size
        segments, pillars = building_segments(seed)
        if vector:
            return write_dxf(segments, pillars, out / "large.dxf"), None
        canvas = np.zeros((n, n), dtype=np.uint8)
        for a, b in np.round((segments + margin) / res).astype(np.int32):
            cv2.line(canvas, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), 1, 2)
        for x, y, r in pillars:
            cv2.circle(canvas, (int((x + margin) / res), int((y + margin) / res)), max(1, int(r / res)), 1, -1)
        img = canvas.astype(bool)
        path = None
    else:
        from zfloc_stream.io.datasets.carmen import load_log
        from zfloc_stream.plans.map_from_log import map_from_log

        data = SHARED_DATA / "carmen"
        path = data / f"{log}-corrected.log.gz"
        maps = {name: map_from_log(load_log(data / f"{name}-corrected.log.gz", settings), [], settings, resolution=res).occupied
                for name in ("intel", "aces", "belgioioso", "fhw", "orebro")}
        own = maps.pop(log)
        others = list(maps.values())
        gap, at = 20, (20, 20)  # cells between tiles; the own map's corner
        img[at[0] : at[0] + own.shape[0], at[1] : at[1] + own.shape[1]] = own
        origin = map_from_log(load_log(path, settings), [], settings, resolution=res).origin - np.array(at[::-1]) * res
        row, col, shelf, k = at[0], at[1] + own.shape[1] + gap, own.shape[0], 0
        while True:
            tile = np.rot90(others[k % len(others)], k // len(others))
            if col + tile.shape[1] > n:  # next shelf
                row, col, shelf = row + shelf + gap, gap, 0
                if row + tile.shape[0] > n:
                    break
            if row + tile.shape[0] <= n:
                img[row : row + tile.shape[0], col : col + tile.shape[1]] = tile
                shelf = max(shelf, tile.shape[0])
            col += tile.shape[1] + gap
            k += 1
            if k > 400:
                break
    return write_ros_map(out, "large", img, res, origin), path  # the raster is written, not built


def large_main(bench, args, settings, out: Path) -> int:
    import resource

    from zfloc_stream.estimation.correlative import _near_wall_mask
    from zfloc_stream.estimation.scoring import floorplan_scorer

    plan_path, log_path = large_plan(args.large, args.seed, out, settings, args.log, args.vector)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10
    plan, t_load = timed(lambda: load_floorplan(plan_path, settings=settings))
    _, t_tables = timed(lambda: (floorplan_scorer(plan, settings.estimator.scoring), floorplan_matches(plan, settings.estimator.solvers),
                                 _near_wall_mask(plan, settings.estimator.correlative.cell, settings.estimator.correlative.tolerance)))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10
    h, w = plan.shape
    bench.note(f"plan: {args.large:.0f} x {args.large:.0f} m {'DXF' if args.vector else 'raster'} at 0.05 m -> kept {w} x {h} cells at {plan.resolution:g} m "
               f"({len(plan.lines)} lines, {len(plan.circles)} circles)")
    table = bench.table(["step", ("wall_s", "wall s"), ("cpu_s", "CPU s")], title="large plan")
    table.add(step="load_floorplan (image or drawing, pooling, field, primitives)", wall_s=t_load[0], cpu_s=t_load[1])
    table.add(step="estimator tables (scorer, RANSAC, correlative mask)", wall_s=t_tables[0], cpu_s=t_tables[1])
    table.add(step="total", wall_s=t_load[0] + t_tables[0], cpu_s=t_load[1] + t_tables[1], peak_rss_mib=peak, rss_before_mib=before)
    bench.note(f"peak RSS of the process: {peak:.0f} MiB ({before:.0f} MiB before the load: imports, kernels, the generated image)")
    if log_path is None:
        return 0
    from zfloc_stream.io.datasets.carmen import carmen_sequence
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.metrics import position_errors

    run = load_settings(overrides=args.set, base_overrides={"estimator": {"scale_mode": "fixed"}})
    seq = carmen_sequence(log_path, run)
    frames = list(seq.frames(0, min(args.frames, seq.n_frames)))
    localizer = Localizer(plan, run)
    estimates = [localizer.push(f) for f in frames]
    localizer.close()
    errors = position_errors([e.pose for e in estimates], np.array([f.ground_truth for f in frames]))
    tracking = np.array([e.status == "tracking" for e in estimates])
    first = int(np.argmax(tracking)) if tracking.any() else None
    bench.table(["log", "scans", ("first_tracking", "first tracking frame"), ("tracking", "tracking frames"),
                 ("within_1m_pct", "% of them within 1 m"), ("last_10_within_1m", "last 10 within 1 m"), ("peak_rss_mib", "peak RSS MiB")],
                title=f"the log's scans on the {args.large:.0f} m plan").add(
        log=args.log, scans=len(frames), first_tracking=first, tracking=int(tracking.sum()),
        within_1m_pct=float(np.mean(errors[tracking] < 1.0) * 100) if tracking.any() else 0.0, last_10_within_1m=bool(np.all(errors[-10:] < 1.0)),
        peak_rss_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10)
    return 0


HONEST = {  # family: (generator, its count at size 1, file suffix, scale)
    "scatter": ("dxf_scatter", 100_000, ".dxf", None),
    "pieces": ("dxf_pieces", 100_000, ".dxf", None),
    "path200k": ("svg_long_path", 200_000, ".svg", 0.01),
}


def honest_one(path: Path, scale: float | None, tables: bool) -> dict:
    """In this (fresh) process: the drawing's load, then its RANSAC tables; peak RSS."""
    import resource

    settings = load_settings()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10
    plan, t_load = timed(lambda: load_vector_floorplan(path, settings, scale=scale))  # what load_floorplan calls, with --scale
    peak_load = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10
    out = {"load_wall": t_load[0], "load_cpu": t_load[1], "peak_load": peak_load, "before": before,
           "lines": len(plan.lines), "circles": len(plan.circles), "neighbour_pairs": int(sum(len(nb) for nb in plan.line_neighbours))}
    if tables:
        _, t_tables = timed(lambda: floorplan_matches(plan, settings.estimator.solvers))
        out.update(tables_wall=t_tables[0], tables_cpu=t_tables[1], peak=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**10)
    return out


def honest_main(bench, args, out: Path) -> int:
    table = bench.table(["family", "drawing", ("kept", "lines, circles kept"), ("load_wall_s", "load wall s"), ("load_cpu_s", "load CPU s"),
                         ("peak_load_mib", "peak RSS MiB (load)"), ("tables_wall_s", "RANSAC tables wall s"), ("peak_mib", "peak RSS MiB"), "outcome"],
                        title="honest drawings")
    worst = 0.0
    for name in args.families.split(","):
        generator, count, suffix, scale = HONEST[name]
        n = max(int(count * args.size), 10)
        path = getattr(plan_bombs, generator)(out / f"{name}{suffix}", n, **({"seed": args.seed} if suffix == ".dxf" else {}))
        cmd = [sys.executable, "-m", "benchmarks.bench_plan_load", "--honest-one", str(path), "--scale", str(scale or 0)] + (["--no-tables"] if args.no_tables else [])
        drawing = f"{n:,} {'segments' if suffix == '.svg' else 'LINEs'}"
        try:
            run = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout, env=dict(os.environ), cwd=ROOT)
        except subprocess.TimeoutExpired:
            table.add(family=name, drawing=drawing, count=n, outcome=f"killed after {args.timeout:.0f} s")
            worst = float("inf")
            continue
        if run.returncode != 0:
            table.add(family=name, drawing=drawing, count=n, outcome=f"failed: {run.stderr.strip().splitlines()[-1:]}")
            worst = float("inf")
            continue
        r = json.loads(run.stdout.strip().splitlines()[-1])
        worst = max(worst, r["load_wall"])
        table.add(family=name, drawing=drawing, count=n, kept=f"{r['lines']:,}, {r['circles']} ({r['neighbour_pairs']:,} neighbour pairs)",
                  load_wall_s=r["load_wall"], load_cpu_s=r["load_cpu"], peak_load_mib=r["peak_load"], tables_wall_s=r.get("tables_wall"),
                  peak_mib=r.get("peak"), outcome="loaded", lines=r["lines"], circles=r["circles"], neighbour_pairs=r["neighbour_pairs"])
    return 0 if worst <= 10.0 else 1


def main(argv=None) -> int:
    global WIDTH, HEIGHT
    bench = Benchmark("plan_load", __doc__, seed=0, frames=150, settings=True)  # --frames: with --log, scans played
    parser = bench.parser
    parser.add_argument("--keep", type=Path, help="write the plan files here (default: a temporary folder)")
    parser.add_argument("--large", type=float, metavar="S", help="instead: a S x S m raster at 0.05 m, default settings (issue 43)")
    parser.add_argument("--log", help="with --large: a Carmen log whose map is placed in the plan and whose scans are played on it")
    parser.add_argument("--vector", action="store_true", help="with --large (no --log): the floor as a DXF drawing, not a raster")
    parser.add_argument("--honest", action="store_true", help="instead: issue 44's large honest drawings, each in a fresh process")
    parser.add_argument("--families", default=",".join(HONEST), help="with --honest: which (comma-separated)")
    parser.add_argument("--size", type=float, default=1.0, help="with --honest: counts times this")
    parser.add_argument("--no-tables", action="store_true", help="with --honest: the load only, not the RANSAC tables")
    parser.add_argument("--timeout", type=float, default=300.0, help="with --honest: seconds per family before it is killed")
    parser.add_argument("--honest-one", type=Path, help=argparse.SUPPRESS)  # the child process of --honest
    parser.add_argument("--scale", type=float, default=0.0, help=argparse.SUPPRESS)
    args = bench.parse(argv)
    if args.honest_one:
        print(json.dumps(honest_one(args.honest_one, args.scale or None, not args.no_tables)))
        return 0
    if args.quick:
        WIDTH, HEIGHT = 40.0, 34.0
    with tempfile.TemporaryDirectory() as tmp:
        out = args.keep if args.keep is not None else Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        if args.large:
            code = large_main(bench, args, load_settings(overrides=args.set), out)
            bench.done()
            return code
        if args.honest:
            code = honest_main(bench, args, out)
            bench.done()
            return code
        segments, pillars = building_segments(args.seed)
        dxf = write_dxf(segments, pillars, out / "building.dxf")
        settings = load_settings(overrides=args.set)
        # what a process pays once, whatever the plan, outside the timings: the compiled
        # kernels' load (or compile, once per machine) and the first imports (scikit-learn
        # for the raster's pillar clustering, ~1.2 s); a small plan (the corner 40 x 20 m)
        # and its raster load first
        corner = (segments[..., 0].max(axis=1) <= 40.0) & (segments[..., 1].max(axis=1) <= 20.0)
        in_corner = (pillars[:, 0] <= 40.0) & (pillars[:, 1] <= 20.0)
        warm = load_floorplan(write_dxf(segments[corner], pillars[in_corner], out / "warm.dxf"), settings=settings)
        _, t_first = timed(lambda: Floorplan.load(Floorplan.write_ros(warm, out, "warm-raster"), settings=settings))
        plan, t_dxf = timed(lambda: load_floorplan(dxf, settings=settings))
        _, t_dxf_tables = timed(lambda: floorplan_matches(plan, settings.estimator.solvers))
        _, t_dxf_cached = timed(lambda: floorplan_matches(plan, settings.estimator.solvers))
        raster_yaml = Floorplan.write_ros(plan, out, "raster")  # the base method: a plain ROS map, no vector key
        raster, t_raster = timed(lambda: Floorplan.load(raster_yaml, settings=settings))
        _, t_raster_tables = timed(lambda: floorplan_matches(raster, settings.estimator.solvers))
        h, w = raster.shape
        bench.note(f"plan: {WIDTH:.0f} x {HEIGHT:.0f} m, {len(segments)} LINE segments + {len(pillars)} pillars -> "
                   f"{len(plan.lines)} lines, {len(plan.circles)} circles")
        bench.note(f"raster: {w} x {h} cells at {raster.resolution} m -> {len(raster.lines)} lines, {len(raster.circles)} circles")
        table = bench.table(["load", ("wall_s", "wall s"), ("cpu_s", "CPU s"), ("goal_s", "goal (s)")], title="plan load")
        table.add(load="DXF plan (load_floorplan)", wall_s=t_dxf[0], cpu_s=t_dxf[1], goal_s=5.0)
        table.add(load="raster plan (Floorplan.load)", wall_s=t_raster[0], cpu_s=t_raster[1], goal_s=3.0)
        table.add(load="RANSAC tables, DXF plan (first use)", wall_s=t_dxf_tables[0], cpu_s=t_dxf_tables[1])
        table.add(load="RANSAC tables, DXF plan (cached)", wall_s=t_dxf_cached[0], cpu_s=t_dxf_cached[1])
        table.add(load="RANSAC tables, raster plan (first use)", wall_s=t_raster_tables[0], cpu_s=t_raster_tables[1])
        table.add(load="once per process: a 40 x 20 m raster's load (imports, kernels)", wall_s=t_first[0], cpu_s=t_first[1])
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
