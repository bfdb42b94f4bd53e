"""Scoring throughput, numpy vs the torch backend (scoring.backend, issue 10).

The BEV of an ACES laser window after 30 scans (benchmarks/profile_round.py's laser-aces
case: the map of the log without the window), scored under N random hypotheses spread
over the map: coarse Cc on the sparse line points, full Cc on every BEV wall point, Cv.
Milliseconds per call (the best of --repeats after one warm call) per backend and device:
numpy, torch on CPU, and torch on CUDA when torch sees a GPU. The torch scores equal the
numpy ones (checked here on every call: bit for bit on CPU, within one point per
hypothesis on a GPU; tests/test_scoring_torch.py).

    python -m benchmarks.bench_scoring
    python -m benchmarks.bench_scoring --hypotheses 100 1000 10000 --repeats 5

Measured on the shared 2-core machine (no GPU; load average ~2 from other jobs):

    backend      n  coarse    full      Cv   (ms)
    numpy       50     0.1     4.0     1.8
    numpy      500     0.7    66.3    11.5
    numpy     5000     9.2   479.3   111.5
    torch-cpu   50     0.2     6.6     9.7
    torch-cpu  500     1.6   103.4   100.7
    torch-cpu 5000    16.7   606.6  1151.1

A second run (load average 0.7, after the uint8 coarse pass), where torch's two intra-op
threads had both cores:

    numpy       50     0.2     3.8     1.7
    numpy      500     0.6    72.9    11.5
    numpy     5000     7.9   488.8   124.3
    torch-cpu   50     0.3     4.7     5.1
    torch-cpu  500     0.9    39.4    54.8
    torch-cpu 5000     8.1   328.5   443.3

On CPU the torch path is slower overall (the numpy kernels are cache-tuned and Cv only reads the
floorplan wall points near each hypothesis, where torch reads all of them masked, a
layout for a GPU): keep numpy there. No GPU was available to measure the CUDA column.
"""

from __future__ import annotations

import time

import numpy as np

from zfloc_stream.estimation.scoring import BevView, floorplan_scorer, scoring_kernels, sparse_line_points
from zfloc_stream.stream.localizer import Localizer

from benchmarks.harness import Benchmark
from benchmarks.profile_round import build_case


def best_ms(fn, repeats: int) -> tuple[float, np.ndarray]:
    out = fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1000 * min(times), out


def main(argv=None) -> int:
    bench = Benchmark("scoring", __doc__, repeat=3)
    bench.parser.add_argument("--hypotheses", type=int, nargs="+", default=[50, 500, 5000])
    args = bench.parse(argv)
    scans = 30
    if args.quick:  # 10 scans, 20 hypotheses, numpy and torch on the CPU, one repeat
        scans, args.hypotheses, args.repeat = 10, [20], 1
    floorplan, frames, settings = build_case("laser-aces")
    localizer = Localizer(floorplan, settings)
    for frame in frames[:scans]:
        localizer.push(frame)
    obs = localizer.bev.observation(np.random.default_rng(0))
    cfg = settings.estimator.scoring
    view = BevView.of(obs, cfg.tau_v)
    sparse = sparse_line_points(obs.lines, cfg.sparse_spacing, cfg.max_sparse_points)
    bench.note(f"BEV: {len(obs.wall_points)} wall points, {len(sparse)} sparse; floorplan: "
               f"{len(floorplan_scorer(floorplan, cfg).wall_points)} wall points for Cv")
    backends = [("numpy", "numpy", "cpu")]
    try:
        import torch

        backends.append(("torch-cpu", "torch", "cpu"))
        if torch.cuda.is_available() and not args.quick:
            backends.append(("torch-cuda", "torch", "cuda"))
    except ImportError:
        bench.note("torch not installed: numpy only")
    x0, y0, x1, y1 = floorplan.extent
    rng = np.random.default_rng(0)
    models = {n: np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n), rng.uniform(-np.pi, np.pi, n), np.ones(n)])
              for n in args.hypotheses}
    reference = {}
    table = bench.table(["backend", ("n", "hypotheses"), ("coarse_ms", "coarse ms"), ("full_ms", "full ms"), ("cv_ms", "Cv ms"),
                         ("worst_difference", "largest difference from numpy")])
    for label, backend, device in backends:
        kernels = scoring_kernels(floorplan, cfg.model_copy(update={"backend": backend, "device": device}))
        for n, m in models.items():
            row, worst_all = [], 0.0
            for stage, fn, n_points in (
                ("coarse", lambda: kernels.coarse_consistency(m, sparse, cfg.chunk_size), len(sparse)),
                ("full", lambda: kernels.consistency(m, obs.wall_points, cfg.tau_c, cfg.chunk_size), len(obs.wall_points)),
                ("cv", lambda: kernels.violation(m, view, cfg.tau_v, cfg.chunk_size, cfg.violation_per), None),
            ):
                ms, out = best_ms(fn, args.repeat)
                row.append(ms)
                ref = reference.setdefault((n, stage), out)
                worst = float(np.abs(out - ref).max())
                worst_all = max(worst_all, worst)
                if worst > (1.0 / n_points if n_points else 0.02) + 1e-12:
                    bench.note(f"  {label} {stage} n={n}: differs from numpy by {worst:.3g}")
            table.add(backend=label, n=n, coarse_ms=row[0], full_ms=row[1], cv_ms=row[2], worst_difference=worst_all)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
