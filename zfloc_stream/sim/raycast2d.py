"""A simulated planar range sensor on a floorplan's occupancy grid.

Every beam is traced exactly through the grid (all cell-boundary crossings of all beams at
once, no per-beam loop), so a range is the distance to where the beam enters the first
wall cell. Optional Gaussian range noise and uniform short outliers model a real scanner.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..plans.floorplan import Floorplan
from ..frames import LaserFrame


MAX_CROSSINGS_PER_CHUNK = 2_000_000  # memory bound of one traversal batch (not a tuning knob)


@dataclass(frozen=True)
class ScanResult:
    ranges: np.ndarray  # (n,) measured ranges (noise/outliers applied); inf where no hit
    angles: np.ndarray  # (n,) beam angles relative to the sensor heading (CCW, radians)
    hits: np.ndarray  # (n, 2) floorplan points where beams hit (NaN where no hit)
    hit_mask: np.ndarray  # (n,) bool: the beam hit a wall within max_range
    origin: np.ndarray  # (3,) sensor pose (x, y, theta) in the floorplan
    true_ranges: np.ndarray  # (n,) noise-free ranges; inf where no hit
    outlier_mask: np.ndarray  # (n,) bool: beams whose range was replaced by an outlier

    @property
    def hit_points(self) -> np.ndarray:
        """(k, 2) floorplan points of the beams that hit."""
        return self.hits[self.hit_mask]


def beam_angles(fov: float, n_beams: int) -> np.ndarray:
    """Evenly spaced beams centred on the heading; a full circle has no repeated beam."""
    if np.isclose(fov, 2 * np.pi):
        return -np.pi + 2 * np.pi * np.arange(n_beams) / n_beams
    if n_beams == 1:
        return np.zeros(1)
    return np.linspace(-fov / 2, fov / 2, n_beams)


def trace(floorplan: Floorplan, origin, directions: np.ndarray, max_range: float) -> np.ndarray:
    """Exact distance along each unit direction (k, 2) from origin (2,) to the entry into the
    first occupied cell; inf when none within max_range (or the beam leaves the grid)."""
    res = floorplan.resolution
    o = (np.asarray(origin, dtype=float) - floorplan.origin) / res  # grid units, cell = unit square
    limit = max_range / res
    k_max = int(np.ceil(limit)) + 1
    crossings = []
    for axis in (0, 1):
        d = directions[:, axis]
        step = np.sign(d)
        first = np.where(step > 0, np.floor(o[axis]) + 1.0, np.ceil(o[axis]) - 1.0)  # next boundary ahead
        bounds = first[:, None] + step[:, None] * np.arange(k_max)[None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (bounds - o[axis]) / d[:, None]
        t[~np.isfinite(t) | (t < 0)] = np.inf
        crossings.append(t)
    t = np.concatenate([np.zeros((len(directions), 1)), *crossings], axis=1)
    t = np.sort(np.minimum(t, limit), axis=1)
    start, end = t[:, :-1], t[:, 1:]
    mid = 0.5 * (start + end)
    px = o[0] + mid * directions[:, 0:1]
    py = o[1] + mid * directions[:, 1:2]
    col, row = np.floor(px).astype(np.int64), np.floor(py).astype(np.int64)
    h, w = floorplan.shape
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    occ = np.zeros_like(inside)
    occ[inside] = floorplan.occupied[row[inside], col[inside]]
    occ &= end > start  # ignore empty intervals (ties, the clipped tail)
    first_hit = np.argmax(occ, axis=1)
    hit = occ[np.arange(len(occ)), first_hit]
    return np.where(hit, start[np.arange(len(occ)), first_hit] * res, np.inf)


def cast_rays(
    floorplan: Floorplan,
    pose,
    fov: float,
    max_range: float,
    n_beams: int,
    rng: np.random.Generator | None = None,
    range_noise: float = 0.0,
    outlier_ratio: float = 0.0,
) -> ScanResult:
    """Scan from pose (x, y, theta) in the floorplan. range_noise: std (m) of additive
    Gaussian noise on hit ranges; outlier_ratio: probability that a hit beam instead reads
    a uniform range in (0, true range]. Beams that hit nothing read inf."""
    pose = np.asarray(pose, dtype=float).reshape(-1)
    if pose.shape != (3,) or not np.isfinite(pose).all():
        raise InputError(f"pose must be finite (x, y, theta), got {pose}")
    if not (np.isfinite(fov) and 0 < fov <= 2 * np.pi + 1e-9):
        raise InputError(f"fov must be in (0, 2*pi] radians, got {fov}")
    if not (np.isfinite(max_range) and max_range > 0):
        raise InputError(f"max_range must be positive and finite, got {max_range}")
    if int(n_beams) < 1:
        raise InputError(f"n_beams must be at least 1, got {n_beams}")
    if not (range_noise >= 0 and 0 <= outlier_ratio <= 1):
        raise InputError("need range_noise >= 0 and 0 <= outlier_ratio <= 1")
    if (range_noise > 0 or outlier_ratio > 0) and rng is None:
        raise InputError("a numpy Generator (rng) is required for range noise or outliers")
    angles = beam_angles(float(fov), int(n_beams))
    world = pose[2] + angles
    directions = np.stack([np.cos(world), np.sin(world)], axis=1)
    # Beams in chunks: a beam holds ~2 * max_range / resolution crossings, so this bounds
    # the temporaries on fine grids with long ranges.
    per_beam = 2 * (int(np.ceil(max_range / floorplan.resolution)) + 2)
    chunk = max(1, MAX_CROSSINGS_PER_CHUNK // per_beam)
    true = np.concatenate([trace(floorplan, pose[:2], directions[i : i + chunk], float(max_range)) for i in range(0, len(directions), chunk)])
    hit = np.isfinite(true)
    ranges = true.copy()
    outlier = np.zeros(len(ranges), dtype=bool)
    if range_noise > 0:
        ranges[hit] = np.maximum(ranges[hit] + rng.normal(0.0, range_noise, hit.sum()), 0.0)
    if outlier_ratio > 0:
        outlier = hit & (rng.random(len(ranges)) < outlier_ratio)
        # (0, true]: 1 - U with U in [0, 1) never reads exactly zero
        ranges[outlier] = true[outlier] * (1.0 - rng.random(outlier.sum()))
    hits = np.full((len(ranges), 2), np.nan)
    hits[hit] = pose[:2] + ranges[hit, None] * directions[hit]
    return ScanResult(ranges, angles, hits, hit, pose, true, outlier)


def _pose_matrix(x: float, y: float, theta: float) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(theta), np.sin(theta)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = (x, y)
    return T


def to_laser_frame(scan: ScanResult, odom_pose, timestamp: float, max_range: float, range_min: float = 0.0) -> LaserFrame:
    """The scan as a LaserFrame seen from odom_pose (x, y, theta) in the odometry frame (it
    may differ from the true pose); the true pose travels as ground_truth."""
    x, y, theta = (float(v) for v in np.asarray(odom_pose, dtype=float).reshape(3))
    angles = scan.angles
    increment = float(angles[1] - angles[0]) if len(angles) > 1 else 1.0
    return LaserFrame(
        ranges=scan.ranges.copy(),
        angle_min=float(angles[0]),
        angle_increment=increment,
        range_min=float(range_min),
        range_max=float(max_range),
        T_odom_sensor=_pose_matrix(x, y, theta),
        timestamp=float(timestamp),
        ground_truth=scan.origin.copy(),
    )


@dataclass(frozen=True)
class RangeSensor2D:
    """A planar scanner model: field of view, reach, beam count and noise."""

    fov: float = 2 * np.pi
    max_range: float = 10.0
    n_beams: int = 360
    range_noise: float = 0.0
    outlier_ratio: float = 0.0

    def scan(self, floorplan: Floorplan, pose, rng: np.random.Generator | None = None) -> ScanResult:
        return cast_rays(floorplan, pose, self.fov, self.max_range, self.n_beams, rng, self.range_noise, self.outlier_ratio)

    def frame(self, floorplan: Floorplan, pose, odom_pose, timestamp: float, rng: np.random.Generator | None = None) -> LaserFrame:
        return to_laser_frame(self.scan(floorplan, pose, rng), odom_pose, timestamp, self.max_range)
