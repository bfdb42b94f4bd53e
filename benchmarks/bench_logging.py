"""Session logging cost at 640x480: time per frame against the localizer's own time, and
bytes per frame (depth stored losslessly as 32FC1).

    .venv/bin/python benchmarks/bench_logging.py                 # 40 frames, apartment, zstd
    .venv/bin/python benchmarks/bench_logging.py --frames 100 --compression zstd lz4 none

Frames are simulated (zfloc_stream.sim, 640x480, depth noise 1%) and pre-rendered, then
run twice through a fresh localizer: once bare, once with every frame and estimate logged
(SessionWriter with its chunking, compression and per-frame flush). Logging time is
measured around the writer calls only (wall and this thread's CPU time; the localizer's
CPU time counts all its threads); the goal is a logging overhead below 20% of the frame's
processing time. On a shared machine wall times include waiting for a core: the CPU-time
ratio is the uncontended estimate. The file is read back and
every depth image compared bit for bit.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from zfloc_stream.config import Settings, load_settings
from zfloc_stream.localizer import Localizer
from zfloc_stream.session import SessionWriter, read_session
from zfloc_stream.sim import SimSettings, build_scene, simulate


def run(frames, plan, settings: Settings, path: Path | None):
    """Seconds per frame: push wall, push CPU (all threads), logging wall, logging CPU."""
    localizer = Localizer(plan, settings)
    push, push_cpu, log_wall, log_cpu = [], [], [], []
    writer = None if path is None else SessionWriter(path, settings, plan)
    try:
        for i, frame in enumerate(frames):
            if writer is not None:
                t0, c0 = time.perf_counter(), time.thread_time()
                frame = writer.write_frame(i, frame)
                w, c = time.perf_counter() - t0, time.thread_time() - c0
            t0, c0 = time.perf_counter(), time.process_time()
            est = localizer.push(frame)
            push.append(time.perf_counter() - t0)
            push_cpu.append(time.process_time() - c0)
            if writer is not None:
                t0, c0 = time.perf_counter(), time.thread_time()
                writer.write_estimate(est, localizer)
                log_wall.append(w + time.perf_counter() - t0)
                log_cpu.append(c + time.thread_time() - c0)
    finally:
        if writer is not None:
            t0, c0 = time.perf_counter(), time.thread_time()
            writer.close()  # the last chunk and the summary: part of the logging cost
            if log_wall:
                log_wall[-1] += time.perf_counter() - t0
                log_cpu[-1] += time.thread_time() - c0
    return np.array(push), np.array(push_cpu), np.array(log_wall), np.array(log_cpu)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--scene", default="apartment")
    ap.add_argument("--compression", nargs="+", default=["zstd"], choices=["zstd", "lz4", "none"])
    args = ap.parse_args()

    scene = build_scene(args.scene, seed=0)
    t0 = time.perf_counter()
    frames = list(simulate(scene, SimSettings(width=640, height=480), seed=0, n_frames=args.frames).frames)
    print(f"simulated {len(frames)} frames of 640x480 in {time.perf_counter() - t0:.1f} s ({args.scene})")
    raw = frames[0].depth.nbytes + (0 if frames[0].labels is None else frames[0].labels.nbytes)

    push_bare, cpu_bare, _, _ = run(frames, scene.floorplan, Settings(), None)
    print(f"localizer alone: mean {push_bare.mean() * 1e3:.1f} ms/frame wall (median {np.median(push_bare) * 1e3:.1f} ms), "
          f"CPU {cpu_bare.mean() * 1e3:.1f} ms/frame")
    with tempfile.TemporaryDirectory() as tmp:
        for comp in args.compression:
            settings = load_settings(overrides=[f"logging.compression={comp}"])
            path = Path(tmp) / f"{comp}.mcap"
            push, push_cpu, wall, cpu = run(frames, scene.floorplan, settings, path)
            size = path.stat().st_size
            back = list(read_session(path).frames())
            lossless = len(back) == len(frames) and all(
                np.array_equal(a.depth, b.depth, equal_nan=True) for a, b in zip(back, frames, strict=True)
            )
            print(
                f"[{comp}] logging: mean {wall.mean() * 1e3:.2f} ms/frame wall (CPU {cpu.mean() * 1e3:.2f} ms, "
                f"p95 wall {np.quantile(wall, 0.95) * 1e3:.2f} ms); localizer {push.mean() * 1e3:.1f} ms/frame; "
                f"overhead {wall.sum() / push.sum() * 100:.1f}% of processing wall time, "
                f"{cpu.sum() / push_cpu.sum() * 100:.1f}% of its CPU time (goal < 20%)"
            )
            print(
                f"[{comp}] {size / len(frames) / 1e6:.3f} MB/frame ({size / 1e6:.1f} MB file; raw depth+labels "
                f"{raw / 1e6:.3f} MB/frame, ratio {raw * len(frames) / size:.2f}); depth lossless: {lossless}"
            )


if __name__ == "__main__":
    main()
