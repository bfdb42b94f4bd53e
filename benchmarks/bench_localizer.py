"""Per-push time of the streaming localizer (fusion-only frames and RANSAC frames apart)
and the process's resident memory as the session grows (it must stay flat).

    python -m benchmarks.bench_localizer                      # apartment, 10,000 frames
    python -m benchmarks.bench_localizer --frames 2000 --scene office

--quick: 60 frames (a few rounds).
"""

from __future__ import annotations

import time

import numpy as np
import psutil

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.sim import build_scene
from zfloc_stream.sim.simulator import SimSettings, simulate

from benchmarks.harness import Benchmark


def main(argv=None) -> int:
    bench = Benchmark("localizer", __doc__, seed=0, frames=10_000, settings=True)
    bench.parser.add_argument("--scene", default="apartment")
    args = bench.parse(argv)
    if args.quick:
        args.frames = 60
    settings = load_settings(overrides=args.set)
    scene = build_scene(args.scene, seed=args.seed)
    sequence = simulate(scene, SimSettings(), seed=args.seed, n_frames=args.frames)
    localizer = Localizer(scene.floorplan, settings)
    process = psutil.Process()
    fusion_ms, round_ms = [], []
    checkpoints = {c for c in (100, 1_000, 5_000, 10_000, args.frames) if c <= args.frames}
    memory = {}
    growth = bench.table(["frame", ("rss_mib", "RSS MiB"), ("bev_mib", "BEV MiB"), "status"], title="memory")
    for k, frame in enumerate(sequence, start=1):  # frames are rendered lazily, outside the timer
        t0 = time.perf_counter()
        est = localizer.push(frame)
        ms = 1000 * (time.perf_counter() - t0)
        (round_ms if "model_estimation" in est.timings else fusion_ms).append(ms)
        if k in checkpoints:
            memory[k] = process.memory_info().rss / 2**20
            growth.add(frame=k, rss_mib=memory[k], bev_mib=localizer.bev.memory_bytes() / 2**20, status=est.status)
    if len(memory) > 1:
        first, last = min(k for k in memory if k >= 1_000) if any(k >= 1_000 for k in memory) else min(memory), max(memory)
        bench.note(f"RSS growth from frame {first} to {last}: {memory[last] - memory[first]:+.1f} MiB")
    push = bench.table(["push", "n", ("median_ms", "median ms"), ("p90_ms", "p90 ms"), ("max_ms", "max ms")], title="push time")
    for name, values in (("fusion-only", fusion_ms), ("RANSAC round", round_ms)):
        v = np.array(values)
        if len(v):
            push.add(push=name, n=len(v), median_ms=float(np.median(v)), p90_ms=float(np.percentile(v, 90)), max_ms=float(v.max()))
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
