"""Cost of a round by stage, and push latency inline vs pipelined (issue 10).

Stages: every round of each case, run inline (so the round runs in the push that starts
it and nothing else shares its time), wall (perf_counter) and CPU (thread_time of the
thread that ran the stage; BLAS helper threads not counted) of primitives,
model_estimation, scoring, refinement, tracking and their sum per round, and of fusion
per fused frame (fusion + monitor: a push that neither starts nor applies a round);
median and p95. Cases: built-in scenes (camera 160x120, laser), the shared real camera
sessions (../shared/data/sessions/*/session.mcap against map.yaml beside it) at fixed,
prior and free scale, and windows of a Carmen laser log localized against the map of the
log without the window (as benchmarks/evaluation/eval_real.py).

Push latency: a 640x480 camera walk on a built-in scene, with labels and without (the
geometric labeller labels each frame), median / p99 / max of the push wall time over all
frames and max over the frames where a round starts or joins, inline vs pipelined (one
worker thread; --process adds a worker process). Frames are rendered before timing.

    python -m benchmarks.bench_round --short        # a few minutes on 2 cores
    python -m benchmarks.bench_round                # more scenes, frames and windows
    python -m benchmarks.bench_round --quick        # a smoke run: one scene, a few frames
    python -m benchmarks.bench_round --defaults --rate 0      # the package defaults on real data
    PYTHONPATH=../main:. python benchmarks/bench_round.py --defaults --rate 0   # another checkout's package
    python -m benchmarks.bench_round --defaults --rate 10 --frame-kinds       # join / start / plain frames apart

--defaults (issue 25): push latency with the package defaults through the Python API on
the shared camera sessions belgioioso-camera-50 and fhw-camera-50 (metric prior) and two
50-scan Carmen laser windows (fhw, intel; fixed scale), one warm-up pass: median, p99,
amortized, the first frame with a pose and the slowest push. Measurements, with their date
and commit, are in docs/performance.md (this script's earlier ones too).
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.io.datasets.carmen import carmen_sequence
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.io.session import read_session
from zfloc_stream.sim import LaserSimSettings, SimSettings, build_scene, simulate, simulate_laser

from benchmarks.harness import Benchmark
from benchmarks.shared_data import SHARED_DATA as SHARED
STAGES = ("fusion", "primitives", "model_estimation", "scoring", "refinement", "tracking", "local_refinement", "round")


def stage_times(floorplan, frames, settings) -> dict[str, tuple[list, list]]:
    """{stage: (wall seconds, CPU seconds)} over the rounds (fusion: over the fused frames)."""
    out: dict[str, tuple[list, list]] = defaultdict(lambda: ([], []))
    with Localizer(floorplan, settings) as loc:
        for frame in frames:
            last = loc.last_round
            c0 = time.thread_time()
            est = loc.push(frame)
            cpu = time.thread_time() - c0
            if loc.last_round is not last:
                r = loc.last_round
                for k in r.timings:
                    out[k][0].append(r.timings[k])
                    out[k][1].append(r.cpu_timings.get(k, np.nan))
                out["round"][0].append(sum(r.timings.values()))
                out["round"][1].append(sum(r.cpu_timings.values()))
            elif "fusion" in est.timings:
                out["fusion"][0].append(est.timings["fusion"])
                out["fusion"][1].append(cpu)
    return out


def add_stages(table, name: str, times: dict) -> None:
    """One row per stage of a case: median and p95 of wall and CPU ms."""
    n = len(times.get("round", ([], []))[0])
    for stage in STAGES:
        wall, cpu = (np.array(v) * 1000 for v in times.get(stage, ([], [])))
        if len(wall):
            table.add(case=name, rounds=n, stage=stage, n=len(wall), wall_median_ms=float(np.median(wall)), wall_p95_ms=float(np.percentile(wall, 95)),
                      cpu_median_ms=float(np.nanmedian(cpu)), cpu_p95_ms=float(np.nanpercentile(cpu, 95)))


def scene_cases(size: str):
    quick = size != "full"
    frames = {"quick": 15, "short": 40, "full": 100}[size]
    for name in ("apartment",) if quick else ("apartment", "office", "hall"):
        scene = build_scene(name, seed=0)
        yield f"scene {name} camera", scene.floorplan, simulate(scene, SimSettings(), seed=0, n_frames=frames).frames, []
    scene = build_scene("office", seed=1)
    yield "scene office laser", scene.floorplan, simulate_laser(scene, LaserSimSettings(), seed=1, n_frames=frames).frames, ["estimator.scale_mode=fixed"]


def session_cases(size: str):
    sessions = sorted((SHARED / "sessions").glob("*/session.mcap"))
    if not sessions:
        print(f"(no shared sessions under {SHARED / 'sessions'}: skipped)")
    for path in {"quick": sessions[:1], "short": sessions[:2], "full": sessions}[size]:
        frames = list(read_session(path).frames())
        if size == "quick":
            frames = frames[:15]
        for mode in ("prior",) if size == "quick" else ("fixed", "prior", "free"):
            overrides = [f"estimator.scale_mode={mode}"]
            plan = Floorplan.load(path.parent / "map.yaml", settings=load_settings(overrides=overrides))
            yield f"{path.parent.name} {mode}", plan, frames, overrides


def carmen_cases(size: str):
    log = SHARED / "carmen" / "intel-corrected.log.gz"
    if not log.exists():
        print(f"(no Carmen log {log}: skipped)")
        return
    overrides = ["estimator.scale_mode=fixed"]
    seq = carmen_sequence(log, load_settings(overrides=overrides))
    n, length = len(seq.ground_truth), 15 if size == "quick" else 50
    for start in [n // 3] if size != "full" else np.linspace(0, n - length, 3).astype(int).tolist():
        yield f"carmen intel [{start}, {start + length})", seq.floorplan_for(start, start + length), list(seq.frames(start, start + length)), overrides


def timed_pushes(frames, floorplan, settings, rate: float) -> tuple[np.ndarray, list]:
    """Each push's wall time (ms) and estimate, frames arriving at `rate` Hz (0: back to back)."""
    walls, estimates = [], []
    with Localizer(floorplan, settings) as loc:
        start = time.perf_counter()
        for i, frame in enumerate(frames):
            if rate > 0:
                time.sleep(max(0.0, start + i / rate - time.perf_counter()))
            t0 = time.perf_counter()
            estimates.append(loc.push(frame))
            walls.append(time.perf_counter() - t0)
    return np.array(walls) * 1000, estimates


def push_latency(frames, floorplan, overrides, rate: float) -> dict:
    """Push wall times with frames arriving at `rate` Hz (0: back to back), as from a camera:
    the worker's time between arrivals is what pipelining puts to use."""
    w, estimates = timed_pushes(frames, floorplan, load_settings(overrides=overrides), rate)
    r = np.array([t for t, e in zip(w, estimates) if {"round_start", "round_wait", "model_estimation"} & e.timings.keys()])
    waits = np.array([e.timings.get("round_wait", np.nan) for e in estimates]) * 1000
    return {"median": np.median(w), "p99": np.percentile(w, 99), "max": w.max(), "round_max": r.max() if len(r) else np.nan,
            "wait_max": np.nanmax(waits) if np.isfinite(waits).any() else 0.0}


def default_cases(laser_scans: int = 50):
    """(name, floorplan, frames, base overrides) of the real data the defaults are timed on:
    the shared camera sessions belgioioso-camera-50 and fhw-camera-50 (metric prior, the
    default scale mode) and laser_scans-scan Carmen laser windows of fhw and intel (fixed
    scale) against the map of the log without the window."""
    for name in ("belgioioso-camera-50", "fhw-camera-50"):
        path = SHARED / "sessions" / name / "session.mcap"
        if path.exists():
            yield name, Floorplan.load(path.parent / "map.yaml", settings=load_settings()), list(read_session(path).frames()), []
    for log in ("fhw", "intel"):
        path = SHARED / "carmen" / f"{log}-corrected.log.gz"
        if not path.exists():
            continue
        overrides = ["estimator.scale_mode=fixed"]
        seq = carmen_sequence(path, load_settings(overrides=overrides))
        start = min(len(seq.ground_truth) // 3, max(0, len(seq.ground_truth) - laser_scans))
        stop = min(start + laser_scans, len(seq.ground_truth))
        yield f"laser {log} [{start}, {stop})", seq.floorplan_for(start, stop), list(seq.frames(start, stop)), overrides


def defaults_latency(frames, floorplan, overrides, rate: float) -> dict:
    """Push wall times through the Python API with the package's defaults (plus the case's
    overrides), after one warm-up pass over the same frames: median, p99, amortized (all
    push time / frames: with back-to-back pushes it includes any wait for a worker's round)
    and the first frame with a pose."""
    settings = load_settings(overrides=overrides)
    timed_pushes(frames, floorplan, settings, rate)  # warm-up: caches, kernels
    w, estimates = timed_pushes(frames, floorplan, settings, rate)
    first = next((i for i, e in enumerate(estimates) if e.pose is not None), None)
    after = w[first + 1:] if first is not None and first + 1 < len(w) else w[:0]
    return {"median": np.median(w), "p99": np.percentile(w, 99), "amortized": w.sum() / len(w), "first": first,
            "p99_after": np.percentile(after, 99) if len(after) else np.nan, "slowest": int(np.argmax(w)), "max": w.max(),
            "kinds": frame_kinds(w, estimates)}


def frame_kinds(walls: np.ndarray, estimates) -> dict[str, tuple]:
    """Pushes by what they did: a round landed ("join": its stage timings are there), a
    round started on the worker ("start"), neither ("plain"); per kind the count, median
    and max push and median fusion (ms)."""
    kinds: dict[str, list] = {"join": [], "start": [], "plain": []}
    for t, e in zip(walls, estimates):
        kind = "join" if "primitives" in e.timings else "start" if "round_start" in e.timings else "plain"
        kinds[kind].append((t, 1000 * e.timings.get("fusion", 0.0)))
    return {k: (len(v), np.median([a for a, _ in v]), max(a for a, _ in v), np.median([b for _, b in v]))
            for k, v in kinds.items() if v}


def main(argv=None) -> int:
    bench = Benchmark("round", __doc__, settings=True)  # --set: for every run
    ap = bench.parser
    ap.add_argument("--short", action="store_true", help="fewer cases and frames (a few minutes on 2 cores)")
    ap.add_argument("--process", action="store_true", help="also time a pipelined worker process")
    ap.add_argument("--skip-stages", action="store_true", help="push latency only")
    ap.add_argument("--latency-frames", type=int, default=None, help="640x480 frames per latency run (default 10 quick, 40 short, 120)")
    ap.add_argument("--rate", type=float, default=30.0, help="frames per second the latency runs feed (0: back to back)")
    ap.add_argument("--switch-interval", type=float, default=None, help="sys.setswitchinterval for the latency runs, --defaults too (s; Python's default 0.005)")
    ap.add_argument("--defaults", action="store_true",
                    help="only: push latency with the package defaults on the shared real camera sessions and laser logs "
                         "(run it once with this tree and once with another checkout on PYTHONPATH to compare defaults)")
    ap.add_argument("--laser-scans", type=int, default=50,
                    help="--defaults: scans per laser window (default 50; a longer window shows the p99 of a steady "
                         "stream)")
    ap.add_argument("--frame-kinds", action="store_true",
                    help="--defaults: also push and fusion times of the frames where a round lands, starts, or neither")
    args = bench.parse(argv)
    if args.laser_scans < 10:
        ap.error(f"--laser-scans must be at least 10, got {args.laser_scans}")
    if args.switch_interval is not None and not args.switch_interval > 0:
        ap.error(f"--switch-interval must be a positive number of seconds, got {args.switch_interval}")
    size = "quick" if args.quick else "short" if args.short else "full"
    previous_interval = sys.getswitchinterval()
    if args.switch_interval:  # how long a thread waiting for the GIL waits before asking for it
        sys.setswitchinterval(args.switch_interval)
    try:
        run(bench, args, size)
    finally:
        sys.setswitchinterval(previous_interval)
    return bench.done()


def run(bench, args, size: str) -> None:
    if args.defaults:
        import zfloc_stream

        table = bench.table(["case", ("median_ms", "median"), ("p99_ms", "p99"), ("amortized_ms", "amortized"), ("first_pose", "first pose at frame"),
                             ("p99_after_ms", "p99 after it"), ("slowest", "slowest frame"), ("max_ms", "its push")],
                            title=f"defaults of {Path(zfloc_stream.__file__).parent}: push ms, one warm-up pass, frames "
                                  f"{'back to back' if args.rate <= 0 else f'at {args.rate:g} Hz'}")
        kinds = []
        for name, plan, frames, overrides in default_cases(args.laser_scans):
            s = defaults_latency(frames, plan, overrides + args.set, args.rate)
            table.add(case=name, median_ms=s["median"], p99_ms=s["p99"], amortized_ms=s["amortized"], first_pose=s["first"],
                      p99_after_ms=s["p99_after"], slowest=s["slowest"], max_ms=s["max"])
            kinds += [(name, k, v) for k, v in s["kinds"].items()]
        if args.frame_kinds:
            by_kind = bench.table(["case", "kind", "n", ("push_median_ms", "push median ms"), ("push_max_ms", "push max ms"),
                                   ("fusion_median_ms", "fusion median ms")], title="frames by kind")
            for name, k, (n, m, x, f) in kinds:
                by_kind.add(case=name, kind=k, n=n, push_median_ms=m, push_max_ms=x, fusion_median_ms=f)
        return
    if not args.skip_stages:
        table = bench.table(["case", "rounds", "stage", "n", ("wall_median_ms", "wall median ms"), ("wall_p95_ms", "wall p95"),
                             ("cpu_median_ms", "CPU median ms"), ("cpu_p95_ms", "CPU p95")],
                            title=f"round stages, inline, GIL switch interval {sys.getswitchinterval() * 1000:g} ms")
        for cases in (scene_cases, session_cases, carmen_cases):
            for name, plan, frames, overrides in cases(size):
                add_stages(table, name, stage_times(plan, frames, load_settings(overrides=overrides + ["localizer.pipeline=inline"] + args.set)))

    n = args.latency_frames or {"quick": 10, "short": 40, "full": 120}[size]
    scene = build_scene("apartment", seed=0)
    modes = [("inline", ["localizer.pipeline=inline"]), ("pipelined thread", ["localizer.pipeline=pipelined"])]
    if args.process:
        modes.append(("pipelined process", ["localizer.pipeline=pipelined", "localizer.worker=process"]))
    table = bench.table(["input", "mode", ("median_ms", "median"), ("p99_ms", "p99"), ("max_ms", "max"), ("round_max_ms", "max on start/join frames"),
                         ("wait_max_ms", "longest join wait")],
                        title=f"push latency, 640x480 camera, apartment, {n} frames at {args.rate:g} Hz, "
                              f"GIL switch interval {sys.getswitchinterval() * 1000:g} ms; ms")
    for labels in (True,) if size == "quick" else (True, False):
        frames = simulate(scene, SimSettings(width=640, height=480, use_labels=labels), seed=0, n_frames=n).frames
        for mode, overrides in modes:
            s = push_latency(frames, scene.floorplan, overrides + args.set, args.rate)
            table.add(input="labels" if labels else "geometric labeller", mode=mode, median_ms=s["median"], p99_ms=s["p99"], max_ms=s["max"],
                      round_max_ms=s["round_max"], wait_max_ms=s["wait_max"])


if __name__ == "__main__":
    raise SystemExit(main())
