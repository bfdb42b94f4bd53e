"""Kidnaps inside the repetitive building (scene 'offices'): a walk along its
corridor and back, and where to carry the sensor off so that it lands whole offices
further along, at a place that looks like the one it left.

`corridor_kidnaps` gives the true walk and the cuts; the caller simulates the walk (camera
or laser) and plays the frames spliced at the cuts with the odometry standing still across
each (benchmarks/evaluation/eval_scenes.py --kidnap, tests/test_localizer.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import InputError
from ..runtime.rng import make_rng
from .scenes import Scene
from .trajectory import trajectory_through

def spliced(segments: list[list]) -> tuple[list, list[int]]:
    """Frames (camera or laser) of consecutive segments, each later segment's odometry
    re-anchored so that its first pose equals the previous segment's last (a kidnap: no
    odometry motion across the cut). Returns the frames and the index of each cut."""
    frames, cuts = list(segments[0]), []
    key = "T_odom_sensor" if hasattr(frames[0], "T_odom_sensor") else "T_odom_cam"
    for segment in segments[1:]:
        anchor = getattr(frames[-1], key) @ np.linalg.inv(getattr(segment[0], key))
        cuts.append(len(frames))
        frames += [replace(f, **{key: anchor @ getattr(f, key)}) for f in segment]
    return frames, cuts


def played(frames: list, poses: np.ndarray, cuts: list[tuple[int, int]]) -> tuple[list, np.ndarray, list[int]]:
    """The frames of a walk played with the cuts of corridor_kidnaps (frames k..j-1 of each
    (k, j) skipped, the odometry standing still across): (frames, their true poses, the
    index of each cut in them)."""
    bounds = [0] + [i for cut in cuts for i in cut] + [len(frames)]
    pairs = list(zip(bounds[::2], bounds[1::2]))
    out, at = spliced([frames[a:b] for a, b in pairs])
    return out, np.concatenate([poses[a:b] for a, b in pairs]), at


MIN_BEFORE = 25  # frames before the first cut (the first fix comes first)
MIN_AFTER = 40  # frames after each landing before the next cut or the end (recovery is judged over 30)


def _in_corridor(scene: Scene, xy: np.ndarray) -> np.ndarray:
    x0, y0, x1, y1 = scene.info["corridor"]
    return (xy[:, 0] > x0 + 0.5) & (xy[:, 0] < x1 - 0.5) & (xy[:, 1] > y0) & (xy[:, 1] < y1)


def _cut(poses: np.ndarray, legal: np.ndarray, lo: int, hi: int, direction: int, distances, rng,
         after: int) -> tuple[int, int, float] | None:
    """A random (k, j): frame k - 1 walking `direction` (+1 east, -1 west) along the
    corridor, frame j > k the frame of the same leg [lo, hi) nearest to `distance` further
    along, with at least `after` frames from j to hi. None when no such pair exists."""
    for distance in distances:
        pairs = []
        for k in range(max(lo, 1), hi):
            if not legal[k - 1]:
                continue
            target = poses[k - 1, 0] + direction * distance
            later = np.arange(k, hi - after)
            later = later[legal[later]]
            if len(later) == 0:
                continue
            j = int(later[np.argmin(np.abs(poses[later, 0] - target))])
            if abs(poses[j, 0] - target) < 0.3:
                pairs.append((k, j))
        if pairs:
            k, j = pairs[int(rng.integers(len(pairs)))]
            return k, j, float(distance)
    return None


def corridor_kidnaps(scene: Scene, seed: int, count: int = 2, min_m: float = 10.0,
                     max_m: float = 20.0) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """The true walk (N, 3) of the 'offices' scene: stairs, an office near the west end,
    the corridor east, the kitchen, an office near the east end, the corridor west, an
    office near the west end, the stairs; and up to `count` cuts (k, j): frames k..j-1 are
    skipped, the sensor carried from frame k - 1's place to frame j's, whole offices
    (min_m..max_m m) further along the corridor in its walking direction (east on the way
    there, west on the way back). Deterministic from the seed."""
    if "period" not in scene.info or "corridor" not in scene.info:
        raise InputError(f"corridor kidnaps need the 'offices' scene, not '{scene.name}'")
    rng = make_rng(seed, "sim", "corridor_kidnaps")
    n, period = scene.info["n_offices"], scene.info["period"]
    wp = scene.waypoints
    a, b, c = int(rng.integers(0, 2)), int(rng.integers(n - 2, n)), int(rng.integers(0, 2))
    side = ["south", "north"]
    sa, sb, sc = (side[int(rng.integers(2))] for _ in range(3))
    legs = [[wp["stairs"], wp[f"{sa}{a}_door"], wp[f"{sa}{a}"], wp[f"{sa}{a}_door"], wp["east_end"]],
            [wp["east_end"], wp["kitchen"], wp[f"{sb}{b}_door"], wp[f"{sb}{b}"], wp[f"{sb}{b}_door"], wp["west_end"]],
            [wp["west_end"], wp[f"{sc}{c}_door"], wp[f"{sc}{c}"], wp[f"{sc}{c}_door"], wp["stairs"]]]
    parts = [trajectory_through(scene, leg, rng) for leg in legs]
    poses = np.concatenate([parts[0], parts[1][1:], parts[2][1:]])
    east_end = len(parts[0])  # the eastward corridor walk ends here
    # the westward corridor walk starts once the office near the east end is left
    office = np.linalg.norm(parts[1][:, :2] - np.asarray(wp[f"{sb}{b}"]), axis=1)
    west_from = east_end - 1 + int(np.argmin(office))
    legal = _in_corridor(scene, poses[:, :2])
    # kidnaps land a whole number of offices along (the same place in another office)
    distances = [m * period for m in range(int(np.ceil(min_m / period)), int(max_m // period) + 1)]
    rng.shuffle(distances)
    cuts = []
    first = _cut(poses, legal, MIN_BEFORE, east_end, +1, distances, rng, 0)
    if first is not None:
        cuts.append(first[:2])
    if count > 1:
        lo = max(west_from, cuts[-1][1] + MIN_AFTER if cuts else 0)
        second = _cut(poses, legal, lo, len(poses), -1, distances, rng, MIN_AFTER)
        if second is not None:
            cuts.append(second[:2])
    return poses, cuts[:count]
