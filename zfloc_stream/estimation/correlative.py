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

import weakref
from dataclasses import dataclass

import numpy as np
import scipy.fft as sfft

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


_MASKS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _near_wall_mask(floorplan, cell: float, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """float32 mask (1 within `tolerance` of a wall) on a `cell` grid over the floorplan and
    the world position of its cell (0, 0) centre; cached per floorplan object."""
    key = (float(cell), float(tolerance))
    try:
        cached = _MASKS.setdefault(floorplan, {})
    except TypeError:  # not weak-referenceable: no caching
        cached = {}
    if key not in cached:
        x0, y0, x1, y1 = floorplan.extent
        cols = int(np.ceil((x1 - x0) / cell))
        rows = int(np.ceil((y1 - y0) / cell))
        xs = x0 + (np.arange(cols) + 0.5) * cell
        ys = y0 + (np.arange(rows) + 0.5) * cell
        gx, gy = np.meshgrid(xs, ys)
        near = floorplan.distance(np.column_stack([gx.ravel(), gy.ravel()])).reshape(rows, cols) < tolerance
        cached[key] = (near.astype(np.float32), np.array([xs[0], ys[0]]))
    return cached[key]


@dataclass(frozen=True)
class _Spectrum:
    values: np.ndarray  # rfft2 of the padded mask
    fft_shape: tuple[int, int]


def _mask_spectrum(floorplan, cell: float, tolerance: float, half: int):
    """The near-wall mask padded by at least `half` zero cells (rounded up to 16 so calls
    share it), its FFT (cached per floorplan), the padded shape and the world centre of
    the padded cell (0, 0)."""
    near, origin = _near_wall_mask(floorplan, cell, tolerance)
    pad = 16 * int(np.ceil(half / 16))
    key = ("spectrum", float(cell), float(tolerance), pad)
    try:
        cached = _MASKS.setdefault(floorplan, {})
    except TypeError:
        cached = {}
    if key not in cached:
        mask = np.pad(near, pad)
        fft_shape = (sfft.next_fast_len(mask.shape[0], real=True), sfft.next_fast_len(mask.shape[1], real=True))
        cached[key] = (_Spectrum(sfft.rfft2(mask, s=fft_shape), fft_shape), mask.shape)
    spectrum, shape = cached[key]
    return spectrum, shape, origin - pad * cell


def correlative_models(
    floorplan,
    points: np.ndarray,
    scale: float = 1.0,
    *,
    cell: float = 0.1,
    angle_step_deg: float = 2.0,
    tolerance: float = 0.15,
    peaks: int = 8,
) -> np.ndarray:
    """(K <= peaks, 4) models (tx, ty, theta, s = scale), best grid count first, pairwise
    distinct (1 m at the points' centre, or 10 deg)."""
    pts = thin_to_grid(np.asarray(points, dtype=float).reshape(-1, 2) * scale, cell)
    if len(pts) < 3:
        return np.zeros((0, 4))
    centre = pts.mean(axis=0)
    local = pts - centre
    radius = float(np.linalg.norm(local, axis=1).max()) + cell
    half = int(np.ceil(radius / cell)) + 1
    side = 2 * half  # the template: a square of side cells around the points' centre
    spectrum, shape, mask_origin = _mask_spectrum(floorplan, cell, tolerance + 0.5 * cell, half)
    n_i, n_j = shape[0] - side + 1, shape[1] - side + 1  # placements with the template inside the mask
    per_angle = max(1, peaks)
    counts, thetas, corners = [], [], []
    for theta in np.deg2rad(np.arange(0.0, 360.0, angle_step_deg)):
        c, s = np.cos(theta), np.sin(theta)
        rot = local @ np.array([[c, s], [-s, c]])  # R(theta) applied to each row
        ij = np.floor(rot / cell).astype(np.int64) + half
        template = np.zeros(spectrum.fft_shape, dtype=np.float32)
        np.add.at(template, (ij[:, 1], ij[:, 0]), 1.0)
        # correlation = IFFT(FFT(mask) * conj(FFT(template))); the mask's FFT is cached
        score = sfft.irfft2(spectrum.values * np.conj(sfft.rfft2(template)), s=spectrum.fft_shape)[:n_i, :n_j]
        score = np.round(score).ravel()  # integer counts: FFT round-off never decides a tie
        best = np.argpartition(score, -per_angle)[-per_angle:] if len(score) > per_angle else np.arange(len(score))
        i, j = np.divmod(best, n_j)
        counts.append(score[best])
        thetas.append(np.full(len(best), theta))
        # template cell (half, half) holds the points' centre at its corner; placed at
        # (i, j) that corner lies at mask cell (i + half, j + half)'s corner
        corners.append(mask_origin + (np.column_stack([j, i]) + half - 0.5) * cell)
    counts, thetas, corners = np.concatenate(counts), np.concatenate(thetas), np.concatenate(corners)
    c, s = np.cos(thetas), np.sin(thetas)
    t = corners - np.column_stack([c * centre[0] - s * centre[1], s * centre[0] + c * centre[1]])
    order = np.lexsort((t[:, 1], t[:, 0], thetas, -np.round(counts)))  # stable, CPU-independent ties
    chosen: list[int] = []
    for k in order:  # greedy non-maximum suppression on the centre's image and the angle
        far = all(
            np.hypot(*(corners[k] - corners[q])) > 1.0 or abs(wrap_angle(thetas[k] - thetas[q])) > np.deg2rad(10) for q in chosen
        )
        if far:
            chosen.append(int(k))
            if len(chosen) >= peaks:
                break
    chosen = np.array(chosen, dtype=np.int64)
    return np.column_stack([t[chosen], wrap_angle(thetas[chosen]), np.full(len(chosen), float(scale))])


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
    floorplan, best (most matched points after LM refinement) first."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(thin_to_grid(points, cell)) < 3:
        raise InputError(f"correlative search needs at least 3 points, got {len(points)}")
    models = correlative_models(floorplan, points, cell=cell, angle_step_deg=angle_step_deg, tolerance=tolerance, peaks=peaks)
    refined = refine_batch(floorplan, points, models, refine_settings, "fixed")
    thinned = thin_to_grid(points, 0.5 * cell)
    matches = []
    for m in refined:
        alignment = Sim2(1.0, m[2], m[:2])
        matched = int((floorplan.distance(alignment.apply(thinned)) < tolerance).sum())
        matches.append(CorrelativeMatch(alignment, matched, len(thinned)))
    matches.sort(key=lambda m: -m.matched)
    return matches
