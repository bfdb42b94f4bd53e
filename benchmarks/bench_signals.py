"""What a stopped run leaves behind: `zfloc-stream demo` stopped by SIGTERM, and killed
by SIGKILL at random points.

    python -m benchmarks.bench_signals                  # 1 SIGTERM + 10 SIGKILLs
    python -m benchmarks.bench_signals --kills 20 --frames 80 --seed 3

Each run writes trajectory.csv one flushed row per finished frame, so its row count is
the frames the run had finished when the signal came. SIGTERM: the exit code, whether
session.mcap reads without --salvage (footer written) and how many frames it holds.
SIGKILL (at a seeded random moment once the first frame is out): frames read back with
salvage against the rows in trajectory.csv; "lost" counts finished frames missing from
the file (the goal: none; the frame being written when the kill came is not finished).
--quick: 8 frames, one SIGKILL.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from zfloc_stream.errors import SessionLogError
from zfloc_stream.io.session import read_session

from benchmarks.harness import Benchmark


def start(out: Path, frames: int, scene: str, overrides=()) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "zfloc_stream.tools.cli", "demo", "--scene", scene, "--frames", str(frames), "--out", str(out), "--no-progress"]
    for o in overrides:
        cmd += ["--set", o]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def rows(out: Path) -> int:
    csv = out / "trajectory.csv"
    if not csv.is_file():
        return 0
    return max(sum(1 for line in csv.read_text().splitlines() if line.strip()) - 1, 0)  # header


def wait_rows(child: subprocess.Popen, out: Path, at_least: int, timeout: float = 600) -> None:
    t0 = time.monotonic()
    while rows(out) < at_least:
        if child.poll() is not None or time.monotonic() - t0 > timeout:
            raise RuntimeError(f"the run ended before {at_least} frames: {child.stderr.read()}")
        time.sleep(0.02)


def frames_in(path: Path, salvage: bool) -> int:
    return sum(1 for _ in read_session(path, salvage=salvage).records())


def sigterm(tmp: Path, frames: int, scene: str) -> dict:
    out = tmp / "term"
    child = start(out, frames, scene)
    wait_rows(child, out, frames // 2)
    child.send_signal(signal.SIGTERM)
    _, err = child.communicate(timeout=300)
    done = rows(out)
    try:
        logged, footer = frames_in(out / "session.mcap", salvage=False), True
    except SessionLogError:
        logged, footer = frames_in(out / "session.mcap", salvage=True), False
    return {"exit": child.returncode, "stderr": err.strip(), "csv_rows": done, "frames_read": logged, "footer": footer}


def sigkills(tmp: Path, frames: int, scene: str, kills: int, seed: int, overrides=()) -> list[dict]:
    rng = np.random.default_rng(seed)
    results = []
    for k in range(kills):
        out = tmp / f"kill{k}"
        child = start(out, frames, scene, overrides)
        wait_rows(child, out, 1)
        target = int(rng.integers(1, frames * 3 // 4))  # a kill mid-run, not after the end
        try:
            wait_rows(child, out, target)
        except RuntimeError:
            pass
        time.sleep(float(rng.uniform(0, 0.3)))  # anywhere inside a frame
        finished_first = child.poll() is not None
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
        done = rows(out)
        salvaged = frames_in(out / "session.mcap", salvage=True)
        results.append({"kill": k, "csv_rows": done, "salvaged": salvaged, "lost": max(done - salvaged, 0), "ended_before": finished_first})
    return results


def main(argv=None) -> int:
    bench = Benchmark("signals", __doc__, frames=50, seed=29, settings=True)  # --set: settings for the killed runs
    bench.parser.add_argument("--scene", default="rooms")
    bench.parser.add_argument("--kills", type=int, default=10)
    args = bench.parse(argv)
    if args.quick:
        args.frames, args.kills = 8, 1
    with tempfile.TemporaryDirectory(prefix="zfloc-signals-") as tmp:
        term = sigterm(Path(tmp), args.frames, args.scene)
        bench.table(["signal", ("exit", "exit code"), ("footer", "footer written"), ("frames_read", "frames read"),
                     ("csv_rows", "trajectory.csv rows")], title="SIGTERM").add(signal="SIGTERM", **term)
        bench.note(f"stderr: {term['stderr']!r}")
        table = bench.table(["kill", ("csv_rows", "frames finished"), ("salvaged", "read back with salvage"), "lost",
                             ("ended_before", "run ended before the kill")], title="SIGKILL")
        results = [table.add(**r) for r in sigkills(Path(tmp), args.frames, args.scene, args.kills, args.seed, args.set)]
        bench.note(f"SIGKILL x{len(results)}: frames lost per kill {[r['lost'] for r in results]}, max {max(r['lost'] for r in results)}")
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
