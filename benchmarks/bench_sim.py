"""Simulator speed: scene build, one render per resolution, a walk, a camera sequence.

    python -m benchmarks.bench_sim
    python -m benchmarks.bench_sim --scenes rooms apartment --repeat 5

Goals: each scene builds in < 1 s; 160x120 renders in a few ms; 640x480 in < 100 ms.
Times are the best of --repeat calls (renders: the median over a walk's poses of the best
of --repeat); --quick: one scene, 160x120 only, a short walk and sequence.
"""

from __future__ import annotations

import time

import numpy as np

from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.sim import SCENES, SimSettings, build_scene, camera_pose, intrinsics, random_walk, render, simulate

from benchmarks.harness import Benchmark


def best_of(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main(argv=None) -> int:
    bench = Benchmark("sim", __doc__, repeat=3)
    bench.parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    args = bench.parse(argv)
    sizes, walk_steps, sim_frames = ((160, 120), (640, 480)), 200, 50
    if args.quick:
        args.scenes, args.repeat, sizes, walk_steps, sim_frames = args.scenes[:1], 1, ((160, 120),), 20, 5
    columns = ["scene", ("build_ms", "build ms")] + [(f"render_{w}x{h}_ms", f"render {w}x{h} ms") for w, h in sizes]
    columns += [("walk_ms", f"walk({walk_steps}) ms"), ("simulate_s", f"simulate({sim_frames} frames, 160x120) s")]
    table = bench.table(columns)
    for name in args.scenes:
        row = {"scene": name, "build_ms": best_of(lambda: build_scene(name, 0), args.repeat) * 1e3}
        scene = build_scene(name, 0)
        walk = random_walk(scene, make_rng(0, "bench"), 20)
        poses = [camera_pose(x, y, yaw, 1.4, np.radians(-8), np.radians(4)) for x, y, yaw in walk]
        for w, h in sizes:
            K = intrinsics(w, h, 90.0)
            row[f"render_{w}x{h}_ms"] = float(np.median([best_of(lambda T=T: render(scene, T, K, (h, w)), args.repeat) for T in poses[::4]])) * 1e3
        row["walk_ms"] = best_of(lambda: random_walk(scene, make_rng(1, "bench"), walk_steps), 1) * 1e3
        row["simulate_s"] = best_of(lambda: simulate(scene, SimSettings(), seed=0, n_frames=sim_frames).frames, 1)
        table.add(**row)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
