"""Session logging cost at 640x480: time per frame against the localizer's own time, and
bytes per frame (depth stored losslessly as 32FC1).

    .venv/bin/python benchmarks/bench_logging.py                 # 40 frames, apartment, zstd
    .venv/bin/python benchmarks/bench_logging.py --frames 100 --compression zstd lz4 none

Frames are simulated (zfloc_stream.sim, 640x480, depth noise 1%) and pre-rendered, then
run through a fresh localizer: once bare, then with every frame and estimate logged, for
each writer mode (logging.background: compression and file writes on a worker thread, or
inline). Reported: the time the caller spends in the writer (wall and its thread's CPU;
the goal is below 20% of the frame's processing time), the process CPU per frame with and
without logging (all threads, so the worker's compression is counted), bytes per frame.
The file is read back and every depth image compared bit for bit. On a shared machine
wall times include waiting for a core.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.io.session import SessionWriter, read_session
from zfloc_stream.sim import SimSettings, build_scene, simulate


def run(frames, plan, settings: Settings, path: Path | None):
    """Per-frame seconds: push wall, logging wall and CPU on the caller's thread; and the
    process CPU time of the whole run (all threads: the background writer included)."""
    localizer = Localizer(plan, settings)
    push, log_wall, log_cpu = [], [], []
    cpu0 = time.process_time()
    writer = None if path is None else SessionWriter(path, settings, plan)
    try:
        for i, frame in enumerate(frames):
            if writer is not None:
                t0, c0 = time.perf_counter(), time.thread_time()
                frame = writer.write_frame(i, frame)
                w, c = time.perf_counter() - t0, time.thread_time() - c0
            t0 = time.perf_counter()
            est = localizer.push(frame)
            push.append(time.perf_counter() - t0)
            if writer is not None:
                t0, c0 = time.perf_counter(), time.thread_time()
                writer.write_estimate(est, localizer)
                log_wall.append(w + time.perf_counter() - t0)
                log_cpu.append(c + time.thread_time() - c0)
    finally:
        if writer is not None:
            t0, c0 = time.perf_counter(), time.thread_time()
            writer.close()  # drains the background queue, last chunk, summary: part of the cost
            if log_wall:
                log_wall[-1] += time.perf_counter() - t0
                log_cpu[-1] += time.thread_time() - c0
    total_cpu = (time.process_time() - cpu0) / len(frames)
    return np.array(push), np.array(log_wall), np.array(log_cpu), total_cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40)
    ap.add_argument("--scene", default="apartment")
    ap.add_argument("--compression", nargs="+", default=["zstd"], choices=["zstd", "lz4", "none"])
    ap.add_argument("--background", nargs="+", default=["true", "false"], choices=["true", "false"],
                    help="writer modes to measure (logging.background)")
    args = ap.parse_args()

    scene = build_scene(args.scene, seed=0)
    t0 = time.perf_counter()
    frames = list(simulate(scene, SimSettings(width=640, height=480), seed=0, n_frames=args.frames).frames)
    print(f"simulated {len(frames)} frames of 640x480 in {time.perf_counter() - t0:.1f} s ({args.scene})")
    raw = frames[0].depth.nbytes + (0 if frames[0].labels is None else frames[0].labels.nbytes)

    push_bare, _, _, cpu_bare = run(frames, scene.floorplan, Settings(), None)
    print(f"localizer alone: mean {push_bare.mean() * 1e3:.1f} ms/frame wall (median {np.median(push_bare) * 1e3:.1f} ms), "
          f"process CPU {cpu_bare * 1e3:.1f} ms/frame")
    with tempfile.TemporaryDirectory() as tmp:
        for comp in args.compression:
            for background in args.background:
                settings = load_settings(overrides=[f"logging.compression={comp}", f"logging.background={background}"])
                path = Path(tmp) / f"{comp}-{background}.mcap"
                push, wall, cpu, total = run(frames, scene.floorplan, settings, path)
                size = path.stat().st_size
                back = list(read_session(path).frames())
                lossless = len(back) == len(frames) and all(
                    np.array_equal(a.depth, b.depth, equal_nan=True) for a, b in zip(back, frames, strict=True)
                )
                tag = f"[{comp}, background={background}]"
                print(
                    f"{tag} caller's logging time: mean {wall.mean() * 1e3:.2f} ms/frame wall (CPU {cpu.mean() * 1e3:.2f} ms, "
                    f"p95 wall {np.quantile(wall, 0.95) * 1e3:.2f} ms) = {wall.sum() / push.sum() * 100:.1f}% of the "
                    f"localizer's {push.mean() * 1e3:.1f} ms/frame (goal < 20%)"
                )
                print(
                    f"{tag} process CPU {total * 1e3:.1f} ms/frame vs {cpu_bare * 1e3:.1f} without logging: "
                    f"logging costs {(total - cpu_bare) * 1e3:.1f} ms/frame of CPU on all threads "
                    f"({(total - cpu_bare) / cpu_bare * 100:.0f}% of the localizer's CPU)"
                )
                print(
                    f"{tag} {size / len(frames) / 1e6:.3f} MB/frame ({size / 1e6:.1f} MB file; raw depth+labels "
                    f"{raw / 1e6:.3f} MB/frame, ratio {raw * len(frames) / size:.2f}); depth lossless: {lossless}"
                )


if __name__ == "__main__":
    main()
