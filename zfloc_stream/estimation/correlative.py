"""Exhaustive correlative search: the brute-force reference for a rigid (known-scale) fit.

Every rotation on a grid (angle_step_deg) and every translation on a grid (cell) is
scored by how many of the observed wall points land within `tolerance` of a floorplan
wall: a plain count of matched points, as correlative scan matching does. For each
rotation the count over all translations is one cross-correlation of the rasterised
points with the floorplan's "near a wall" mask (cv2.matchTemplate, FFT-based), so the
search is exact on its grid. The best distinct peaks are then refined with the
estimator's Levenberg-Marquardt (fixed scale) and re-counted at full resolution.

It is the yardstick of benchmarks/eval_real.py: what an offline, exhaustive search
reaches on the same points, against which the online RANSAC localizer is measured.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..config import RefineSettings
from ..errors import InputError
from ..sim2 import Sim2, wrap_angle
from .refine import refine_batch


@dataclass(frozen=True)
class CorrelativeMatch:
    alignment: Sim2  # odometry plane -> floorplan, scale fixed
    matched: int  # points within tolerance of a wall after refinement
    n_points: int  # points searched (after thinning)


def thin_to_grid(points: np.ndarray, cell: float) -> np.ndarray:
    """One point (the first) per occupied cell of a `cell`-sized grid, in input order."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) == 0:
        return points
    keys = np.floor(points / cell).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    return points[np.sort(first)]


def _near_wall_mask(floorplan, cell: float, tolerance: float, pad: int) -> tuple[np.ndarray, np.ndarray]:
    """float32 mask (1 near a wall) on a `cell` grid over the floorplan, padded by `pad`
    cells of zeros on every side; and the world position of its cell (0, 0) centre."""
    x0, y0, x1, y1 = floorplan.extent
    cols = int(np.ceil((x1 - x0) / cell))
    rows = int(np.ceil((y1 - y0) / cell))
    xs = x0 + (np.arange(cols) + 0.5) * cell
    ys = y0 + (np.arange(rows) + 0.5) * cell
    gx, gy = np.meshgrid(xs, ys)
    near = floorplan.distance(np.column_stack([gx.ravel(), gy.ravel()])).reshape(rows, cols) < tolerance
    mask = np.zeros((rows + 2 * pad, cols + 2 * pad), dtype=np.float32)
    mask[pad : pad + rows, pad : pad + cols] = near
    return mask, np.array([xs[0] - pad * cell, ys[0] - pad * cell])


def correlative_search(
    floorplan,
    points: np.ndarray,
    *,
    cell: float = 0.1,
    angle_step_deg: float = 2.0,
    tolerance: float = 0.15,
    peaks: int = 8,
    refine_settings: RefineSettings = RefineSettings(),
) -> list[CorrelativeMatch]:
    """Ranked distinct rigid alignments of `points` (odometry plane, metres) to the
    floorplan, best (most matched points) first."""
    pts = thin_to_grid(points, cell)
    if len(pts) < 3:
        raise InputError(f"correlative search needs at least 3 points, got {len(pts)}")
    centre = pts.mean(axis=0)
    local = pts - centre
    radius = float(np.linalg.norm(local, axis=1).max()) + cell
    pad = int(np.ceil(radius / cell)) + 2
    mask, mask_origin = _near_wall_mask(floorplan, cell, tolerance + 0.5 * cell, pad)
    side = 2 * pad - 2  # the template: a square of side cells around the points' centre
    candidates = []  # (count, theta, tx, ty)
    for theta in np.deg2rad(np.arange(0.0, 360.0, angle_step_deg)):
        c, s = np.cos(theta), np.sin(theta)
        rot = local @ np.array([[c, s], [-s, c]])  # R(theta) applied to each row
        ij = np.floor(rot / cell).astype(np.int64) + side // 2
        template = np.zeros((side, side), dtype=np.float32)
        np.add.at(template, (ij[:, 1], ij[:, 0]), 1.0)
        score = cv2.matchTemplate(mask, template, cv2.TM_CCORR)
        # keep this rotation's best few placements (distinct enough by a coarse grid)
        flat = np.argpartition(score.ravel(), -peaks)[-peaks:]
        for f in flat:
            i, j = divmod(int(f), score.shape[1])
            # template cell (side//2, side//2) holds the centre's cell: its corner maps to
            # mask cell (i + side//2, j + side//2), whose centre is mask_origin + (j, i) * cell
            corner = mask_origin + (np.array([j, i]) + side // 2 - 0.5) * cell
            t = corner - np.array([c * centre[0] - s * centre[1], s * centre[0] + c * centre[1]])
            candidates.append((float(score.ravel()[f]), float(wrap_angle(theta)), t[0], t[1]))
    candidates.sort(key=lambda row: (-row[0], row[1], row[2], row[3]))
    chosen: list[tuple] = []
    for row in candidates:  # greedy non-maximum suppression on (centre position, angle)
        p = _apply(row, centre)
        if all(np.hypot(*(p - _apply(k, centre))) > 1.0 or abs(wrap_angle(row[1] - k[1])) > np.deg2rad(10) for k in chosen):
            chosen.append(row)
        if len(chosen) >= peaks:
            break
    models = np.array([[tx, ty, th, 1.0] for _, th, tx, ty in chosen])
    refined = refine_batch(floorplan, points, models, refine_settings, "fixed")
    thinned = thin_to_grid(points, 0.5 * cell)
    matches = []
    for m in refined:
        alignment = Sim2(1.0, m[2], m[:2])
        matched = int((floorplan.distance(alignment.apply(thinned)) < tolerance).sum())
        matches.append(CorrelativeMatch(alignment, matched, len(thinned)))
    matches.sort(key=lambda m: -m.matched)
    return matches


def _apply(row, centre: np.ndarray) -> np.ndarray:
    _, theta, tx, ty = row
    c, s = np.cos(theta), np.sin(theta)
    return np.array([c * centre[0] - s * centre[1] + tx, s * centre[0] + c * centre[1] + ty])
