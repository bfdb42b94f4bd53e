"""Cost of a round by stage, and push latency inline vs pipelined (issue 10).

Stages: every round of each case, run inline (so the round runs in the push that starts
it and nothing else shares its time), wall (perf_counter) and CPU (thread_time of the
thread that ran the stage; BLAS helper threads not counted) of primitives,
model_estimation, scoring, refinement, tracking and their sum per round, and of fusion
per fused frame (fusion + monitor: a push that neither starts nor applies a round);
median and p95. Cases: built-in scenes (camera 160x120, laser), the shared real camera
sessions (../shared/data/sessions/*/session.mcap against map.yaml beside it) at fixed,
prior and free scale, and windows of a Carmen laser log localized against the map of the
log without the window (as benchmarks/eval_real.py).

Push latency: a 640x480 camera walk on a built-in scene, with labels and without (the
geometric labeller labels each frame), median / p99 / max of the push wall time over all
frames and max over the frames where a round starts or joins, inline vs pipelined (one
worker thread; --process adds a worker process). Frames are rendered before timing.

    python benchmarks/bench_round.py --quick        # a few minutes on 2 cores
    python benchmarks/bench_round.py                # more scenes, frames and windows
    python benchmarks/bench_round.py --defaults --rate 0      # the package defaults on real data
    PYTHONPATH=../main python benchmarks/bench_round.py --defaults --rate 0   # another checkout's
    python benchmarks/bench_round.py --defaults --rate 10 --frame-kinds       # join / start / plain frames apart

--defaults (issue 25): push latency with the defaults through the Python API on the shared
camera sessions belgioioso-camera-50 and fhw-camera-50 (metric prior) and two 50-scan
Carmen laser windows (fhw, intel; fixed scale), one warm-up pass. Measured on 2026-12-03 on
the shared 2-core machine at load average 7-7.7 (other jobs), new defaults (online,
compiled kernels) against the commit before (4c13297: inline, numpy), ms:

    frames back to back     median        p99          amortized    first pose
    belgioioso camera       19.3 -> 40.6  937 -> 243   159 -> 63    4 -> 4
    fhw camera              17.3 -> 35.7  891 -> 279   137 -> 67    4 -> 4
    laser fhw               10.0 -> 23.9  583 -> 700    96 -> 90    4 -> 4
    laser intel             11.0 -> 19.0  447 -> 256    80 -> 46    4 -> 4
    at 10 Hz
    belgioioso camera        7.9 -> 16.4  346 -> 156    59 -> 24    4 -> 4
    fhw camera              12.1 -> 17.4  502 -> 107    87 -> 22    4 -> 4
    laser fhw                9.0 -> 4.2   661 -> 219   102 -> 16    4 -> 4
    laser intel              3.9 -> 3.8   562 -> 109    85 -> 13    4 -> 4

A second back-to-back run at load average 10.6-11.1 (old -> new, median / p99 / amortized):
belgioioso camera 11.7 -> 19.7 / 668 -> 150 / 97 -> 37; fhw camera 11.9 -> 51.6 / 541 ->
498 / 85 -> 95; laser fhw 11.3 -> 16.1 / 611 -> 674 / 92 -> 59; laser intel 9.7 -> 13.4 /
446 -> 176 / 79 -> 29. Under this load the runs vary by 2x; fhw camera was worse this time.
The first pose lands at the same frame. The p99 of 50 frames is set by the one or two
rounds that ran inline before the first pose (until 2026-12-04; now a preview round on the
worker gives that pose, docs/performance.md);
back to back, a join also waits for the worker's round, and the median grows because the
worker shares the two loaded cores with the stream. The issue's targets (p99 <= 15 ms,
amortized <= 10 ms, quiet machine) were not reached here; this machine was never quiet.

Measured on the shared 2-core machine under load average 6-7 from other jobs (so walls are
~1.5x CPU), `--quick`: a round (wall median) takes 180 ms on the apartment camera, 340 ms on
the office laser, 360-610 ms on the aces / belgioioso camera sessions (fixed, prior, free
scale) and 500 ms on an Intel Carmen window; fusion 8 ms (camera 160x120), 1 ms (laser).
Push latency, 640x480, 60 frames (`--quick --skip-stages --latency-frames 60 --rate R`):

    rate   labels      mode               median   p99    max  (ms)
    10 Hz  labels      inline               8.8   223    235
    10 Hz  labels      pipelined thread     9.4    31     45
    10 Hz  labels      pipelined process    8.8    22     34
    10 Hz  geometric   inline              10.0   206    218
    10 Hz  geometric   pipelined thread    13.8    53     57
    10 Hz  geometric   pipelined process   10.8    27     38
    30 Hz  labels      pipelined thread    12.2   155    164   (rounds longer than 5 frames: joins wait)

Again on a quiet machine (load average 0.9, same command at 10 Hz, after the torch backend
and heap trimming; the push path is otherwise unchanged):

    10 Hz  labels      inline               5.8   186    283
    10 Hz  labels      pipelined thread     7.4    13     14
    10 Hz  labels      pipelined process    6.6    17     18
    10 Hz  geometric   inline               9.4   151    160
    10 Hz  geometric   pipelined thread    11.0    26     26
    10 Hz  geometric   pipelined process    9.8    17     17

After the correlative rotation prefilter and the 3L scale pre-check (rounds ~30% shorter),
load average 0.4-0.6, the same command 4 times (p99 of each run, ms):

    labels      pipelined thread    14.7   7.2   9.2  11.0
    labels      pipelined process   11.8   7.2  10.0  11.8
    geometric   pipelined thread    11.4   9.5  14.6  14.3
    geometric   pipelined process   12.2  14.6  13.9  15.4
    (inline: p99 73-100 ms, the round)

There the slowest pipelined pushes are the start / join frames: fusion (~6 ms) plus the
tracker update and local refinement of the join (~4 ms, `tracking`) plus the BEV copy of the
start (~1 ms). Joining one frame before the next start (`--set localizer.join_delay=4`) did
not change the p99 (13.2 ms thread, labels).

With the compiled kernels (issue 10, `--set estimator.kernels=numba`) against numpy, the same
command alternated twice each, load average 0.4-0.65 (p99 of each run, ms):

                                  numpy        numba
    labels      pipelined thread    9.5   9.4   11.6   7.9
    labels      pipelined process  11.8  12.8    7.8  12.3
    geometric   pipelined thread   12.0  10.8   12.4  10.4
    geometric   pipelined process  12.3  11.8   10.2  11.8
    (inline p99: numpy 83-95 ms; numba 29-32 ms geometric, 112-120 ms labels: that first
    run of the process loads the kernels from numba's cache in its first round, max 229 ms)

Pipelined pushes cost fusion (4-6 ms median) whatever the round costs; their p99 sits at
8-13 ms either way, so the kernels change the inline push, not the pipelined one.

With the round's threads (`estimator.threads`, auto: a pipelined round keeps to one core of
the two, an inline one takes both), `--quick --skip-stages --latency-frames 60 --rate 10
--process --set estimator.kernels=numba`, load average 0.9, p99 (max) in ms, auto and then
`--set estimator.threads=2` (the pipelined round on both cores):

                                  auto          threads=2
    labels      pipelined thread   8.7 (8.9)     8.8 (9.6)
    labels      pipelined process  8.7 (8.8)     9.3 (10.7)
    geometric   pipelined thread  11.6 (11.7)   15.1 (20.3)
    geometric   pipelined process 13.4 (19.7)   10.3 (12.3)
    (inline: labels 118 / 117 ms p99, the first round loading the kernels; geometric 31.6 /
    30.1 ms)

A round on both cores slowed the stream's geometric pushes in one run of two, hence auto
leaves the stream its core.

At 30 Hz a round (130-230 ms here) is longer than k = 5 frames, so the join waits and
pipelining cannot help; it needs round time < k / rate (raise every_k_frames or join_delay,
or fewer RANSAC iterations). The worst pipelined pushes are fusion frames slowed by the
worker (CPU and GIL), not the start / join frames (max 13-18 ms at 10 Hz).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from zfloc_stream.config import load_settings
from zfloc_stream.datasets.carmen import carmen_sequence
from zfloc_stream.floorplan import Floorplan
from zfloc_stream.localizer import Localizer
from zfloc_stream.session import read_session
from zfloc_stream.sim import LaserSimSettings, SimSettings, build_scene, simulate, simulate_laser

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
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


def print_stages(name: str, times: dict) -> None:
    n = len(times.get("round", ([], []))[0])
    cells = []
    for stage in STAGES:
        wall, cpu = (np.array(v) * 1000 for v in times.get(stage, ([], [])))
        if len(wall):
            cells.append(f"{stage} {np.median(wall):.1f}/{np.percentile(wall, 95):.1f} (cpu {np.nanmedian(cpu):.1f}/{np.nanpercentile(cpu, 95):.1f})")
    print(f"{name:34s} rounds {n:3d} | " + " | ".join(cells), flush=True)


def scene_cases(quick: bool):
    frames = 40 if quick else 100
    for name in ("apartment",) if quick else ("apartment", "office", "hall"):
        scene = build_scene(name, seed=0)
        yield f"scene {name} camera", scene.floorplan, simulate(scene, SimSettings(), seed=0, n_frames=frames).frames, []
    scene = build_scene("office", seed=1)
    yield "scene office laser", scene.floorplan, simulate_laser(scene, LaserSimSettings(), seed=1, n_frames=frames).frames, ["estimator.scale_mode=fixed"]


def session_cases(quick: bool):
    sessions = sorted((SHARED / "sessions").glob("*/session.mcap"))
    if not sessions:
        print(f"(no shared sessions under {SHARED / 'sessions'}: skipped)")
    for path in sessions[:2] if quick else sessions:
        frames = list(read_session(path).frames())
        for mode in ("fixed", "prior", "free"):
            overrides = [f"estimator.scale_mode={mode}"]
            plan = Floorplan.load(path.parent / "map.yaml", settings=load_settings(overrides=overrides))
            yield f"{path.parent.name} {mode}", plan, frames, overrides


def carmen_cases(quick: bool):
    log = SHARED / "carmen" / "intel-corrected.log.gz"
    if not log.exists():
        print(f"(no Carmen log {log}: skipped)")
        return
    overrides = ["estimator.scale_mode=fixed"]
    seq = carmen_sequence(log, load_settings(overrides=overrides))
    n, length = len(seq.ground_truth), 50
    for start in [n // 3] if quick else np.linspace(0, n - length, 3).astype(int).tolist():
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer cases and frames")
    ap.add_argument("--process", action="store_true", help="also time a pipelined worker process")
    ap.add_argument("--skip-stages", action="store_true", help="push latency only")
    ap.add_argument("--latency-frames", type=int, default=None, help="640x480 frames per latency run (default 40 quick, 120)")
    ap.add_argument("--rate", type=float, default=30.0, help="frames per second the latency runs feed (0: back to back)")
    ap.add_argument("--switch-interval", type=float, default=None, help="sys.setswitchinterval for the latency runs, --defaults too (s; Python's default 0.005)")
    ap.add_argument("--set", action="append", default=[], help="dotted.key=value for every run")
    ap.add_argument("--defaults", action="store_true",
                    help="only: push latency with the package defaults on the shared real camera sessions and laser logs "
                         "(run it once with this tree and once with another checkout on PYTHONPATH to compare defaults)")
    ap.add_argument("--laser-scans", type=int, default=50,
                    help="--defaults: scans per laser window (default 50; a longer window shows the p99 of a steady "
                         "stream)")
    ap.add_argument("--frame-kinds", action="store_true",
                    help="--defaults: also push and fusion times of the frames where a round lands, starts, or neither")
    args = ap.parse_args()
    if args.laser_scans < 10:
        ap.error(f"--laser-scans must be at least 10, got {args.laser_scans}")
    if args.switch_interval is not None and not args.switch_interval > 0:
        ap.error(f"--switch-interval must be a positive number of seconds, got {args.switch_interval}")
    if args.switch_interval:  # how long a thread waiting for the GIL waits before asking for it
        sys.setswitchinterval(args.switch_interval)
    if args.defaults:
        import zfloc_stream

        print(f"defaults of {Path(zfloc_stream.__file__).parent}: load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; "
              f"push ms, one warm-up pass, frames {'back to back' if args.rate <= 0 else f'at {args.rate:g} Hz'}", flush=True)
        for name, plan, frames, overrides in default_cases(args.laser_scans):
            s = defaults_latency(frames, plan, overrides + args.set, args.rate)
            print(f"  {name:34s} median {s['median']:6.1f}  p99 {s['p99']:6.1f}  amortized {s['amortized']:6.1f}  "
                  f"first pose at frame {s['first']}  p99 after it {s['p99_after']:6.1f}  "
                  f"slowest: frame {s['slowest']} ({s['max']:.1f})", flush=True)
            if args.frame_kinds:
                print("    " + "; ".join(f"{k} x{n}: push median {m:.1f} max {x:.1f}, fusion median {f:.1f}"
                                         for k, (n, m, x, f) in s["kinds"].items()), flush=True)
        return
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, GIL switch interval {sys.getswitchinterval() * 1000:g} ms; ms, median/p95 per stage, wall (cpu)", flush=True)
    if not args.skip_stages:
        for cases in (scene_cases, session_cases, carmen_cases):
            for name, plan, frames, overrides in cases(args.quick):
                print_stages(name, stage_times(plan, frames, load_settings(overrides=overrides + ["localizer.pipeline=inline"] + args.set)))

    n = args.latency_frames or (40 if args.quick else 120)
    scene = build_scene("apartment", seed=0)
    modes = [("inline", ["localizer.pipeline=inline"]), ("pipelined thread", ["localizer.pipeline=pipelined"])]
    if args.process:
        modes.append(("pipelined process", ["localizer.pipeline=pipelined", "localizer.worker=process"]))
    print(f"push latency, 640x480 camera, apartment, {n} frames at {args.rate:g} Hz, GIL switch interval {sys.getswitchinterval() * 1000:g} ms; ms", flush=True)
    for labels in (True, False):
        frames = simulate(scene, SimSettings(width=640, height=480, use_labels=labels), seed=0, n_frames=n).frames
        for mode, overrides in modes:
            s = push_latency(frames, scene.floorplan, overrides + args.set, args.rate)
            print(f"  {'labels' if labels else 'geometric labeller':18s} {mode:18s} median {s['median']:6.1f}  p99 {s['p99']:6.1f}  "
                  f"max {s['max']:6.1f}  max on start/join frames {s['round_max']:6.1f}  longest join wait {s['wait_max']:6.1f}", flush=True)


if __name__ == "__main__":
    main()
