"""Study throughput: chunks per second of `run_study` with 1 and 2 local worker processes
(and in-process, no dask), on the same cells. Wall time includes starting the cluster.

    python -m benchmarks.bench_study [--dataset sim:rooms,apartment] [--length 20]
        [--chunks 4] [--seeds 2] [--workers 0,1,2]

--quick: in-process only, one seed, one chunk of 10 frames.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from zfloc_stream.study import run_study

from benchmarks.harness import Benchmark


def main(argv=None) -> int:
    bench = Benchmark("study", __doc__)
    bench.parser.add_argument("--dataset", default="sim:rooms,apartment")
    bench.parser.add_argument("--length", type=int, default=20)
    bench.parser.add_argument("--chunks", type=int, default=4, help="study.max_chunks_per_sequence")
    bench.parser.add_argument("--seeds", type=int, default=2)
    bench.parser.add_argument("--workers", default="0,1,2", help="comma-separated worker counts (0 = in-process)")
    args = bench.parse(argv)
    if args.quick:
        args.dataset, args.length, args.chunks, args.seeds, args.workers = "sim:rooms", 10, 1, 1, "0"
    overrides = {"study": {"max_chunks_per_sequence": args.chunks}}
    reference = None
    table = bench.table(["workers", "chunks", ("wall_s", "wall s"), ("chunks_per_s", "chunks/s"),
                         ("work_per_chunk_s", "work per chunk s"), ("same_as_first", "results as the first run")])
    for workers in (int(w) for w in args.workers.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            out = run_study([args.dataset], [args.length], list(range(args.seeds)), Path(tmp), overrides=overrides,
                            workers=workers, progress=False)
            wall = time.perf_counter() - t0
        metrics = [{k: v for k, v in r.items() if k != "seconds"} for r in out.rows]
        same = reference is None or metrics == reference
        reference = reference or metrics
        table.add(workers=workers, chunks=len(out.rows), wall_s=wall, chunks_per_s=len(out.rows) / wall,
                  work_per_chunk_s=sum(r["seconds"] for r in out.rows) / len(out.rows), same_as_first=same)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
