"""Reading long sessions: building the Sequence, a deep slice against the first frames,
and peak memory while iterating every frame; the old path against the new one.

    .venv/bin/python benchmarks/bench_session_read.py                          # 2000 frames
    .venv/bin/python benchmarks/bench_session_read.py --frames 5000 --session /tmp/long.mcap   # kept, reused

The session (written once, reused when --session names an existing file) is a built-in
scene's camera walk (160x120 depth + labels) run through the real localizer by
`record_session`: every input, every output, the BEV every 10 frames, 10 frames a chunk.
Each measurement runs in a fresh process:

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

SLICE = 50


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
        deep, t_deep = timed(lambda: frames(n - SLICE, n))
        _, t_head = timed(lambda: frames(0, SLICE))
        t_cold = t_deep
    else:
        seq, t_open = timed(lambda: session_sequence(path, Settings()))
        n = seq.n_frames
        deep, t_deep = timed(lambda: list(seq.frames(n - SLICE, n)))
        _, t_head = timed(lambda: list(seq.frames(0, SLICE)))
        _, t_cold = timed(lambda: [r.frame for r in read_session(path).records(n - SLICE, n)])
    return {"n": n, "open": t_open, "deep": t_deep, "head": t_head, "cold_deep": t_cold, "digest": digest(deep)}


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
    out = subprocess.run([sys.executable, __file__, "--session", str(path), "--child", what, mode],
                         check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=2000)
    ap.add_argument("--scene", default="apartment")
    ap.add_argument("--session", type=Path, help="session file to use (written there first if missing)")
    ap.add_argument("--child", nargs=2, metavar=("WHAT", "MODE"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        what, mode = args.child
        print(json.dumps((measure_times if what == "times" else measure_memory)(args.session, mode)))
        return

    with tempfile.TemporaryDirectory() as tmp:
        path = args.session or Path(tmp) / "long.mcap"
        if not path.exists():
            write_session(path, args.frames, args.scene)
        size = path.stat().st_size / 1e6
        n_chunks = len(read_session(path).summary.chunk_indexes)
        res = {(w, m): run_child(path, w, m) for w in ("times", "memory") for m in ("old", "new")}
    old, new = res["times", "old"], res["times", "new"]
    n = old["n"]
    print(f"{path.name}: {n} frames, {size:.1f} MB, {n_chunks} chunks")
    assert new["n"] == n and new["digest"] == old["digest"], "the new path read other frames than the old one"
    rows = [
        ("open + Sequence (n_frames, ground truth)", "open"),
        (f"frames [{n - SLICE}, {n}) of the Sequence", "deep"),
        (f"frames [0, {SLICE}) of the Sequence", "head"),
        (f"cold: read_session + records({n - SLICE}, {n})", "cold_deep"),
    ]
    print(f"{'':48s} {'old':>9s} {'new':>9s} {'speed-up':>9s}")
    for label, key in rows:
        print(f"{label:48s} {old[key]:8.3f}s {new[key]:8.3f}s {old[key] / max(new[key], 1e-9):8.1f}x")
    mo, mn = res["memory", "old"], res["memory", "new"]
    print(f"{'iterate all frames':48s} {mo['all']:8.3f}s {mn['all']:8.3f}s {mo['all'] / mn['all']:8.1f}x")
    print(f"{'RSS growth while iterating all frames':48s} {mo['growth_mb']:7.1f}MB {mn['growth_mb']:7.1f}MB")
    print(f"{'RSS after opening (before iterating)':48s} {mo['base_mb']:7.1f}MB {mn['base_mb']:7.1f}MB")
    print(f"{'peak RSS of the process (open + iterate)':48s} {mo['maxrss_mb']:7.1f}MB {mn['maxrss_mb']:7.1f}MB")
    print(f"deep slice identical in both paths (sha256 {new['digest']})")


if __name__ == "__main__":
    main()
