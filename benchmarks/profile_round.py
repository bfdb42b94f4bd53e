"""Where a round's time goes on the shared real buildings (issue 10).

Cases: two held-out Carmen laser windows (fixed scale, as benchmarks/eval_real.py builds
them) and the camera session intel-camera-30 (scale_mode prior, and free). Each case runs
a fresh Localizer twice over the same frames: the first pass fills the per-floorplan
caches (its first round is reported as "cold"), the second is measured (caches warm).
Per round stage: median / p95 / max in ms; "round" is primitives + model estimation +
scoring + refinement + tracking.

    python benchmarks/profile_round.py                      # all cases, stage table
    python benchmarks/profile_round.py --cases camera-prior --profile 25
    python benchmarks/profile_round.py --dump out.json      # per-frame status + pose, to
    python benchmarks/profile_round.py --compare a.json b.json   # compare two code versions
"""

from __future__ import annotations

import argparse
import cProfile
import os
import json
import pstats
import sys
import time
from pathlib import Path

import numpy as np

from zfloc_stream.config import load_settings
from zfloc_stream.datasets.carmen import carmen_sequence
from zfloc_stream.floorplan import Floorplan
from zfloc_stream.localizer import Localizer
from zfloc_stream.session import read_session

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
STAGES = ("primitives", "model_estimation", "scoring", "refinement", "tracking")
LASER = {"laser-aces": ("aces", 200, 50), "laser-fhw": ("fhw", 300, 35)}
CAMERA = {"camera-prior": ("intel-camera-30", "prior"), "camera-free": ("intel-camera-30", "free")}


def build_case(name: str):
    """(floorplan, frames, settings) of one case; built outside any timing."""
    if name in LASER:
        log, start, length = LASER[name]
        settings = load_settings(base_overrides={"estimator": {"scale_mode": "fixed"}})
        seq = carmen_sequence(SHARED / "carmen" / f"{log}-corrected.log.gz", settings)
        return seq.floorplan_for(start, start + length), list(seq.frames(start, start + length)), settings
    session, mode = CAMERA[name]
    folder = SHARED / "sessions" / session
    settings = load_settings(base_overrides={"estimator": {"scale_mode": mode}})
    frames = list(read_session(folder / "session.mcap").frames())
    return Floorplan.load(folder / "map.yaml", settings=settings), frames, settings


def run(floorplan, frames, settings):
    loc = Localizer(floorplan, settings)
    return [loc.push(f) for f in frames]


def rounds(estimates) -> list[dict]:
    out = []
    for e in estimates:
        if "primitives" in e.timings:
            t = {k: 1000 * e.timings.get(k, 0.0) for k in STAGES}
            t["round"] = sum(t.values())
            out.append(t)
    return out


def record(estimates) -> list[dict]:
    return [{"status": e.status, "pose": None if e.pose is None else [float(v) for v in e.pose], "score": None if not np.isfinite(e.score) else float(e.score),
             "scale": None if e.alignment is None else float(e.alignment.s), "modes": len(e.alternatives),
             "skipped": e.skipped} for e in estimates]


def summary(name: str, warm: list[dict], cold_first: float) -> str:
    lines = [f"{name}: {len(warm)} rounds, cold first round {cold_first:.0f} ms"]
    for k in (*STAGES, "round"):
        v = np.array([r[k] for r in warm])
        lines.append(f"  {k:17s} median {np.median(v):7.1f}  p95 {np.percentile(v, 95):7.1f}  max {v.max():7.1f}")
    return "\n".join(lines)


def compare(a_path: Path, b_path: Path) -> int:
    a, b = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    bad = 0
    for case in a:
        if case not in b:
            continue
        fa, fb = a[case], b[case]
        worst, before = 0.0, bad
        for i, (x, y) in enumerate(zip(fa, fb)):
            if (x["status"], x["modes"], x["skipped"], x["pose"] is None) != (y["status"], y["modes"], y["skipped"], y["pose"] is None):
                print(f"{case} frame {i}: {x} != {y}")
                bad += 1
            elif x["pose"] is not None:
                worst = max(worst, float(np.max(np.abs(np.subtract(x["pose"], y["pose"])))), abs(x["scale"] - y["scale"]))
        if len(fa) != len(fb):
            print(f"{case}: {len(fa)} vs {len(fb)} frames")
            bad += 1
        print(f"{case}: {len(fa)} frames, decisions {'identical' if bad == before else 'DIFFER'}, largest pose/scale difference {worst:.3g}")
    return 1 if bad else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=",".join([*LASER, *CAMERA]))
    parser.add_argument("--profile", type=int, default=0, help="cProfile the warm pass; print this many functions")
    parser.add_argument("--repeat", type=int, default=1, help="warm passes; each round's stage times are the minimum over them (a busy machine)")
    parser.add_argument("--dump", type=Path, help="write per-frame status + pose of every case here (JSON)")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("A", "B"))
    args = parser.parse_args(argv)
    if args.compare:
        return compare(*args.compare)
    import zfloc_stream

    print(f"zfloc_stream from {Path(zfloc_stream.__file__).parent}")
    dump, all_warm = {}, []
    for name in args.cases.split(","):
        floorplan, frames, settings = build_case(name)
        cold = run(floorplan, frames, settings)
        cold_rounds = rounds(cold)
        profiler = cProfile.Profile() if args.profile else None
        if profiler:
            profiler.enable()
        t0 = time.perf_counter()
        warm = run(floorplan, frames, settings)
        seconds = time.perf_counter() - t0
        warm_rounds = rounds(warm)
        for _ in range(args.repeat - 1):
            warm_rounds = [{k: min(r[k], q[k]) for k in r} for r, q in zip(warm_rounds, rounds(run(floorplan, frames, settings)))]
        if profiler:
            profiler.disable()
        print(summary(name, warm_rounds, cold_rounds[0]["round"] if cold_rounds else float("nan")) + f"\n  whole pass {seconds:.2f} s")
        if profiler:
            pstats.Stats(profiler).sort_stats(os.environ.get("SORT", "tottime")).print_stats(args.profile)
        if name in LASER or CAMERA[name][1] == "prior":
            all_warm += warm_rounds
        dump[name] = record(warm)
        assert record(cold) == dump[name], f"{name}: the cold and warm passes differ"
    if all_warm:
        v = np.array([r["round"] for r in all_warm])
        print(f"metric prior/fixed, all rounds: median {np.median(v):.1f} ms, p95 {np.percentile(v, 95):.1f} ms")
    if args.dump:
        args.dump.write_text(json.dumps(dump, indent=0))
    return 0


if __name__ == "__main__":
    sys.exit(main())
