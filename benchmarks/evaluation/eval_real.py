"""SR@1m on real buildings: held-out windows of the shared Carmen laser logs (issue 9).

For every log in ../shared/data/carmen/ and every length L, `--windows` windows of L scans
spread evenly along the log (they may overlap on short logs). Each window:

- floorplan: map-from-log of the same log leaving the window and heldout_margin (25)
  scans either side out, so every wall seen comes from other passes (clutter, missing rooms);
- odometry: the true relative motion with realistic drift (datasets.odometry: per step
  2% of the step + 5 mm per axis, 2% of the turn + 0.3 deg), from a random origin;
- zfloc-stream: a fresh Localizer pushed the window's frames (what `run` writes to
  trajectory.csv, frame by frame);
- reference: exact correlative SE(2) search (0.1 m / 2 deg grid + LM, known scale) on all
  the window's wall points at once (zfloc_stream.estimation.correlative);
- camera (--camera): the same window as depth + labels frames (160x120, 90 deg, pitch
  +-8 deg, 1.3 m high, 1% depth noise) rendered by the simulator in the map of the WHOLE
  log extruded into walls (sim.build_scene_from_floorplan), odometry drifting 2% of the
  step per axis + 0.3 deg per step, localized at the default metric prior (odometry metric: localizer.odometry_scale) against the
  same held-out map; its reference searches the localizer's final BEV wall points (and
  places each frame by its plane pose as the BEV fused it);
- success (F3Loc): all of the last 10 frames within 1 m. A failure is attributed to "no
  pose" (a last-10 frame without pose), "lost" (final status lost) or "wrong mode";
- map coverage: the fraction of the window's laser hits, placed by their TRUE poses, that
  lie within COVERAGE_DISTANCE of a wall of the held-out map. A window whose map covers
  little of what it sees cannot be localized by any method (on belgioioso and orebro most
  windows cover < 0.5: those areas were walked only once); the last table splits the
  success rates by it (camera windows walk the same trajectory: the same coverage).

    python -m benchmarks.evaluation.eval_real                         # 5 logs x 5 lengths x 8 windows
    python -m benchmarks.evaluation.eval_real --logs intel --lengths 20,50 --windows 3 --workers 2
    python -m benchmarks.evaluation.eval_real --no-reference --set tracking.weight_gain=10
    python -m benchmarks.evaluation.eval_real --camera --windows 3           # camera rows too
    python -m benchmarks.evaluation.eval_real --drift-free --logs belgioioso,orebro   # what the maps allow
    python -m benchmarks.evaluation.eval_real --drift-free --plan-style --windows 2     # what the plans allow
    python -m benchmarks.evaluation.eval_real --plan-style --camera --windows 2   # against the maps drawn as plans
    python -m benchmarks.evaluation.eval_real --plan-style two-face                # plans with both faces of each wall
    python -m benchmarks.evaluation.eval_real --plan-style two-face-centred       # both faces 0.1 m about each seen wall
    python -m benchmarks.evaluation.eval_real --wrong-map --lengths 20,50 --windows 1   # every input on every OTHER building's map (wrong_map.py)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from functools import partial
from pathlib import Path

import numpy as np

from functools import lru_cache

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.io.datasets.carmen import carmen_sequence, load_log
from zfloc_stream.plans.map_from_log import log_odds_map, map_from_log
from zfloc_stream.sim import SimSettings, build_scene_from_floorplan, simulate
from zfloc_stream.sim.kidnap import spliced
from zfloc_stream.estimation.correlative import correlative_search
from zfloc_stream.estimate import STATUSES
from zfloc_stream.frames import FLOOR, WALL
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.prior import Prior
from zfloc_stream.metrics import is_success, position_errors
from zfloc_stream.plans.vector import load_vector_floorplan
from zfloc_stream.geometry.sim2 import Sim2

from benchmarks.shared_data import SHARED_DATA

DATA = SHARED_DATA / "carmen"
LOGS = ["intel", "aces", "belgioioso", "fhw", "orebro"]
LENGTHS = [15, 20, 35, 50, 100]
COVERAGE_DISTANCE = 0.3  # metres: estimator.correlative.tolerance, "near a wall"
COVERAGE_BINS = [(0.0, 0.4), (0.4, 0.7), (0.7, 1.01)]


def window_starts(n_scans: int, length: int, count: int) -> list[int]:
    return sorted({int(round(s)) for s in np.linspace(0, n_scans - length, count)})


def laser_points(frame) -> np.ndarray:
    """Wall hits of a LaserFrame in the odometry plane."""
    return _hits(frame, frame.T_odom_sensor)


CAMERA_RIG = ["localizer.odometry_scale=metric"]
CAMERA = SimSettings(camera_height=1.3, camera_height_jitter=0.0, max_pitch_deg=8.0, max_roll_deg=0.0, scale_error=0.0,
                     furniture_as_wall_prob=0.0, wall_dropout=0.0, odom_origin_range=50.0)


@lru_cache(maxsize=2)
def world_of(log: str):
    """The building a camera walks in: the map of the whole log, extruded into walls."""
    path = DATA / f"{log}-corrected.log.gz"
    settings = load_settings()
    return build_scene_from_floorplan(map_from_log(load_log(path, settings), [], settings), seed=0)


# --- harder conditions (issue 26): each option is applied by one function here ----------------
@dataclasses.dataclass(frozen=True)
class Conditions:
    """What a user's sensors bring beyond the default windows. drift multiplies the odometry
    drift (laser: datasets.odometry noise and floors; camera: the simulator's per-step
    translation and yaw noise). The rest are a monocular depth network's errors, applied to
    camera frames only: a global depth scale per window uniform in [1 - e, 1 + e]
    (depth_scale_error), a per-frame scale factor of std depth_scale_jitter, noise growing
    with range (std depth_noise * depth^2, depth in m), and mislabelled pixels at
    wall/floor borders (each pixel within 2 px of such a border takes the other label with
    probability label_noise)."""

    drift: float = 1.0
    depth_scale_error: float = 0.0
    depth_scale_jitter: float = 0.0
    depth_noise: float = 0.0
    label_noise: float = 0.0
    prior_sigma_xy: float = 0.0  # > 0: each window gets a pose prior (prior.py) at its true start pose...
    prior_sigma_deg: float = 0.0  # ...with these sigmas
    prior_offset: float = 0.0  # m, the prior's position this far from the truth (a wrong prior), in a seeded direction

    def monocular(self) -> bool:
        return any((self.depth_scale_error, self.depth_scale_jitter, self.depth_noise, self.label_noise))

    def describe(self) -> str:
        changed = [f"{f.name.replace('_', '-')} {getattr(self, f.name):g}" for f in dataclasses.fields(self)
                   if getattr(self, f.name) != f.default]
        return ", ".join(changed) or "default conditions"


def drift_overrides(drift: float) -> list[str]:
    """--set overrides that scale the laser windows' odometry drift (noise and both floors)."""
    if drift == 1.0:
        return []
    odo = load_settings().datasets.odometry
    return [f"datasets.odometry.noise={odo.noise * drift!r}",
            f"datasets.odometry.translation_floor={odo.translation_floor * drift!r}",
            f"datasets.odometry.heading_floor_deg={odo.heading_floor_deg * drift!r}"]


def camera_settings(conditions: "Conditions | None") -> SimSettings:
    """The simulated camera of the windows, its odometry drift scaled by conditions.drift."""
    drift = 1.0 if conditions is None else conditions.drift
    return CAMERA.model_copy(update={"odom_translation_noise": CAMERA.odom_translation_noise * drift,
                                     "odom_yaw_noise_deg": CAMERA.odom_yaw_noise_deg * drift})


def _border_band(labels: np.ndarray, width: int = 2) -> np.ndarray:
    """Wall or floor pixels within `width` px (4-neighbourhood steps) of a wall/floor border."""
    wall, floor = labels == WALL, labels == FLOOR
    near_wall, near_floor = wall.copy(), floor.copy()
    for _ in range(width):
        for grown in (near_wall, near_floor):
            g = grown.copy()
            g[1:] |= grown[:-1]
            g[:-1] |= grown[1:]
            g[:, 1:] |= grown[:, :-1]
            g[:, :-1] |= grown[:, 1:]
            grown[:] = g
    return (wall & near_floor) | (floor & near_wall)


def monocular_frames(frames, conditions: Conditions, seed: int, log: str, start: int) -> list:
    """Camera frames as a monocular depth + segmentation network would give them."""
    rng = make_rng(seed, "monocular", log, start)
    scale = 1.0 + rng.uniform(-conditions.depth_scale_error, conditions.depth_scale_error)
    out = []
    for f in frames:
        depth = f.depth.astype(np.float64)
        ok = np.isfinite(depth) & (depth > 0)
        factor = scale * (1.0 + rng.normal(0.0, conditions.depth_scale_jitter)) if conditions.depth_scale_jitter else scale
        noisy = depth * factor + rng.normal(0.0, 1.0, depth.shape) * conditions.depth_noise * depth**2
        depth = np.where(ok, np.maximum(noisy, 0.0), depth).astype(np.float32)
        labels = f.labels
        if conditions.label_noise and labels is not None:
            flip = _border_band(labels) & (rng.random(labels.shape) < conditions.label_noise)
            labels = labels.copy()
            labels[flip] = np.where(labels[flip] == WALL, FLOOR, WALL)
        out.append(dataclasses.replace(f, depth=depth, labels=labels))
    return out


def window_prior(frames, conditions: "Conditions | None", seed: int, start: int) -> Prior | None:
    """The pose prior of --prior / --prior-offset: at the window's true start pose, or
    prior_offset metres from it in a direction seeded by the window (heading kept)."""
    if conditions is None or conditions.prior_sigma_xy <= 0:
        return None
    x, y, yaw = np.asarray(frames[0].ground_truth, dtype=float)[:3]
    angle = make_rng(seed, "prior offset", start).uniform(0, 2 * np.pi)
    d = conditions.prior_offset
    return Prior.at(x + d * np.cos(angle), y + d * np.sin(angle), yaw, conditions.prior_sigma_xy,
                    np.radians(conditions.prior_sigma_deg))


def localize_frames(floorplan, frames, settings, prior: Prior | None = None) -> tuple[dict, Localizer]:
    """Push the frames through a fresh Localizer; success and where a failure came from.
    prior: given at construction (window_prior); the row then says where the prior's place
    was tracked (prior_*)."""
    truth = np.array([f.ground_truth for f in frames])
    t0 = time.perf_counter()
    localizer = Localizer(floorplan, settings, prior=prior)
    estimates, plane_poses = [], []
    for f in frames:
        estimates.append(localizer.push(f))
        plane_poses.append(localizer.bev.plane_pose(f))  # as fused (scan matching corrects the odometry)
    seconds = time.perf_counter() - t0
    localizer.close()  # stops an online / pipelined worker (its estimates are all in)
    localizer.plane_poses = plane_poses
    errors = position_errors([e.pose for e in estimates], truth)
    row = {"seconds": seconds, "success": is_success(errors, 1.0), "final_error": float(errors[-1]),
           "final_status": estimates[-1].status, **frame_record(estimates, errors),
           "first_pose_frame": next((i for i, e in enumerate(estimates) if e.pose is not None), None),
           "first_tracking_frame": next((i for i, e in enumerate(estimates) if e.status == "tracking"), None)}
    if prior is not None:
        near = [e.pose is not None and np.hypot(*(np.asarray(e.pose[:2]) - np.array(prior.pose[:2]))) < 2.5 * prior.sigma_xy
                for e in estimates]
        # tracking 1 m+ off the truth and near the prior's place: the prior obeyed against the frames
        row.update(prior_state=estimates[-1].prior,
                   prior_tracking_off=int(sum(e.status == "tracking" and n and not v < 1.0 for e, n, v in zip(estimates, near, errors))))
    if row["success"]:
        row["cause"] = ""
    elif not np.isfinite(errors[-10:]).all():
        row["cause"] = "no pose"
    elif estimates[-1].status == "lost":
        row["cause"] = "lost"
    else:
        row["cause"] = "wrong mode"
    return row, localizer


def frame_record(estimates, errors) -> dict:
    """Per-frame status, error and confidence of a window (for status_table)."""
    return {"frame_status": [e.status for e in estimates],
            "frame_errors": [float(v) if np.isfinite(v) else None for v in errors],
            "frame_confidence": [float(getattr(e, "confidence", float("nan"))) for e in estimates]}


def status_table(rows: list[dict]) -> str:
    """Per frame, over every window: how often each status is within 1 m, and the share of
    `tracking` frames 1 m or more off (what a caller acting on `tracking` meets)."""
    status, errors = [], []
    for r in rows:
        status += r.get("frame_status", [])
        errors += [np.inf if v is None else v for v in r.get("frame_errors", [])]
    status, errors = np.array(status), np.array(errors, dtype=float)
    lines = ["| status | frames | within 1 m | 1 m+ off | windows with a 1 m+ frame |", "|---|---|---|---|---|"]
    for name in STATUSES:
        mine = status == name
        bad_windows = sum(any(s == name and (v is None or v >= 1.0) for s, v in zip(r.get("frame_status", []), r.get("frame_errors", [])))
                          for r in rows)
        lines.append(f"| {name} | {int(mine.sum())} | {_pct(errors[mine] < 1.0, 1)} | {_pct(errors[mine] >= 1.0, 1)} | {bad_windows} |")
    return "\n".join(lines)


CONFIDENCE_LEVELS = (0.5, 0.9, 0.99)


def confidence_table(rows: list[dict]) -> str:
    """Per frame: how often a pose whose Estimate.confidence exceeds a level is within 1 m
    (what a caller thresholding the confidence instead of the status meets)."""
    conf, errors = [], []
    for r in rows:
        conf += [np.nan if v is None else v for v in r.get("frame_confidence", [])]
        errors += [np.inf if v is None else v for v in r.get("frame_errors", [])]
    conf, errors = np.array(conf, dtype=float), np.array(errors, dtype=float)
    lines = ["| confidence | frames | within 1 m |", "|---|---|---|"]
    for level in CONFIDENCE_LEVELS:
        mine = conf > level  # nan (no pose, or an older localizer) never exceeds a level
        lines.append(f"| > {level:g} | {int(mine.sum())} | {_pct(errors[mine] < 1.0, 1)} |")
    return "\n".join(lines)


def reference_row(floorplan, points, frames, yaw_of) -> dict:
    """The exact correlative search on all points at once, judged like the localizer."""
    t0 = time.perf_counter()
    best = correlative_search(floorplan, points)[0]
    poses = [np.array(best.alignment.apply_pose(f.T[0, 3], f.T[1, 3], yaw_of(f.T))) for f in frames]
    errors = position_errors(poses, np.array([f.truth for f in frames]))
    return {"ref_seconds": time.perf_counter() - t0, "ref_success": is_success(errors, 1.0), "ref_final_error": float(errors[-1])}


def _hits(frame, T: np.ndarray) -> np.ndarray:
    """Wall hits of a LaserFrame placed by the 4x4 sensor pose T."""
    ok = frame.valid
    a, r = frame.angles[ok], frame.ranges[ok]
    return np.column_stack([r * np.cos(a), r * np.sin(a)]) @ T[:2, :2].T + T[:2, 3]


def true_hits(laser_frames) -> np.ndarray:
    """The frames' wall hits placed by their true poses (floorplan frame)."""
    return np.concatenate([_hits(f, _plane_T(f.ground_truth)) for f in laser_frames])


def map_coverage(floorplan, points: np.ndarray) -> float:
    """Fraction of true_hits near a held-out map wall."""
    return float((floorplan.distance(points) < COVERAGE_DISTANCE).mean()) if len(points) else 0.0


def laser_window(log: str, start: int, length: int, overrides=(), seed: int = 0):
    """(settings, floorplan, frames) of a held-out laser window at fixed scale."""
    settings = load_settings(overrides=list(overrides), base_overrides={"estimator": {"scale_mode": "fixed"}})
    settings = settings.model_copy(update={"seed": seed})
    seq = carmen_sequence(DATA / f"{log}-corrected.log.gz", settings)
    return settings, seq.floorplan_for(start, start + length), list(seq.frames(start, start + length))


def drift_free_row(log: str, start: int, length: int, plan_style: str | None = None) -> dict:
    """The exact search with perfect relative motion: every hit of the window placed by its
    TRUE pose, then moved by a fixed rigid offset (so the grid is not aligned with the
    truth) and searched like the reference. What no odometry drift, i.e. the held-out
    map alone (plan_style: that map drawn as a plan, plan_of), allows."""
    settings, floorplan, frames = laser_window(log, start, length)
    if plan_style is not None:
        floorplan = plan_of(floorplan, settings, plan_style, log, start, start + length)
    placed = true_hits(frames)
    offset = Sim2(1.0, 1.234, np.array([13.0, -7.0]))
    found = correlative_search(floorplan, offset.apply(placed))[0].alignment @ offset  # the identity when right
    truth = np.array([f.ground_truth[:2] for f in frames])
    errors = np.linalg.norm(found.apply(truth) - truth, axis=1)
    return {"log": log, "start": start, "length": length, "success": is_success(errors, 1.0),
            "coverage": map_coverage(floorplan, placed), "plan_style": plan_style}


def _plane_T(pose) -> np.ndarray:
    """4x4 of a plane pose (x, y, yaw): the heading is the x axis."""
    x, y, yaw = pose
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:2, 3] = x, y
    return T


class _Posed:
    def __init__(self, T, truth):
        self.T, self.truth = T, truth


def run_window(log: str, start: int, length: int, seed: int, overrides: list[str], reference: bool, camera: bool = False,
               localize: bool = True, conditions: Conditions | None = None, plan_style: str | None = None) -> dict:
    """One window's row. localize=False: the laser reference alone (it does not depend on
    the localizer, so --reference-cache keeps it across runs). plan_style: localize (and
    search) against the held-out map redrawn as a plan (plan_window). conditions: the camera's
    drift and monocular errors (the laser's drift comes in as datasets.odometry overrides)."""
    path = DATA / f"{log}-corrected.log.gz"
    stop = start + length
    row = {"log": log, "start": start, "length": length, "seed": seed, "sensor": "camera" if camera else "laser"}
    if camera:
        # the simulated rig's odometry is metric (CAMERA.scale_error 0): only a monocular
        # condition's depth is off in scale (localizer.odometry_scale); --set can say otherwise
        settings = load_settings(overrides=[*CAMERA_RIG, *overrides]).model_copy(update={"seed": seed})
        seq = carmen_sequence(path, settings)
        floorplan = seq.floorplan_for(start, stop)
        truth = seq.ground_truth[start:stop]
        frames = simulate(world_of(log), camera_settings(conditions), seed=seed + start, trajectory=truth).frames
        if conditions is not None and conditions.monocular():
            frames = monocular_frames(frames, conditions, seed, log, start)
        if plan_style:
            row.update(plan_window(floorplan, frames, settings, true_hits(seq.frames(start, stop))))
            floorplan = plan_of(floorplan, settings, plan_style, log, start, stop)
        result, localizer = localize_frames(floorplan, frames, settings, window_prior(frames, conditions, seed, start))
        row.update(result, coverage=map_coverage(floorplan, true_hits(seq.frames(start, stop))))
        if reference:
            obs = localizer.last_observation
            # the BEV's frame: each frame's plane pose as the localizer fused it
            posed = [_Posed(_plane_T(p), f.ground_truth) for p, f in zip(localizer.plane_poses, frames)]
            if obs is None:
                row.update(ref_seconds=0.0, ref_success=False, ref_final_error=float("inf"))
            else:
                row.update(reference_row(floorplan, obs.wall_points, posed, lambda T: np.arctan2(T[1, 0], T[0, 0])))
        return row
    settings, floorplan, frames = laser_window(log, start, length, overrides, seed)
    if plan_style:
        row.update(plan_window(floorplan, frames, settings, true_hits(frames)))
        floorplan = plan_of(floorplan, settings, plan_style, log, start, stop)
    row["coverage"] = map_coverage(floorplan, true_hits(frames))
    if localize:
        result, _ = localize_frames(floorplan, frames, settings, window_prior(frames, conditions, seed, start))
        row.update(result)
    if reference:
        points = np.concatenate([laser_points(f) for f in frames])
        posed = [_Posed(f.T_odom_sensor, f.ground_truth) for f in frames]
        row.update(reference_row(floorplan, points, posed, lambda T: np.arctan2(T[1, 0], T[0, 0])))
    return row


# --- plan style: the held-out map redrawn as an architect's plan (issue 30) ---------------
# two-face: each wall as both faces, the one the sensor saw where the map shows it and the
# wall's body behind it; two-face-centred: both faces thickness/2 about the map's wall line,
# so every face toward a room lies 0.1 m inside the open space the sensor saw (a plan off by
# that much everywhere: the variant measured before 2026-12-04)
PLAN_STYLES = ("one-face", "two-face", "two-face-centred")
PLAN_WALL_THICKNESS = 0.2  # m, two-face plans: each wall drawn as its faces this far apart
PLAN_COVERAGE = 0.7  # windows whose plan covers at least this share of their hits


def plan_of(floorplan, settings, style: str, log: str, start: int, stop: int):
    """The held-out map of window [start, stop) of a log redrawn as a plan
    (benchmarks/evaluation/plan_drawing.py), written as a DXF in metres and loaded through the vector
    path, as a user's `run --floorplan plan.dxf`."""
    from benchmarks.evaluation.plan_drawing import draw_plan, two_faces, write_plan_dxf

    segments = draw_plan(floorplan)
    if style == "two-face":
        segments = two_faces(segments, PLAN_WALL_THICKNESS, heldout_free(log, start, stop, settings))
    elif style == "two-face-centred":
        segments = two_faces(segments, PLAN_WALL_THICKNESS)
    with tempfile.TemporaryDirectory() as tmp:
        return load_vector_floorplan(write_plan_dxf(segments, Path(tmp) / f"plan-{style}.dxf"), settings)


def heldout_free(log: str, start: int, stop: int, settings):
    """(free cells, origin, resolution) of the held-out map of a window: what the scans
    outside it saw open (mapping.log_odds_map, the grid carmen_sequence's map thresholds)."""
    margin = settings.datasets.carmen.heldout_margin
    logodds, origin, res = log_odds_map(load_log(DATA / f"{log}-corrected.log.gz", settings),
                                        [(start - margin, stop + margin)], settings)
    return logodds < 0, origin, res


def plan_window(raster, frames, settings, hits: np.ndarray) -> dict:
    """What a plan row is compared with: the same window localized against the raster
    (held-out) map it was drawn from, and that map's coverage."""
    result, _ = localize_frames(raster, frames, settings)
    return {"raster_success": result["success"], "raster_final_error": result["final_error"],
            "map_coverage": map_coverage(raster, hits)}


def plan_table(rows: list[dict], lengths: list[int], reference: bool) -> str:
    """Per sensor: SR on the plan (ours, the reference on the same plan rasterised) and on
    the raster map (ours, the same windows), by length; then split by plan coverage."""
    out = []
    for sensor in dict.fromkeys(r["sensor"] for r in rows):
        mine = [r for r in rows if r["sensor"] == sensor]
        by_len = {L: [r for r in mine if r["length"] == L] for L in lengths}
        lines = [f"### {sensor}, {mine[0]['plan_style']} plans\n", "| method | " + " | ".join(f"#{L}" for L in lengths) + " | all |",
                 "|---" * (len(lengths) + 2) + "|"]
        methods = [("zfloc-stream on the plan", "success")] + ([("exact search (batch) on the plan", "ref_success")] if reference else [])
        methods.append(("zfloc-stream on the raster map (same windows)", "raster_success"))
        for name, key in methods:
            lines.append(f"| {name} | {' | '.join(_pct([r[key] for r in by_len[L]]) for L in lengths)} | {_pct([r[key] for r in mine])} |")
        for name, key in methods:  # the bar is per length on the covered windows too
            cov = {L: [r[key] for r in by_len[L] if r["coverage"] >= PLAN_COVERAGE] for L in lengths}
            lines.append(f"| {name}, plan coverage >= {PLAN_COVERAGE} | {' | '.join(f'{sum(cov[L])}/{len(cov[L])}' for L in lengths)} | "
                         f"{_pct([v for L in lengths for v in cov[L]])} |")
        lines += ["", "| plan coverage | windows | on the plan | on the raster map |" + (" exact search on the plan |" if reference else ""),
                  "|---|---|---|---|" + ("---|" if reference else "")]
        for label, keep in ((f">= {PLAN_COVERAGE}", lambda c: c >= PLAN_COVERAGE), (f"< {PLAN_COVERAGE}", lambda c: c < PLAN_COVERAGE)):
            part = [r for r in mine if keep(r["coverage"])]
            cells = [_pct([r["success"] for r in part]), _pct([r["raster_success"] for r in part])]
            cells += [_pct([r["ref_success"] for r in part])] if reference else []
            lines.append(f"| {label} | {len(part)} | {' | '.join(cells)} |")
        if reference:
            lost = [r for r in mine if not r["success"]]
            lines.append(f"\nfailures on the plan: {len(lost)}, of which the reference fails too (the plan's): "
                         f"{sum(not r['ref_success'] for r in lost)}, the reference succeeds (ours): {sum(r['ref_success'] for r in lost)}")
        lines.append(f"median plan coverage {np.median([r['coverage'] for r in mine]):.2f}, map coverage {np.median([r['map_coverage'] for r in mine]):.2f}")
        out.append("\n".join(lines))
    return "\n\n".join(out)


def plan_style_main(args, jobs: list, lengths: list[int]) -> int:
    """--plan-style: every window against its held-out map drawn as a plan (no reference cache:
    the cached references are the raster map's)."""
    rows = _map(partial(run_window, plan_style=args.plan_style), jobs, args.workers)
    for r in rows:
        r["plan_style"] = args.plan_style
    print(plan_table(rows, lengths, not args.no_reference))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


def _pct(values, digits: int = 0) -> str:
    return f"{100 * np.mean(values):.{digits}f}%" if len(values) else "-"


def table(rows: list[dict], lengths: list[int], reference: bool) -> str:
    return "\n\n".join(f"### {sensor}\n\n" + sensor_table([r for r in rows if r["sensor"] == sensor], lengths, reference)
                       + "\n\nPer frame:\n\n" + status_table([r for r in rows if r["sensor"] == sensor])
                       + "\n\n" + confidence_table([r for r in rows if r["sensor"] == sensor])
                       for sensor in dict.fromkeys(r["sensor"] for r in rows))


def sensor_table(rows: list[dict], lengths: list[int], reference: bool) -> str:
    by_len = defaultdict(list)
    for r in rows:
        by_len[r["length"]].append(r)
    head = "| method | " + " | ".join(f"#{L}" for L in lengths) + " | all | median s/window |"
    lines = [head, "|---" * (len(lengths) + 3) + "|"]
    ours = [_pct([r["success"] for r in by_len[L]]) for L in lengths]
    lines.append(f"| zfloc-stream (online) | {' | '.join(ours)} | {_pct([r['success'] for r in rows])} | "
                 f"{np.median([r['seconds'] for r in rows]):.2f} |")
    firsts = [r.get("first_tracking_frame") for r in rows]
    tracked = [f for f in firsts if f is not None]
    summary = (f"first `tracking` frame: median {np.median(tracked):.0f}, mean {np.mean(tracked):.1f} over {len(tracked)} of "
               f"{len(rows)} windows" if tracked else f"no window reached `tracking` ({len(rows)} windows)")
    if any("prior_state" in r for r in rows):
        states = defaultdict(int)
        for r in rows:
            states[r.get("prior_state")] += 1
        summary += ("; prior at the end: " + ", ".join(f"{k} {v}" for k, v in sorted(states.items(), key=str))
                    + f"; `tracking` frames 1 m+ off near the prior's place: {sum(r.get('prior_tracking_off', 0) for r in rows)}"
                    + f" (windows: {sum(r.get('prior_tracking_off', 0) > 0 for r in rows)})")
    trailer = [summary]
    if reference:
        ref = [_pct([r["ref_success"] for r in by_len[L]]) for L in lengths]
        lines.append(f"| exact correlative search (batch) | {' | '.join(ref)} | {_pct([r['ref_success'] for r in rows])} | "
                     f"{np.median([r['ref_seconds'] for r in rows]):.2f} |")
    lines += ["", "| building | " + " | ".join(f"#{L}" for L in lengths) + " | windows | failures: no pose / lost / wrong mode |",
              "|---" * (len(lengths) + 3) + "|"]
    for log in dict.fromkeys(r["log"] for r in rows):
        mine = [r for r in rows if r["log"] == log]
        cells = [_pct([r["success"] for r in mine if r["length"] == L]) for L in lengths]
        causes = [sum(r["cause"] == c for r in mine) for c in ("no pose", "lost", "wrong mode")]
        lines.append(f"| {log} | {' | '.join(cells)} | {len(mine)} | {causes[0]} / {causes[1]} / {causes[2]} |")
    lines += ["", "| map coverage | windows | zfloc-stream |" + (" exact search (batch) |" if reference else ""),
              "|---|---|---|" + ("---|" if reference else "")]
    for lo, hi in COVERAGE_BINS:
        mine = [r for r in rows if lo <= r["coverage"] < hi]
        cells = [_pct([r["success"] for r in mine])] + ([_pct([r["ref_success"] for r in mine])] if reference else [])
        lines.append(f"| {lo:.1f}-{min(hi, 1.0):.1f} | {len(mine)} | {' | '.join(cells)} |")
    return "\n".join(lines + [""] + trailer)


def _cache_key(job) -> str:
    log, start, length, seed, overrides = job[:5]
    return f"{log}/{start}/{length}/{seed}/" + ",".join(o for o in overrides if o.startswith("datasets."))


def _read_cache(path: Path | None) -> dict:
    return json.loads(path.read_text()) if path is not None and path.exists() else {}


def _map(fn, jobs: list, workers: int) -> list:
    if workers > 1 and len(jobs) > 1:
        with ProcessPoolExecutor(workers) as pool:
            return list(pool.map(fn, *zip(*jobs)))
    return [fn(*job) for job in jobs]


# --- whole walks (issue 26): a log from its first scan to its last, online ---------------------
def kidnap_order(n: int, kidnap: bool) -> list[tuple[int, int]]:
    """The log's scan ranges in the order they are played. kidnap: thirds played first,
    last, middle, so the robot is carried twice between far-apart places while its
    odometry says it stood still."""
    if not kidnap:
        return [(0, n)]
    a, b = n // 3, 2 * n // 3
    return [(0, a), (b, n), (a, b)]


def walk_metrics(statuses: list[str], errors: np.ndarray, cuts: list[int]) -> dict:
    """After the first `tracking` frame: the share of frames within 1 m, the runs of frames
    1 m or more off (count, longest), and per kidnap the frames until the pose is
    `tracking` and within 1 m again (None: never)."""
    first = next((i for i, s in enumerate(statuses) if s == "tracking"), None)
    if first is None:
        return {"first_fix": None, "within_1m": 0.0, "off_runs": 0, "longest_off": len(errors), "recovery": [None] * len(cuts)}
    off = errors[first:] >= 1.0
    runs, current = [], 0
    for o in off:
        current = current + 1 if o else 0
        if o and current == 1:
            runs.append(0)
        if o:
            runs[-1] = current
    recovery = []
    for cut in cuts:
        back = next((k for k in range(cut, len(errors)) if statuses[k] == "tracking" and errors[k] < 1.0), None)
        recovery.append(None if back is None else back - cut)
    return {"first_fix": first, "within_1m": float(np.mean(~off)), "off_runs": len(runs), "longest_off": max(runs, default=0),
            "recovery": recovery}


def whole_log_row(log: str, seed: int, overrides: list[str], kidnap: bool) -> dict:
    """One shared laser log played whole (or spliced: kidnap_order) against the map of the
    whole log (the self-map: this measures continuity, not recognition), with drift."""
    path = DATA / f"{log}-corrected.log.gz"
    settings = load_settings(overrides=list(overrides), base_overrides={"estimator": {"scale_mode": "fixed"}})
    settings = settings.model_copy(update={"seed": seed})
    seq = carmen_sequence(path, settings)
    floorplan = map_from_log(load_log(path, settings), [], settings)
    order = kidnap_order(seq.n_frames, kidnap)
    frames, cuts = spliced([list(seq.frames(a, b)) for a, b in order])
    result, _ = localize_frames(floorplan, frames, settings)
    errors = np.array([np.inf if v is None else v for v in result["frame_errors"]])
    truth = np.array([f.ground_truth[:2] for f in frames])
    jumps = [float(np.linalg.norm(truth[c] - truth[c - 1])) for c in cuts]
    return {"log": log, "sensor": "laser", "frames": len(frames), "kidnap_m": jumps, "seconds": result["seconds"],
            "frame_status": result["frame_status"], "frame_errors": result["frame_errors"],
            **walk_metrics(result["frame_status"], errors, cuts)}


def whole_log_table(rows: list[dict]) -> str:
    lines = ["| log | frames | first fix | within 1 m after it | runs 1 m+ off (longest) | kidnaps: metres -> frames to recover | s |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        kid = ", ".join(f"{m:.0f} m -> {'never' if k is None else k}" for m, k in zip(r["kidnap_m"], r["recovery"])) or "-"
        lines.append(f"| {r['log']} | {r['frames']} | {r['first_fix']} | {100 * r['within_1m']:.1f}% | {r['off_runs']} ({r['longest_off']}) | "
                     f"{kid} | {r['seconds']:.0f} |")
    return "\n".join(lines) + "\n\nPer frame:\n\n" + status_table(rows)


def add_condition_options(parser: argparse.ArgumentParser) -> None:
    """The harder conditions of issue 26 (see Conditions)."""
    group = parser.add_argument_group("conditions (what real users bring)")
    group.add_argument("--drift", type=float, default=1.0, metavar="X",
                       help="odometry drift multiplier (3: 6%% of each step + 15 mm, 6%% of each turn + 0.9 deg on laser)")
    group.add_argument("--depth-scale-error", type=float, default=0.0, metavar="E",
                       help="camera: global depth scale per window uniform in [1-E, 1+E] (a monocular network's)")
    group.add_argument("--depth-scale-jitter", type=float, default=0.0, metavar="J",
                       help="camera: per-frame depth scale factor with std J")
    group.add_argument("--depth-noise", type=float, default=0.0, metavar="N",
                       help="camera: depth noise growing with range, std N * depth^2")
    group.add_argument("--label-noise", type=float, default=0.0, metavar="P",
                       help="camera: pixels within 2 px of a wall/floor border take the other label with probability P")
    group.add_argument("--prior", metavar="SIGMA_XY,SIGMA_DEG",
                       help="give each window a pose prior (Localizer(prior=...)) at its true start pose with these sigmas (m, deg)")
    group.add_argument("--prior-offset", type=float, default=0.0, metavar="M",
                       help="with --prior: the prior's position M metres off the truth (a wrong prior)")
    group.add_argument("--whole-log", action="store_true",
                       help="instead of windows: each laser log from its first scan to its last, against the map of the whole log")
    group.add_argument("--kidnap", action="store_true",
                       help="with --whole-log: play each log's thirds first, last, middle (two kidnaps), odometry standing still across the cuts")


def parse_conditions(parser: argparse.ArgumentParser, args) -> Conditions:
    values = {"drift": args.drift, "depth_scale_error": args.depth_scale_error, "depth_scale_jitter": args.depth_scale_jitter,
              "depth_noise": args.depth_noise, "label_noise": args.label_noise}
    bad = [k for k, v in values.items() if not np.isfinite(v) or v < 0]
    if bad or args.drift <= 0:
        parser.error(f"--{(bad or ['drift'])[0].replace('_', '-')} must be a finite number > 0 (drift) or >= 0 (the rest)")
    if args.depth_scale_error >= 1 or args.label_noise > 1:
        parser.error("--depth-scale-error must be < 1 and --label-noise at most 1")
    if args.prior is not None:
        try:
            sigma_xy, sigma_deg = (float(v) for v in args.prior.split(","))
        except ValueError:
            parser.error(f"--prior must be SIGMA_XY,SIGMA_DEG, got {args.prior!r}")
        if not (np.isfinite([sigma_xy, sigma_deg]).all() and sigma_xy > 0 and sigma_deg > 0):
            parser.error(f"--prior sigmas must be positive, got {args.prior!r}")
        values.update(prior_sigma_xy=sigma_xy, prior_sigma_deg=sigma_deg)
    if args.prior_offset and args.prior is None or not np.isfinite(args.prior_offset) or args.prior_offset < 0:
        parser.error("--prior-offset needs --prior and a distance >= 0")
    values["prior_offset"] = args.prior_offset
    conditions = Conditions(**values)
    if conditions.monocular() and not args.camera:
        parser.error("--depth-scale-error, --depth-scale-jitter, --depth-noise and --label-noise apply to camera windows: add --camera")
    return conditions


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--logs", default=",".join(LOGS))
    parser.add_argument("--lengths", default=",".join(map(str, LENGTHS)))
    parser.add_argument("--windows", type=int, default=8, help="windows per log and length")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-reference", action="store_true", help="skip the brute-force reference")
    parser.add_argument("--camera", action="store_true", help="also run the windows as rendered camera frames")
    parser.add_argument("--no-laser", action="store_true", help="skip the laser windows")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="settings override")
    parser.add_argument("--json", type=Path, help="write every window's row here")
    parser.add_argument("--reference-cache", type=Path,
                        help="laser reference rows read from / added to this JSON file (the reference does not depend on the localizer)")
    parser.add_argument("--reference-only", action="store_true", help="only fill --reference-cache, then stop")
    parser.add_argument("--drift-free", action="store_true",
                        help="only the exact search on the laser windows placed by their true poses (what the held-out maps, "
                             "or with --plan-style their plans, allow), then stop")
    parser.add_argument("--plan-style", nargs="?", const="one-face", choices=PLAN_STYLES,
                        help="localize against each held-out map redrawn as an architect's DXF plan (one line per wall, "
                             "two-face: both faces of each wall, the wall behind the face the sensor saw; two-face-centred: "
                             "faces 0.1 m either side of it), beside the raster map on the same windows")
    parser.add_argument("--wrong-map", action="store_true",
                        help="instead: every shared camera session and laser window against every other shared building's map (wrong_map.py)")
    add_condition_options(parser)
    args = parser.parse_args(argv)
    conditions = parse_conditions(parser, args)
    args.set = list(args.set) + drift_overrides(conditions.drift)
    if args.reference_only and args.reference_cache is None:
        parser.error("--reference-only needs --reference-cache")
    if args.plan_style and (args.reference_cache or args.no_laser and not args.camera):
        parser.error("--plan-style runs its own references (no --reference-cache) on laser and/or --camera windows")
    if args.drift_free and args.camera:
        parser.error("--drift-free searches the laser windows' hits: drop --camera")
    logs = [s for s in args.logs.split(",") if s]
    missing_logs = [log for log in logs if not (DATA / f"{log}-corrected.log.gz").exists()]
    if missing_logs:
        parser.error(f"no Carmen log for {', '.join(missing_logs)} in {DATA} (have: {', '.join(sorted(p.name.split('-')[0] for p in DATA.glob('*-corrected.log.gz'))) or 'none'})")
    try:
        lengths = [int(v) for v in args.lengths.split(",")]
    except ValueError:
        parser.error(f"--lengths must be comma-separated whole numbers, got {args.lengths!r}")
    if any(L < 1 for L in lengths):
        parser.error(f"--lengths must be positive, got {args.lengths!r}")
    jobs = []
    for log in logs:
        n = len(load_log(DATA / f"{log}-corrected.log.gz", load_settings()))
        for length in lengths:
            for start in window_starts(n, length, args.windows):
                for camera in [False] * (not args.no_laser) + [True] * args.camera:
                    jobs.append((log, start, length, args.seed, args.set, not args.no_reference, camera))
    t0 = time.perf_counter()
    if args.wrong_map:
        from benchmarks.evaluation import wrong_map

        runs = wrong_map.jobs([j[:3] for j in jobs if not j[6]], logs, args.camera, args.seed, args.set, DATA)
        rows = _map(wrong_map.run, [(r,) for r in runs], args.workers)
        print(wrong_map.table(rows))
        print(f"\n{len(rows)} runs in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        return 0
    if args.plan_style and not args.drift_free:
        status = plan_style_main(args, jobs, lengths)
        print(f"\n{len(jobs)} windows in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        return status
    if args.whole_log or args.kidnap:
        if args.camera or args.no_laser:
            parser.error("--whole-log / --kidnap play the laser logs: drop --camera / --no-laser")
        rows = _map(whole_log_row, [(log, args.seed, args.set, args.kidnap) for log in logs], args.workers)
        print(f"Conditions: {conditions.describe()}{', kidnapped' if args.kidnap else ''}\n")
        print(whole_log_table(rows))
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        return 0
    if args.drift_free:
        rows = _map(drift_free_row, [(*w, args.plan_style) for w in dict.fromkeys(j[:3] for j in jobs)], args.workers)
        print(f"| drift-free exact search{' on the ' + args.plan_style + ' plans' if args.plan_style else ''} | " + " | ".join(f"#{L}" for L in lengths) + " | all |\n" + "|---" * (len(lengths) + 2) + "|")
        for log in logs:
            mine = [r for r in rows if r["log"] == log]
            cells = [_pct([r["success"] for r in mine if r["length"] == L]) for L in lengths]
            print(f"| {log} | {' | '.join(cells)} | {_pct([r['success'] for r in mine])} |")
        print(f"| all | {' | '.join(_pct([r['success'] for r in rows if r['length'] == L]) for L in lengths)} | {_pct([r['success'] for r in rows])} |")
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        return 0
    cache = _read_cache(args.reference_cache)
    missing = [j for j in jobs if j[5] and not j[6] and _cache_key(j) not in cache] if args.reference_cache else []
    rows = _map(run_window, [(*j, False, conditions) for j in missing], args.workers)
    cache.update({_cache_key(j): {k: r[k] for k in r if k.startswith("ref_")} for j, r in zip(missing, rows)})
    if args.reference_cache and missing:
        args.reference_cache.write_text(json.dumps(cache, indent=1, sort_keys=True))
    if args.reference_only:
        print(f"{len(missing)} reference rows added to {args.reference_cache}", file=sys.stderr)
        return 0
    # cached laser references are not recomputed; camera references need the localizer's BEV
    jobs = [(*j[:5], j[5] and (j[6] or _cache_key(j) not in cache), j[6]) for j in jobs]
    rows = _map(run_window, [(*j, True, conditions) for j in jobs], args.workers)
    for j, r in zip(jobs, rows):
        if not r["sensor"] == "camera" and _cache_key(j) in cache:
            r.update(cache[_cache_key(j)])
    print(f"Conditions: {conditions.describe()}\n")
    print(table(rows, lengths, not args.no_reference))
    print(f"\n{len(rows)} windows in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
