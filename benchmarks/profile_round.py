"""Where a round's time goes on the shared real buildings (issue 10).

Cases: two held-out Carmen laser windows (fixed scale, as benchmarks/evaluation/eval_real.py builds
them) and the camera session intel-camera-30 (scale_mode prior, and free). Each case runs
a fresh Localizer twice over the same frames: the first pass fills the per-floorplan
caches (its first round is reported as "cold"), the second is measured (caches warm).
Per round stage: median / p95 / max in ms; "round" is primitives + model estimation +
scoring + refinement + tracking (the tracker update) + local_refinement (the tracked mode's
alignment on the recent hits). Each case also splits its rounds into global ones (no
mode confidently tracked: the full search, correlative seeding included) and tracked ones
(estimator.ransac.tracking_iterations, no global search); the laser-*-300 cases are longer
stretches (scans 100-400) where most rounds are tracked.

    python -m benchmarks.profile_round                      # all cases, stage table
    python -m benchmarks.profile_round --cases camera-prior --profile 25
    python -m benchmarks.profile_round --set estimator.scoring.backend=torch
    python -m benchmarks.profile_round --dump out.json      # per-frame status + pose, to
    python -m benchmarks.profile_round --compare a.json b.json   # compare two code versions
    python -m benchmarks.profile_round --cases laser-aces-300,laser-fhw-300,laser-intel-300
"""

from __future__ import annotations

import cProfile
import os
import json
import pstats
import sys
import time
from pathlib import Path

import numpy as np

from zfloc_stream.stream.localizer import Localizer

from benchmarks.harness import Benchmark
from benchmarks.shared_data import SHARED_DATA as SHARED

STAGES = ("primitives", "model_estimation", "scoring", "refinement", "tracking", "local_refinement")
LASER = {"laser-aces": ("aces", 200, 50), "laser-fhw": ("fhw", 300, 35),
         # optional (not in the default run)
         "laser-intel": ("intel", 400, 50), "laser-belgioioso": ("belgioioso", 150, 35), "laser-orebro": ("orebro", 100, 35),
         # longer stretches (scans 100-400), where most rounds follow a tracked mode
         **{f"laser-{log}-300": (log, 100, 300) for log in ("aces", "fhw", "intel")}}
CAMERA = {"camera-prior": ("intel-camera-30", "prior"), "camera-free": ("intel-camera-30", "free")}
# the other shared camera sessions (not in the default run: bigger maps, 50 frames each)
CAMERA.update({f"camera-{b}-{m}": (f"{b}-camera-50", m) for b in ("aces", "belgioioso", "fhw") for m in ("prior", "free")})
DEFAULT = ["laser-aces", "laser-fhw", "camera-prior", "camera-free"]


# The modules build_case needs, in the package's folders, and where a checkout from before
# the folders (issue 42) had them (a reference for --against)
MODULES = ("settings.loading", "io.datasets.carmen", "plans.floorplan", "stream.localizer", "io.session")
FLAT_MODULES = ("config", "datasets.carmen", "floorplan", "localizer", "session")


def package(prefix: str = "zfloc_stream"):
    """The modules build_case needs, from the installed package or from a reference
    checkout loaded under another name (--against)."""
    import importlib

    try:
        return [importlib.import_module(f"{prefix}.{n}") for n in MODULES]
    except ModuleNotFoundError:
        return [importlib.import_module(f"{prefix}.{n}") for n in FLAT_MODULES]


def load_reference(checkout: Path, alias: str = "zfloc_ref") -> str:
    """Import the zfloc_stream package of another checkout as `alias` (its imports are
    relative), so old and new code run side by side in one process."""
    import importlib.util

    pkg = checkout / "zfloc_stream"
    spec = importlib.util.spec_from_file_location(alias, pkg / "__init__.py", submodule_search_locations=[str(pkg)])
    module = importlib.util.module_from_spec(spec)
    sys.modules[alias] = module
    spec.loader.exec_module(module)
    return alias


def build_case(name: str, prefix: str = "zfloc_stream", overrides: tuple[str, ...] = ()):
    """(floorplan, frames, settings) of one case (dotted.key=value overrides on top of the
    case's own); built outside any timing."""
    config, carmen, floorplan_mod, _, session = package(prefix)
    load_settings, carmen_sequence, Floorplan, read_session = (
        config.load_settings, carmen.carmen_sequence, floorplan_mod.Floorplan, session.read_session)
    if name in LASER:
        log, start, length = LASER[name]
        settings = load_settings(base_overrides={"estimator": {"scale_mode": "fixed"}}, overrides=list(overrides))
        seq = carmen_sequence(SHARED / "carmen" / f"{log}-corrected.log.gz", settings)
        return seq.floorplan_for(start, start + length), list(seq.frames(start, start + length)), settings
    session, mode = CAMERA[name]
    folder = SHARED / "sessions" / session
    settings = load_settings(base_overrides={"estimator": {"scale_mode": mode}}, overrides=list(overrides))
    frames = list(read_session(folder / "session.mcap").frames())
    return Floorplan.load(folder / "map.yaml", settings=settings), frames, settings


def landed(estimate) -> bool:
    """Whether a round landed with this push (its stage timings are there): the
    one test for both rounds() and run()'s kinds, so the two lists line up."""
    return "primitives" in estimate.timings


def run(floorplan, frames, settings, kinds: list | None = None):
    """Estimates of a fresh Localizer pushed every frame; kinds (when given) gets, per
    round, "tracked" (it followed a tracked mode) or "global" (it searched globally)."""
    loc = Localizer(floorplan, settings)
    out = []
    for f in frames:
        out.append(loc.push(f))
        if kinds is not None and landed(out[-1]):
            kinds.append("tracked" if loc.last_round.tracked else "global")
    return out


def side_by_side(name: str, reference: str, passes: int) -> None:
    """Reference and current code on the same case in one process, frame by frame
    alternately (both warm: a first pass of each fills the caches), so a busy machine
    slows both alike; per-round stage times are minima over the passes. Also checks that
    both give the same statuses and bit-identical poses."""
    cases = {"ref": build_case(name, reference), "new": build_case(name)}
    classes = {"ref": package(reference)[3].Localizer, "new": Localizer}
    times = {"ref": None, "new": None}
    records = {}
    for p in range(passes + 1):
        locs = {k: classes[k](cases[k][0], cases[k][2]) for k in cases}
        ests = {k: [] for k in cases}
        for i in range(len(cases["new"][1])):
            for k in (("ref", "new") if (i + p) % 2 == 0 else ("new", "ref")):
                ests[k].append(locs[k].push(cases[k][1][i]))
        for k in cases:
            records[k] = record(ests[k])
            if p > 0:
                r = rounds(ests[k])
                times[k] = r if times[k] is None else [{s: min(a[s], b[s]) for s in a} for a, b in zip(times[k], r)]
    same = records["ref"] == records["new"]
    print(f"{name}: {len(times['new'])} rounds, reference vs current, minimum of {passes} passes; "
          f"statuses and poses {'IDENTICAL' if same else 'DIFFER'}")
    for s in (*STAGES, "round"):
        a, b = (np.array([r[s] for r in times[k]]) for k in ("ref", "new"))
        print(f"  {s:17s} median {np.median(a):7.1f} -> {np.median(b):7.1f}   p95 {np.percentile(a, 95):7.1f} -> {np.percentile(b, 95):7.1f} ms")
    return times


def rounds(estimates) -> list[dict]:
    out = []
    for e in estimates:
        if landed(e):
            t = {k: 1000 * e.timings.get(k, 0.0) for k in STAGES}
            t["round"] = sum(t.values())
            out.append(t)
    return out


def record(estimates) -> list[dict]:
    return [{"status": e.status, "pose": None if e.pose is None else [float(v) for v in e.pose], "score": None if not np.isfinite(e.score) else float(e.score),
             "scale": None if e.alignment is None else float(e.alignment.s), "modes": len(e.alternatives),
             "skipped": e.skipped} for e in estimates]


def add_summary(table, name: str, warm: list[dict], cold_first: float, kinds: list[str], seconds: float) -> None:
    """Rows of one case: per stage median / p95 / max of the warm rounds, then the global
    and the tracked rounds apart (a tracked round skips the global search)."""
    for k in (*STAGES, "round"):
        v = np.array([r[k] for r in warm])
        table.add(case=name, rows=k, n=len(v), median_ms=float(np.median(v)), p95_ms=float(np.percentile(v, 95)), max_ms=float(v.max()),
                  cold_first_round_ms=cold_first, whole_pass_s=seconds)
    for kind in ("global", "tracked"):
        v = np.array([r["round"] for r, q in zip(warm, kinds) if q == kind])
        if len(v):
            table.add(case=name, rows=f"{kind} rounds", n=len(v), median_ms=float(np.median(v)))


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
    # --repeat: warm passes, each round's stage times the minimum over them (a busy machine);
    # --set: for every case (e.g. estimator.scoring.backend=torch)
    bench = Benchmark("profile_round", __doc__, repeat=1, settings=True)
    parser = bench.parser
    parser.add_argument("--cases", default=",".join(DEFAULT), help=f"any of {', '.join([*LASER, *CAMERA])}")
    parser.add_argument("--profile", type=int, default=0, help="cProfile the warm pass; print this many functions")
    parser.add_argument("--dump", type=Path, help="write per-frame status + pose of every case here (JSON)")
    parser.add_argument("--compare", type=Path, nargs=2, metavar=("A", "B"))
    parser.add_argument("--against", type=Path, metavar="CHECKOUT", help="run a reference checkout's code side by side (A/B)")
    args = bench.parse(argv)
    if args.quick:  # the first 20 scans of the fhw window
        args.cases = "laser-fhw"
    unknown = [c for c in args.cases.split(",") if c not in LASER and c not in CAMERA]
    if unknown and not args.compare:
        parser.error(f"--cases: unknown case(s) {', '.join(unknown)}; known: {', '.join([*LASER, *CAMERA])}")
    if args.compare:
        return compare(*args.compare)
    if args.against:
        reference = load_reference(args.against)
        pooled = {"ref": [], "new": []}
        for name in args.cases.split(","):
            times = side_by_side(name, reference, max(1, args.repeat))
            if name in LASER or CAMERA[name][1] == "prior":
                for k in pooled:
                    pooled[k] += [r["round"] for r in times[k]]
        if pooled["new"]:
            a, b = np.array(pooled["ref"]), np.array(pooled["new"])
            print(f"metric prior/fixed, all rounds: median {np.median(a):.1f} -> {np.median(b):.1f} ms, "
                  f"p95 {np.percentile(a, 95):.1f} -> {np.percentile(b, 95):.1f} ms")
        return 0
    import zfloc_stream

    bench.note(f"zfloc_stream from {Path(zfloc_stream.__file__).parent}")
    table = bench.table(["case", ("rows", "stage"), "n", ("median_ms", "median ms"), ("p95_ms", "p95"), ("max_ms", "max"),
                         ("cold_first_round_ms", "cold first round ms"), ("whole_pass_s", "whole pass s")], title="round stages, warm")
    dump, all_warm = {}, []
    for name in args.cases.split(","):
        floorplan, frames, settings = build_case(name, overrides=tuple(args.set))
        frames = frames[:20] if args.quick else frames
        cold = run(floorplan, frames, settings)
        cold_rounds = rounds(cold)
        profiler = cProfile.Profile() if args.profile else None
        if profiler:
            profiler.enable()
        t0 = time.perf_counter()
        kinds: list[str] = []
        warm = run(floorplan, frames, settings, kinds)
        seconds = time.perf_counter() - t0
        warm_rounds = rounds(warm)
        for _ in range(args.repeat - 1):
            warm_rounds = [{k: min(r[k], q[k]) for k in r} for r, q in zip(warm_rounds, rounds(run(floorplan, frames, settings)))]
        if profiler:
            profiler.disable()
        add_summary(table, name, warm_rounds, cold_rounds[0]["round"] if cold_rounds else float("nan"), kinds, seconds)
        if profiler:
            pstats.Stats(profiler).sort_stats(os.environ.get("SORT", "tottime")).print_stats(args.profile)
        if name in LASER or CAMERA[name][1] == "prior":
            all_warm += warm_rounds
        dump[name] = record(warm)
        assert record(cold) == dump[name], f"{name}: the cold and warm passes differ"
    if all_warm:
        v = np.array([r["round"] for r in all_warm])
        table.add(case="metric prior/fixed, all", rows="round", n=len(v), median_ms=float(np.median(v)), p95_ms=float(np.percentile(v, 95)))
    if args.dump:
        args.dump.write_text(json.dumps(dump, indent=0))
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
