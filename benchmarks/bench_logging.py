"""Session logging cost at 640x480: time per frame against the localizer's own time, and
bytes per frame (depth stored losslessly as 32FC1).

    python -m benchmarks.bench_logging                 # 40 frames, apartment, zstd
    python -m benchmarks.bench_logging --frames 100 --compression zstd lz4 none

Frames are simulated (zfloc_stream.sim, 640x480, depth noise 1%) and pre-rendered, then
run through a fresh localizer: once bare, then with every frame and estimate logged, for
each writer mode (logging.background: compression and file writes on a worker thread, or
inline). Reported: the time the caller spends in the writer (wall and its thread's CPU;
the goal is below 20% of the frame's processing time), the process CPU per frame with and
without logging (all threads, so the worker's compression is counted), bytes per frame.
The file is read back and every depth image compared bit for bit. On a shared machine
wall times include waiting for a core. --quick: 6 frames of 160x120, zstd in the background.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.io.session import SessionWriter, read_session
from zfloc_stream.sim import SimSettings, build_scene, simulate

from benchmarks.harness import Benchmark


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


def main(argv=None) -> int:
    bench = Benchmark("logging", __doc__, frames=40)
    bench.parser.add_argument("--scene", default="apartment")
    bench.parser.add_argument("--compression", nargs="+", default=["zstd"], choices=["zstd", "lz4", "none"])
    bench.parser.add_argument("--background", nargs="+", default=["true", "false"], choices=["true", "false"],
                              help="writer modes to measure (logging.background)")
    args = bench.parse(argv)
    width, height = 640, 480
    if args.quick:
        args.frames, args.background, width, height = 6, ["true"], 160, 120

    scene = build_scene(args.scene, seed=0)
    t0 = time.perf_counter()
    frames = list(simulate(scene, SimSettings(width=width, height=height), seed=0, n_frames=args.frames).frames)
    bench.note(f"simulated {len(frames)} frames of {width}x{height} in {time.perf_counter() - t0:.1f} s ({args.scene})")
    raw = frames[0].depth.nbytes + (0 if frames[0].labels is None else frames[0].labels.nbytes)

    push_bare, _, _, cpu_bare = run(frames, scene.floorplan, Settings(), None)
    bench.note(f"localizer alone: mean {push_bare.mean() * 1e3:.1f} ms/frame wall (median {np.median(push_bare) * 1e3:.1f} ms), "
               f"process CPU {cpu_bare * 1e3:.1f} ms/frame")
    table = bench.table(["compression", "background", ("log_wall_ms", "caller's logging ms/frame"), ("log_cpu_ms", "its CPU ms"),
                         ("log_wall_p95_ms", "p95 wall ms"), ("share_pct", "% of push (goal < 20)"),
                         ("process_cpu_ms", "process CPU ms/frame"), ("logging_cpu_ms", "logging CPU ms/frame, all threads"),
                         ("mb_per_frame", "MB/frame"), ("ratio", "raw/file"), ("lossless", "depth lossless")])
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
                table.add(compression=comp, background=background == "true", log_wall_ms=wall.mean() * 1e3, log_cpu_ms=cpu.mean() * 1e3,
                          log_wall_p95_ms=np.quantile(wall, 0.95) * 1e3, share_pct=wall.sum() / push.sum() * 100,
                          push_ms=push.mean() * 1e3, process_cpu_ms=total * 1e3, bare_cpu_ms=cpu_bare * 1e3,
                          logging_cpu_ms=(total - cpu_bare) * 1e3, mb_per_frame=size / len(frames) / 1e6, file_mb=size / 1e6,
                          raw_mb_per_frame=raw / 1e6, ratio=raw * len(frames) / size, lossless=lossless)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
