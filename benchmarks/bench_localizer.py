"""Per-push time of the streaming localizer (fusion-only frames and RANSAC frames apart)
and the process's resident memory as the session grows (it must stay flat).

    python benchmarks/bench_localizer.py                      # apartment, 10,000 frames
    python benchmarks/bench_localizer.py --frames 2000 --scene office
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import psutil

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.sim import build_scene
from zfloc_stream.sim.simulator import SimSettings, simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="apartment")
    ap.add_argument("--frames", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", action="append", default=[])
    args = ap.parse_args()
    settings = load_settings(overrides=args.set)
    scene = build_scene(args.scene, seed=args.seed)
    sequence = simulate(scene, SimSettings(), seed=args.seed, n_frames=args.frames)
    localizer = Localizer(scene.floorplan, settings)
    process = psutil.Process()
    fusion_ms, round_ms = [], []
    checkpoints = {c for c in (100, 1_000, 5_000, 10_000, args.frames) if c <= args.frames}
    memory = {}
    for k, frame in enumerate(sequence, start=1):  # frames are rendered lazily, outside the timer
        t0 = time.perf_counter()
        est = localizer.push(frame)
        ms = 1000 * (time.perf_counter() - t0)
        (round_ms if "model_estimation" in est.timings else fusion_ms).append(ms)
        if k in checkpoints:
            memory[k] = process.memory_info().rss / 2**20
            print(f"frame {k:6d}: RSS {memory[k]:7.1f} MiB, BEV {localizer.bev.memory_bytes() / 2**20:5.1f} MiB, status {est.status}")
    for name, values in (("fusion-only push", fusion_ms), ("RANSAC-round push", round_ms)):
        v = np.array(values)
        if len(v):
            print(f"{name:18s}: n={len(v):5d}  median {np.median(v):7.1f} ms  p90 {np.percentile(v, 90):7.1f} ms  max {v.max():7.1f} ms")
    if len(memory) > 1:
        first, last = min(k for k in memory if k >= 1_000) if any(k >= 1_000 for k in memory) else min(memory), max(memory)
        print(f"RSS growth from frame {first} to {last}: {memory[last] - memory[first]:+.1f} MiB")


if __name__ == "__main__":
    main()
