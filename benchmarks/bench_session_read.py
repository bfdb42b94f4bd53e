"""Reading long sessions: building the Sequence, a deep slice against the first frames,
and peak memory while iterating every frame; the old path against the new one.

    python -m benchmarks.bench_session_read                          # 2000 frames
    python -m benchmarks.bench_session_read --frames 5000 --session /tmp/long.mcap   # kept, reused

The session (written once, reused when --session names an existing file) is a built-in
scene's camera walk (160x120 depth + labels) run through the real localizer by
`record_session`: every input, every output, the BEV every 10 frames, 10 frames a chunk.
Each measurement runs in a fresh process (--quick: 20 frames of rooms):

- old: what the code did before the frame index, still there as the sequential reference
  path: `records(seek=False)` decodes every message from the file's start, logged outputs
  (BEV grids) included. The Sequence was one such full read (n_frames, ground truth); a
  slice [a, b) re-read the file up to b.
- new: `session_sequence` (one pass decoding only the small topics: the frame index),
  slices of that Sequence (only the chunks holding them are read; no outputs decoded), and
  a cold deep slice (`read_session` + `records(n-50, n)`, index build included).
- memory: RSS (psutil, sampled every frame) above what the open session already holds,
  while iterating every frame; and the process's peak RSS (ru_maxrss).

Wall times on a shared machine include waiting for a core.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

from zfloc_stream.settings.loading import Settings
from zfloc_stream.io.datasets.mcap import session_sequence
from zfloc_stream.io.session import read_session

from benchmarks.harness import ROOT, Benchmark

SLICE = 50  # frames in a slice (at most half the session)


def write_session(path: Path, n_frames: int, scene_name: str) -> None:
    from zfloc_stream.io.session import record_session  # the engine and simulator: not in the measuring processes
    from zfloc_stream.sim import build_scene, simulate

    scene = build_scene(scene_name, seed=0)
    t0 = time.perf_counter()
    record_session(path, scene.floorplan, simulate(scene, seed=0, n_frames=n_frames), Settings(), metadata={"bench": "session_read"})
    print(f"wrote {path} ({n_frames} frames of {scene_name}, {path.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.0f} s", flush=True)


def digest(frames) -> str:
    """What a slice holds, bit for bit (stamps, poses, depth, labels, truth)."""
    h = hashlib.sha256()
    for f in frames:
        for a in (f.timestamp, f.T_odom_cam, f.depth, f.labels, f.ground_truth):
            h.update(np.asarray(a).tobytes())
    return h.hexdigest()[:16]


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def measure_times(path: Path, mode: str) -> dict:
    if mode == "old":
        def sequence():
            session, truth = read_session(path), []
            for rec in session.records(seek=False):  # every message decoded, outputs included
                gt = rec.frame.ground_truth
                truth.append(np.full(3, np.nan) if gt is None else np.asarray(gt, dtype=float)[:3])
            return len(truth)

        def frames(a, b):
            return [r.frame for r in read_session(path).records(a, b, seek=False)]

        n, t_open = timed(sequence)
        k = min(SLICE, n // 2)
        deep, t_deep = timed(lambda: frames(n - k, n))
        _, t_head = timed(lambda: frames(0, k))
        t_cold = t_deep
    else:
        seq, t_open = timed(lambda: session_sequence(path, Settings()))
        n = seq.n_frames
        k = min(SLICE, n // 2)
        deep, t_deep = timed(lambda: list(seq.frames(n - k, n)))
        _, t_head = timed(lambda: list(seq.frames(0, k)))
        _, t_cold = timed(lambda: [r.frame for r in read_session(path).records(n - k, n)])
    return {"n": n, "slice": k, "open": t_open, "deep": t_deep, "head": t_head, "cold_deep": t_cold, "digest": digest(deep)}


def measure_memory(path: Path, mode: str) -> dict:
    proc = psutil.Process()
    if mode == "old":
        frames = (r.frame for r in read_session(path).records(seek=False))
    else:
        frames = session_sequence(path, Settings()).frames()
    base = peak = proc.memory_info().rss
    t0, n = time.perf_counter(), 0
    for _ in frames:
        n += 1
        peak = max(peak, proc.memory_info().rss)
    return {"n": n, "all": time.perf_counter() - t0, "base_mb": base / 2**20, "growth_mb": (peak - base) / 2**20,
            "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def run_child(path: Path, what: str, mode: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "benchmarks.bench_session_read", "--session", str(path), "--child", what, mode],
                         check=True, capture_output=True, text=True, cwd=ROOT)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    bench = Benchmark("session_read", __doc__, frames=2000)
    bench.parser.add_argument("--scene", default="apartment")
    bench.parser.add_argument("--session", type=Path, help="session file to use (written there first if missing)")
    bench.parser.add_argument("--child", nargs=2, metavar=("WHAT", "MODE"), help=argparse.SUPPRESS)
    args = bench.parse(argv)
    if args.child:
        what, mode = args.child
        print(json.dumps((measure_times if what == "times" else measure_memory)(args.session, mode)))
        return 0
    if args.quick:
        args.frames, args.scene = 20, "rooms"

    with tempfile.TemporaryDirectory() as tmp:
        path = args.session or Path(tmp) / "long.mcap"
        if not path.exists():
            write_session(path, args.frames, args.scene)
        size = path.stat().st_size / 1e6
        n_chunks = len(read_session(path).summary.chunk_indexes)
        res = {(w, m): run_child(path, w, m) for w in ("times", "memory") for m in ("old", "new")}
    old, new = res["times", "old"], res["times", "new"]
    n, k = old["n"], old["slice"]
    bench.note(f"{path.name}: {n} frames, {size:.1f} MB, {n_chunks} chunks")
    assert new["n"] == n and new["digest"] == old["digest"], "the new path read other frames than the old one"
    rows = [
        ("open + Sequence (n_frames, ground truth)", "open"),
        (f"frames [{n - k}, {n}) of the Sequence", "deep"),
        (f"frames [0, {k}) of the Sequence", "head"),
        (f"cold: read_session + records({n - k}, {n})", "cold_deep"),
    ]
    times = bench.table(["step", ("old_s", "old s"), ("new_s", "new s"), "speedup"], title=f"times, {n} frames")
    for label, key in rows:
        times.add(step=label, key=key, old_s=old[key], new_s=new[key], speedup=old[key] / max(new[key], 1e-9))
    mo, mn = res["memory", "old"], res["memory", "new"]
    times.add(step="iterate all frames", key="all", old_s=mo["all"], new_s=mn["all"], speedup=mo["all"] / max(mn["all"], 1e-9))
    memory = bench.table(["measure", ("old_mib", "old MiB"), ("new_mib", "new MiB")], title="memory")
    memory.add(measure="RSS growth while iterating all frames", key="growth_mb", old_mib=mo["growth_mb"], new_mib=mn["growth_mb"])
    memory.add(measure="RSS after opening (before iterating)", key="base_mb", old_mib=mo["base_mb"], new_mib=mn["base_mb"])
    memory.add(measure="peak RSS of the process (open + iterate)", key="maxrss_mb", old_mib=mo["maxrss_mb"], new_mib=mn["maxrss_mb"])
    bench.note(f"deep slice identical in both paths (sha256 {new['digest']})")
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
