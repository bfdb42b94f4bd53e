"""The wrong-map table of eval_real.py (--wrong-map, issue 43): every shared camera session
(../shared/data/sessions/) and every laser window of the shared Carmen logs run against
every OTHER shared building's map (sessions: the other sessions' map.yaml; laser windows:
the whole-log map of every other log), default settings (laser at fixed scale). Counted
per run: `tracking` frames (must be 0), whether the run ends with map_match's verdict
(the CLI's `warning: the map does not match ...`), frames with confidence >= 0.9, and the
share of judged frames the map explained."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.io.datasets.carmen import load_log
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.plans.map_from_log import map_from_log

from benchmarks.shared_data import SHARED_DATA

SESSIONS = SHARED_DATA / "sessions"


def _run(floorplan, frames, settings) -> dict:
    loc = Localizer(floorplan, settings)
    with loc:
        estimates = [loc.push(f) for f in frames]
    match = loc.map_match
    # per frame as eval_real's windows record them (calibration.py reads both): on another
    # building's map no pose is within 1 m of the truth, so every frame's error is None
    return {"frames": len(estimates), "tracking": sum(e.status == "tracking" for e in estimates),
            "confident": sum(bool(e.confidence >= 0.9) for e in estimates), "warned": match.verdict() is not None,
            "explained": match.explained / match.judged if match.judged else float("nan"),
            "frame_status": [str(e.status) for e in estimates], "frame_errors": [None] * len(estimates),
            "frame_confidence": [float(e.confidence) for e in estimates]}


def session_row(session: str, map_of: str, seed: int, overrides: list[str]) -> dict:
    from zfloc_stream.io.datasets.mcap import session_sequence
    from zfloc_stream.plans.loading import load_floorplan

    settings = load_settings(overrides=list(overrides)).model_copy(update={"seed": seed})
    seq = session_sequence(SESSIONS / session / "session.mcap", settings)
    plan = load_floorplan(SESSIONS / map_of / "map.yaml", settings=settings)
    return {"kind": "camera session", "input": session, "map": map_of, **_run(plan, list(seq.frames(0, seq.n_frames)), settings)}


@lru_cache(maxsize=None)  # one per shared log (a few MB each); the runs of a process share them
def _whole_map(log: str, data: Path):
    settings = load_settings()
    return map_from_log(load_log(data / f"{log}-corrected.log.gz", settings), [], settings)


def laser_row(log: str, start: int, length: int, map_of: str, seed: int, overrides: list[str], data: Path) -> dict:
    from benchmarks.evaluation.eval_real import laser_window  # the same frames as the right-map windows

    settings, _, frames = laser_window(log, start, length, overrides, seed)
    return {"kind": f"laser #{length}", "input": f"{log}@{start}", "map": map_of, **_run(_whole_map(map_of, data), frames, settings)}


def run(job: tuple) -> dict:
    """One run of jobs(): ("session", args) or ("laser", args)."""
    kind, args = job
    return session_row(*args) if kind == "session" else laser_row(*args)


def jobs(windows: list[tuple], logs: list[str], camera: bool, seed: int, overrides: list[str], data: Path) -> list[tuple]:
    """Every shared session on every other session's map (camera), every laser window
    (log, start, length) on every other log's whole-log map; grouped by map, so a worker
    builds each whole-log map once."""
    runs = [("session", (s, m, seed, overrides)) for s in sessions() for m in sessions() if s != m] if camera else []
    laser = [("laser", (log, start, length, other, seed, overrides, data)) for log, start, length in windows
             for other in logs if other != log]
    return runs + sorted(laser, key=lambda job: job[1][3])


def sessions() -> list[str]:
    return sorted(p.name for p in SESSIONS.iterdir() if (p / "session.mcap").is_file() and (p / "map.yaml").is_file()) \
        if SESSIONS.is_dir() else []


def table(rows: list[dict]) -> str:
    lines = ["| runs | pairs | frames | `tracking` frames | runs with the warning | confidence >= 0.9 | frames explained (median) |",
             "|---|---|---|---|---|---|---|"]
    for kind in dict.fromkeys(r["kind"] for r in rows):
        mine = [r for r in rows if r["kind"] == kind]
        lines.append(f"| {kind} | {len(mine)} | {sum(r['frames'] for r in mine)} | {sum(r['tracking'] for r in mine)} | "
                     f"{sum(r['warned'] for r in mine)}/{len(mine)} | {sum(r['confident'] for r in mine)} | "
                     f"{np.nanmedian([r['explained'] for r in mine]) * 100:.0f}% |")
    bad = [f"{r['input']} on {r['map']}: {r['tracking']} tracking" for r in rows if r["tracking"] or not r["warned"]]
    return "\n".join(lines) + ("\n\nruns with `tracking` frames or no warning: " + "; ".join(bad) if bad else "")
