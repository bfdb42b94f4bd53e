"""The large fuzz run over what a user hands the package: floorplans (ROS YAML + PNG, plain
images, DXF, SVG, GeoJSON) and settings (`--set key=text` as typed), with the seeded
generators of benchmarks/inputs/hostile_plans.py (the CI-sized runs: tests/test_floorplan_fuzz.py,
tests/test_settings_fuzz.py).

    python -m benchmarks.evaluation.fuzz_run                            # 1,200 + 1,200 cases
    python -m benchmarks.evaluation.fuzz_run --plans 3000 --settings 3000 --seed 7
    python -m benchmarks.evaluation.fuzz_run --run-accepted 20          # + accepted settings run a short scene

Every case must load or be refused by one ZflocError line; anything else is a traceback
(counted, the first ones printed). Each case runs under an alarm (--timeout s): a case
that outlasts it is a hang. Peak resident memory of the process (ru_maxrss) is reported
against --memory-budget (MiB) and the run fails past it. Exit 0 when there were no
tracebacks, no hangs and the peak stayed under the budget.
"""

from __future__ import annotations

import argparse
import resource
import signal
import sys
import tempfile
import time
import traceback
from collections import Counter
from pathlib import Path

import numpy as np

from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.errors import ZflocError
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.plans.loading import load_floorplan
from zfloc_stream.plans.vector import VECTOR_SUFFIXES, load_vector_floorplan

from benchmarks.inputs.hostile_plans import fuzz_floorplan, hostile_setting


class Hang(Exception):
    pass


def _alarm(signum, frame):
    raise Hang()


def peak_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def leaves(model, prefix: str = "") -> list[str]:
    out = []
    for name in type(model).model_fields:
        value = getattr(model, name)
        out += leaves(value, f"{prefix}{name}.") if hasattr(type(value), "model_fields") else [f"{prefix}{name}"]
    return out


def guarded(fn, timeout: float, tally: Counter, failures: list, label: str):
    """fn() under an alarm: 'ok' / 'refused' (ZflocError, one line) / 'hang' / 'traceback'."""
    signal.setitimer(signal.ITIMER_REAL, timeout)
    t0 = time.perf_counter()
    try:
        result = fn()
        tally["ok"] += 1
        return result
    except Hang:
        tally["hang"] += 1
        failures.append(f"{label}: no answer within {timeout} s")
    except ZflocError as err:
        if "\n" in str(err):
            tally["multi-line error"] += 1
            failures.append(f"{label}: error of {len(str(err).splitlines())} lines")
        else:
            tally["refused"] += 1
    except BaseException as err:  # noqa: BLE001 - what the fuzz is looking for
        if isinstance(err, KeyboardInterrupt):
            raise
        tally["traceback"] += 1
        failures.append(f"{label}: {type(err).__name__}: {err}\n{traceback.format_exc(limit=4)}")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        tally["slowest ms"] = max(tally["slowest ms"], int(1e3 * (time.perf_counter() - t0)))
    return None


def fuzz_plans(n: int, seed: int, timeout: float, d: Path) -> tuple[Counter, list, dict]:
    rng = np.random.default_rng(seed)
    tally, failures, kinds = Counter(), [], Counter()
    for case in range(n):
        path, kwargs = fuzz_floorplan(rng, d, case)
        kinds[path.suffix] += 1

        def load(path=path, kwargs=kwargs):
            if path.suffix in VECTOR_SUFFIXES:
                return load_vector_floorplan(path, **kwargs)
            return load_floorplan(path, **kwargs)

        guarded(load, timeout, tally, failures, f"plan {case} ({path.name}, {kwargs})")
        for f in d.glob(f"case{case}.*"):
            f.unlink()
    return tally, failures, dict(kinds)


def fuzz_settings(n: int, seed: int, timeout: float) -> tuple[Counter, list, list[Settings]]:
    rng = np.random.default_rng(seed)
    keys = leaves(Settings())
    tally, failures, accepted = Counter(), [], {}
    for case in range(n):
        override = hostile_setting(rng, keys)
        got = guarded(lambda o=override: load_settings(overrides=[o]), timeout, tally, failures, f"setting {case} ({override[:60]})")
        if got is not None:
            accepted.setdefault(got.model_dump_json(), got)
    return tally, failures, list(accepted.values())


def run_accepted(settings: list[Settings], timeout: float) -> tuple[Counter, list]:
    """Each distinct accepted setting runs a short laser walk through the session recorder."""
    from zfloc_stream.io.session import record_session
    from zfloc_stream.sim import LaserSimSettings, build_scene, simulate_laser

    scene = build_scene("rooms", 0)
    frames = simulate_laser(scene, LaserSimSettings(), seed=0, n_frames=6).frames
    tally, failures = Counter(), []
    with tempfile.TemporaryDirectory() as tmp:
        for i, s in enumerate(settings):
            def go(s=s, i=i):
                plan = Floorplan.from_occupancy(scene.occupied, scene.resolution, scene.origin, s)
                return record_session(Path(tmp) / f"s{i}.mcap", plan, frames, s)

            guarded(go, timeout, tally, failures, f"accepted setting {i}")
    return tally, failures


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plans", type=int, default=1200)
    p.add_argument("--settings", type=int, default=1200)
    p.add_argument("--seed", type=int, default=2029)
    p.add_argument("--timeout", type=float, default=60.0, help="seconds per case before it counts as a hang")
    p.add_argument("--memory-budget", type=float, default=1536.0, help="MiB of peak resident memory allowed")
    p.add_argument("--run-accepted", type=int, default=0, metavar="K", help="run the first K distinct accepted settings on a short scene")
    args = p.parse_args(argv)
    signal.signal(signal.SIGALRM, _alarm)
    start_mib = peak_mib()
    with tempfile.TemporaryDirectory(prefix="zfloc-fuzz-") as tmp:
        t0 = time.perf_counter()
        plans, plan_failures, kinds = fuzz_plans(args.plans, args.seed, args.timeout, Path(tmp))
        t_plans = time.perf_counter() - t0
    print(f"floorplans: {args.plans} cases {kinds}: {dict(plans)} in {t_plans:.0f} s ({1e3 * t_plans / max(args.plans, 1):.0f} ms/case); "
          f"peak RSS so far {peak_mib():.0f} MiB")
    t0 = time.perf_counter()
    sets, set_failures, accepted = fuzz_settings(args.settings, args.seed, args.timeout)
    t_sets = time.perf_counter() - t0
    print(f"settings: {args.settings} cases: {dict(sets)} ({len(accepted)} distinct accepted) in {t_sets:.0f} s; peak RSS so far {peak_mib():.0f} MiB")
    failures = plan_failures + set_failures
    if args.run_accepted:
        ran, run_failures = run_accepted(accepted[: args.run_accepted], args.timeout * 5)
        print(f"accepted settings run on a 6-frame laser walk: {dict(ran)}")
        failures += run_failures
    peak = peak_mib()
    print(f"peak resident memory: {peak:.0f} MiB (at start {start_mib:.0f} MiB); budget {args.memory_budget:.0f} MiB")
    for f in failures[:10]:
        print("FAIL", f)
    bad = sum(t.get(k, 0) for t in (plans, sets) for k in ("traceback", "hang", "multi-line error"))
    ok = not failures and not bad and peak <= args.memory_budget
    print("RESULT:", "pass" if ok else "FAIL", f"({len(failures)} failing cases)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
