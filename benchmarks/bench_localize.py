"""Time one 500-iteration localization (hybrid RANSAC + scoring + refinement).

    python -m benchmarks.bench_localize [--seeds 7] [--iterations 500] [--scenes apartment office]

Scenario: the batch-localization test's (benchmarks/inputs/batch_trial.py): a RollingBEV
fused from 21 ray-cast scans along a 5 m path at an unknown scale. For each scene and seed
the localization runs once to warm the per-floorplan caches (lookup tables, scorer), then
`--repeats` times; the median over repeats and seeds is printed, split into model
estimation / scoring / refinement (wall clock, time.perf_counter, as reported in
LocalizationResult.timings) plus the process CPU time of the whole call (less sensitive to
other processes sharing the machine). Paper figures (CPU, 500 iterations): 0.51 s on
Gibson, 6.3 s on the large office; the goal here is <= 50 ms (apartment) and <= 630 ms
(office).
"""

from __future__ import annotations

import time

import numpy as np

from zfloc_stream.settings.loading import Settings
from zfloc_stream.estimation import localize
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.sim.scenes import build_scene

from benchmarks.harness import Benchmark
from benchmarks.inputs.batch_trial import MAX_HEADING_ERROR, MAX_POSITION_ERROR, make_trial, pose_errors

GOALS_MS = {"apartment": 50.0, "office": 630.0}


def main(argv=None) -> int:
    bench = Benchmark("localize", __doc__, repeat=3)
    bench.parser.add_argument("--scenes", nargs="+", default=["apartment", "office"])
    bench.parser.add_argument("--seeds", type=int, default=7, help="trials per scene (seeds 0..N-1)")
    bench.parser.add_argument("--iterations", type=int, default=500)
    args = bench.parse(argv)
    if args.quick:  # one apartment trial, one repeat, 100 iterations
        args.scenes, args.seeds, args.repeat, args.iterations = ["apartment"], 1, 1, 100
    cfg = Settings()
    keys = ("model_estimation", "scoring", "refinement")
    table = bench.table(["scene", ("total_ms", "total ms"), ("model_ms", "model"), ("score_ms", "score"), ("refine_ms", "refine"),
                         ("cpu_ms", "cpu ms"), "models", "ok", "trials", ("goal_ms", "goal ms")], formats={"models": "d"})
    for name in args.scenes:
        scene = build_scene(name, 0)
        rows, cpu, models, ok = [], [], [], 0
        for seed in range(args.seeds):
            trial = make_trial(scene, seed, cfg)
            localize(scene.floorplan, trial.obs, cfg.estimator, make_rng(seed, "bench"), iterations=args.iterations)  # warm caches
            for r in range(args.repeat):
                c0 = time.process_time()
                result = localize(scene.floorplan, trial.obs, cfg.estimator, make_rng(seed, "bench", r), iterations=args.iterations)
                cpu.append(time.process_time() - c0)
                rows.append([result.timings[k] for k in keys])
                models.append(result.n_models)
            if result.best is not None:
                position, heading = pose_errors(result.best.alignment, trial)
                ok += position < MAX_POSITION_ERROR and heading < MAX_HEADING_ERROR
        t = np.median(np.array(rows), axis=0) * 1000
        table.add(scene=name, total_ms=float(np.median(np.array(rows).sum(axis=1)) * 1000), model_ms=float(t[0]), score_ms=float(t[1]),
                  refine_ms=float(t[2]), cpu_ms=float(np.median(cpu) * 1000), models=int(np.median(models)), ok=int(ok),
                  trials=args.seeds, goal_ms=GOALS_MS.get(name), iterations=args.iterations, repeat=args.repeat)
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
