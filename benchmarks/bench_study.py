"""Study throughput: chunks per second of `run_study` with 1 and 2 local worker processes
(and in-process, no dask), on the same cells. Wall time includes starting the cluster.

    .venv/bin/python benchmarks/bench_study.py [--dataset sim:rooms,apartment] [--length 20]
        [--chunks 4] [--seeds 2] [--workers 0,1,2]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from zfloc_stream.study import run_study


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", default="sim:rooms,apartment")
    p.add_argument("--length", type=int, default=20)
    p.add_argument("--chunks", type=int, default=4, help="study.max_chunks_per_sequence")
    p.add_argument("--seeds", type=int, default=2)
    p.add_argument("--workers", default="0,1,2", help="comma-separated worker counts (0 = in-process)")
    args = p.parse_args()
    overrides = {"study": {"max_chunks_per_sequence": args.chunks}}
    reference = None
    for workers in (int(w) for w in args.workers.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            out = run_study([args.dataset], [args.length], list(range(args.seeds)), Path(tmp), overrides=overrides,
                            workers=workers, progress=False)
            wall = time.perf_counter() - t0
        metrics = [{k: v for k, v in r.items() if k != "seconds"} for r in out.rows]
        same = reference is None or metrics == reference
        reference = reference or metrics
        per_chunk = sum(r["seconds"] for r in out.rows) / len(out.rows)
        print(f"workers={workers}: {len(out.rows)} chunks in {wall:.1f} s = {len(out.rows) / wall:.3f} chunks/s "
              f"(mean {per_chunk:.2f} s of work per chunk; results identical to the first run: {same})", flush=True)


if __name__ == "__main__":
    main()
