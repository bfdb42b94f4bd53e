"""Reading a session whose messages are not in log-time order (issue 44): the same frames
written in order, grouped by topic and shuffled, each read in a fresh process: frames read,
wall time, peak RSS (sampled every frame).

    .venv/bin/python benchmarks/bench_session_order.py                 # 300 frames of 240x320 depth + labels
    .venv/bin/python benchmarks/bench_session_order.py --frames 1000

A file in order holds one chunk at a time; grouped by topic one per topic; shuffled, every
chunk overlaps every other and the read holds the whole file (bounded beforehand by
logging.reorder_max_mb). Wall times on a shared machine include waiting for a core.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--frames", type=int, default=300)
    args = p.parse_args()
    sys.path.insert(0, str(ROOT / "tests"))
    import numpy as np
    from session_helpers import camera_frames
    from session_hostile import frame_messages, ordered, write_messages

    msgs = frame_messages(camera_frames(args.frames, seed=1, shape=(240, 320)))
    with tempfile.TemporaryDirectory() as tmp:
        print("order      frames  read s  peak RSS MiB  file MiB")
        for order in ("time", "topic", "shuffled"):
            path = Path(tmp) / f"{order}.mcap"
            write_messages(path, ordered(msgs, order, np.random.default_rng(0)), chunk_size=1 << 20)
            out = subprocess.run([sys.executable, "-c", CHILD, str(path)], capture_output=True, text=True, check=True, cwd=ROOT)
            n, wall, rss = out.stdout.split()
            print(f"{order:<10} {n:>6}  {wall:>6}  {rss:>12}  {path.stat().st_size / 2**20:8.0f}")


if __name__ == "__main__":
    main()
