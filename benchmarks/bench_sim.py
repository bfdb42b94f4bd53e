"""Simulator speed: scene build, one render per resolution, a walk, a camera sequence.

    .venv/bin/python benchmarks/sim_render.py
Goals: each scene builds in < 1 s; 160x120 renders in a few ms; 640x480 in < 100 ms.
"""

from __future__ import annotations

import time

import numpy as np

from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.sim import SCENES, SimSettings, build_scene, camera_pose, intrinsics, random_walk, render, simulate


def best_of(fn, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    for name in SCENES:
        build = best_of(lambda: build_scene(name, 0), 3)
        scene = build_scene(name, 0)
        walk = random_walk(scene, make_rng(0, "bench"), 20)
        poses = [camera_pose(x, y, yaw, 1.4, np.radians(-8), np.radians(4)) for x, y, yaw in walk]
        line = f"{name:10s} build {build * 1e3:6.0f} ms"
        for w, h in ((160, 120), (640, 480)):
            K = intrinsics(w, h, 90.0)
            per = np.median([best_of(lambda T=T: render(scene, T, K, (h, w)), 2) for T in poses[::4]])
            line += f" | render {w}x{h} {per * 1e3:6.1f} ms"
        walk_time = best_of(lambda: random_walk(scene, make_rng(1, "bench"), 200), 1)
        seq_time = best_of(lambda: simulate(scene, SimSettings(), seed=0, n_frames=50).frames, 1)
        line += f" | walk(200) {walk_time * 1e3:5.0f} ms | simulate(50 frames, 160x120) {seq_time:5.2f} s"
        print(line, flush=True)


if __name__ == "__main__":
    main()
