"""Time one 500-iteration localization (hybrid RANSAC + scoring + refinement).

    python benchmarks/bench_localize.py [--seeds 7] [--iterations 500] [--scenes apartment office]

Scenario: the batch-localization test's (tests/test_batch_localization.py): a RollingBEV
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

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_batch_localization import make_trial, pose_errors  # noqa: E402  (scenario shared with the test)

from zfloc_stream.settings.loading import Settings  # noqa: E402
from zfloc_stream.estimation import localize  # noqa: E402
from zfloc_stream.runtime.rng import make_rng  # noqa: E402
from zfloc_stream.sim.builtin_scenes import build_scene  # noqa: E402

GOALS_MS = {"apartment": 50.0, "office": 630.0}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["apartment", "office"])
    parser.add_argument("--seeds", type=int, default=7)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--iterations", type=int, default=500)
    args = parser.parse_args(argv)
    cfg = Settings()
    keys = ("model_estimation", "scoring", "refinement")
    print(f"{'scene':10s} {'total ms':>9s} {'model':>7s} {'score':>7s} {'refine':>7s} {'cpu ms':>7s} {'models':>7s} {'ok':>5s}  goal")
    for name in args.scenes:
        scene = build_scene(name, 0)
        rows, cpu, models, ok = [], [], [], 0
        for seed in range(args.seeds):
            trial = make_trial(scene, seed, cfg)
            localize(scene.floorplan, trial.obs, cfg.estimator, make_rng(seed, "bench"), iterations=args.iterations)  # warm caches
            for r in range(args.repeats):
                c0 = time.process_time()
                result = localize(scene.floorplan, trial.obs, cfg.estimator, make_rng(seed, "bench", r), iterations=args.iterations)
                cpu.append(time.process_time() - c0)
                rows.append([result.timings[k] for k in keys])
                models.append(result.n_models)
            if result.best is not None:
                position, heading = pose_errors(result.best.alignment, trial)
                ok += position < 0.5 and heading < 5.0
        t = np.median(np.array(rows), axis=0) * 1000
        total = np.median(np.array(rows).sum(axis=1)) * 1000
        goal = GOALS_MS.get(name)
        print(
            f"{name:10s} {total:9.1f} {t[0]:7.1f} {t[1]:7.1f} {t[2]:7.1f} {np.median(cpu) * 1000:7.1f} "
            f"{int(np.median(models)):7d} {ok:2d}/{args.seeds:<2d}  {'<= %.0f ms' % goal if goal else ''}"
        )


if __name__ == "__main__":
    main()
