"""Reading a session whose messages are not in log-time order (issue 44): the same frames
written in order, grouped by topic and shuffled, each read in a fresh process: frames read,
wall time, peak RSS (sampled every frame).

    python -m benchmarks.bench_session_order                 # 300 frames of 240x320 depth + labels
    python -m benchmarks.bench_session_order --frames 1000

A file in order holds one chunk at a time; grouped by topic one per topic; shuffled, every
chunk overlaps every other and the read holds the whole file (bounded beforehand by
logging.reorder_max_mb). Wall times on a shared machine include waiting for a core. --quick: 5 frames of 24x32.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.harness import ROOT, Benchmark
from benchmarks.inputs.hostile_sessions import frame_messages, ordered, write_messages
from benchmarks.inputs.session_frames import camera_frames

# peak RSS sampled every frame (ru_maxrss would carry the writing parent's peak across exec)
CHILD = """
import sys, time, psutil
from zfloc_stream.io.session import read_session
proc = psutil.Process()
t = time.perf_counter()
n = peak = 0
for _ in read_session(sys.argv[1]).frames():
    n += 1
    peak = max(peak, proc.memory_info().rss)
print(n, round(time.perf_counter() - t, 2), round(peak / 2**20))
"""


def main(argv=None) -> int:
    bench = Benchmark("session_order", __doc__, frames=300)
    args = bench.parse(argv)
    shape = (240, 320)
    if args.quick:
        args.frames, shape = 5, (24, 32)
    msgs = frame_messages(camera_frames(args.frames, seed=1, shape=shape))
    table = bench.table(["order", "frames", ("read_s", "read s"), ("peak_rss_mib", "peak RSS MiB"), ("file_mib", "file MiB")])
    with tempfile.TemporaryDirectory() as tmp:
        for order in ("time", "topic", "shuffled"):
            path = Path(tmp) / f"{order}.mcap"
            write_messages(path, ordered(msgs, order, np.random.default_rng(0)), chunk_size=1 << 20)
            out = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, check=True, cwd=ROOT)
            n, wall, rss = out.stdout.split()
            table.add(order=order, frames=int(n), read_s=float(wall), peak_rss_mib=int(rss), file_mib=path.stat().st_size / 2**20)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
