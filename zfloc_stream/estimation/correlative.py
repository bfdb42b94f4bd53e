"""Exhaustive correlative search: every rotation and translation of a grid, for a fit at known scale.

Every rotation on a grid (angle_step_deg; `plausible_angles` may mask the ones whose wall
directions cannot agree) and every translation on a grid (cell) is scored by how many of
the observed wall points land within `tolerance` of a floorplan wall: a plain count of
matched points, as correlative scan matching does. For each rotation the count over all
translations is one cross-correlation of the rasterised points with the floorplan's "near
a wall" mask, computed with FFTs (scipy.fft, not an image-matching library; the mask's
transform cached per floorplan here, the per-angle work in angle_search.py): a float32
pass whose counts must round to their integers, else the float64 pass, so the search is
exact on its grid. correlative_models returns the best distinct peaks; correlative_search
then refines them with the LM of field_fit.py (fixed scale) and re-counts the matched
points (thinned to half a cell) at the refined alignment.

Two users: the estimator seeds its global rounds at fixed or prior scale with
correlative_models (estimation/model_generation.py, estimator.correlative), and
benchmarks/evaluation/eval_real.py measures the online localizer against correlative_search, what an
offline, exhaustive search reaches on the same points. The plain search the fast one must
equal bit for bit (one float64 FFT per angle) is tests/correlative_reference.py.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..settings.loading import RefineSettings
from ..errors import InputError
from ..geometry.shapes import LineSet
from ..geometry.sim2 import Sim2, wrap_angle
from .angle_search import build_mask_spectrum, search_angles
from .field_fit import refine_batch
from .plan_cache import cached_per_floorplan

# Rotations whose line-direction agreement with the floorplan (length-weighted direction
# histograms, plausible_angles) is below this fraction of the best rotation's are not
# searched: on a building whose walls run in two directions most of the angle grid cannot
# put a wall on a wall. Low enough that the true rotation's agreement, cut by clutter and
# a partial view, stays above it (was estimator.correlative.direction_ratio; every recorded
# result used 0.3: the replay samples, eval_real, the benchmark scenes).
DIRECTION_RATIO = 0.3


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


def _near_wall_mask(floorplan, cell: float, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """float32 mask (1 within `tolerance` of a wall) on a `cell` grid over the floorplan and
    the world position of its cell (0, 0) centre; cached per floorplan object."""
    return cached_per_floorplan(floorplan, ("near-wall mask", float(cell), float(tolerance)), None,
                                lambda: _build_near_wall_mask(floorplan, cell, tolerance))


def _build_near_wall_mask(floorplan, cell: float, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    x0, y0, x1, y1 = floorplan.extent
    cols = int(np.ceil((x1 - x0) / cell))
    rows = int(np.ceil((y1 - y0) / cell))
    xs = x0 + (np.arange(cols) + 0.5) * cell
    ys = y0 + (np.arange(rows) + 0.5) * cell
    gx, gy = np.meshgrid(xs, ys)
    near = floorplan.distance(np.column_stack([gx.ravel(), gy.ravel()])).reshape(rows, cols) < tolerance
    return near.astype(np.float32), np.array([xs[0], ys[0]])


def _mask_spectrum(floorplan, cell: float, tolerance: float, half: int):
    """The near-wall mask padded by at least `half` zero cells (rounded up to 16 so calls
    share it), its FFT (cached per floorplan), the padded shape and the world centre of
    the padded cell (0, 0)."""
    near, origin = _near_wall_mask(floorplan, cell, tolerance)
    pad = FFT_PAD_MULTIPLE * int(np.ceil(half / FFT_PAD_MULTIPLE))
    spectrum, shape = cached_per_floorplan(floorplan, ("mask spectrum", float(cell), float(tolerance), pad), None,
                                           lambda: build_mask_spectrum(near, pad))
    return spectrum, shape, origin - pad * cell


# The floorplan mask is padded by the search's half-width rounded up to a multiple of this
# many cells: nearby half-widths share one cached spectrum and the FFT sizes stay smooth.
FFT_PAD_MULTIPLE = 16


def _direction_histogram(lines: LineSet) -> np.ndarray:
    """Length-weighted histogram of the lines' directions modulo 180 degrees, 1-degree bins,
    each line shared linearly between its two nearest bins: a wall at 90 degrees must not
    jump between bins 89 and 90 with the last bit of arctan2 (SIMD kernels differ by CPU)."""
    ends = np.asarray(lines.endpoints, dtype=float).reshape(-1, 2, 2)
    d = ends[:, 1] - ends[:, 0]
    degrees = np.rad2deg(np.arctan2(d[:, 1], d[:, 0])) % 180.0
    length = np.hypot(d[:, 0], d[:, 1])
    low = np.floor(degrees)
    upper = degrees - low
    low = low.astype(np.int64) % 180
    return (np.bincount(low, weights=length * (1.0 - upper), minlength=180)
            + np.bincount((low + 1) % 180, weights=length * upper, minlength=180))


def plausible_angles(bev_lines: LineSet, floorplan_lines: LineSet, angle_step_deg: float, ratio: float) -> np.ndarray | None:
    """Which rotations of the angle grid (np.arange(0, 360, angle_step_deg)) can turn the
    BEV's walls onto the floorplan's: a rotation turns every direction by the same angle,
    so the length-weighted agreement of the two direction histograms under a rotation
    (a circular correlation, modulo 180 degrees) is high at the true one. Kept: the grid
    angles within one step of a rotation whose agreement is at least `ratio` of the
    best's (a 180-degree turn agrees exactly as well, so both of a pair are kept). None
    (search every angle) when ratio is 0 or either side has no lines."""
    if ratio <= 0 or len(bev_lines.endpoints) == 0 or len(floorplan_lines.endpoints) == 0:
        return None
    bev, fp = _direction_histogram(bev_lines), _direction_histogram(floorplan_lines)
    # agreement[delta] = sum_b bev[b] * fp[b + delta]: BEV direction b lands on b + delta
    agreement = np.real(np.fft.ifft(np.conj(np.fft.fft(bev)) * np.fft.fft(fp)))
    if not agreement.max() > 0:
        return None
    wanted = agreement >= ratio * agreement.max()
    grid = np.arange(0.0, 360.0, angle_step_deg)
    # grid angle theta is kept when a wanted integer rotation lies within one step of it
    # (half a step for the truth between two grid angles, the 1-degree bins, line noise)
    offsets = np.arange(-np.ceil(angle_step_deg) - 1, np.ceil(angle_step_deg) + 2)
    near = np.floor(grid[:, None] + offsets[None, :]).astype(np.int64)
    close = np.abs(near - grid[:, None]) <= angle_step_deg + 1.0
    return (wanted[near % 180] & close).any(axis=1)


class SearchFrame(NamedTuple):
    """The points and the floorplan mask of one correlative search: the points (thinned,
    scaled) about their centre, the template's half side in cells, the mask's spectrum and
    origin, and the number of placements with the template inside the mask (n_i x n_j)."""

    centre: np.ndarray
    local: np.ndarray
    half: int
    spectrum: np.ndarray
    mask_origin: np.ndarray
    n_i: int
    n_j: int


def search_frame(floorplan, points: np.ndarray, scale: float, cell: float, tolerance: float) -> SearchFrame | None:
    """What every angle of a search shares (SearchFrame); None for fewer than 3 points
    after thinning to the grid."""
    pts = thin_to_grid(np.asarray(points, dtype=float).reshape(-1, 2) * scale, cell)
    if len(pts) < 3:
        return None
    centre = pts.mean(axis=0)
    local = pts - centre
    radius = float(np.linalg.norm(local, axis=1).max()) + cell
    half = int(np.ceil(radius / cell)) + 1
    side = 2 * half  # the template: a square of side cells around the points' centre
    spectrum, shape, mask_origin = _mask_spectrum(floorplan, cell, tolerance + 0.5 * cell, half)
    # placements with the template inside the mask
    return SearchFrame(centre, local, half, spectrum, mask_origin, shape[0] - side + 1, shape[1] - side + 1)


def correlative_models(
    floorplan,
    points: np.ndarray,
    scale: float = 1.0,
    *,
    cell: float = 0.1,
    angle_step_deg: float = 2.0,
    tolerance: float = 0.15,
    peaks: int = 8,
    angles: np.ndarray | None = None,
    distinct_distance: float = 1.0,
    distinct_angle_deg: float = 10.0,
) -> np.ndarray:
    """(K <= peaks, 4) models (tx, ty, theta, s = scale), best grid count first, pairwise
    distinct (farther than distinct_distance metres apart at the points' centre, or more
    than distinct_angle_deg apart: estimator.correlative's).

    angles: a boolean mask over the angle grid (plausible_angles); the others are not
    searched (None: all).

    Each angle's per_angle best placements (the highest float64 counts, ties spread evenly
    in placement order, as tests/correlative_reference.py) come from a float32 FFT instead,
    whose counts are checked to round to the same integers (search_angles: compiled
    rasterisation, spectrum products and peak picking around scipy's transforms). With
    every angle searched the result is the reference's, bit for bit (tested); the angles run on the
    round's threads (threads.py), each writing its own slot."""
    frame = search_frame(floorplan, points, scale, cell, tolerance)
    if frame is None:
        return np.zeros((0, 4))
    centre, local, half, spectrum, mask_origin, n_i, n_j = frame
    per_angle = max(1, peaks)
    thetas_grid = np.deg2rad(np.arange(0.0, 360.0, angle_step_deg))
    n_angles = len(thetas_grid)
    searched = np.ones(n_angles, dtype=bool) if angles is None else np.asarray(angles, dtype=bool).reshape(n_angles)
    # angle a + half_turn is angle a turned by 180 degrees (searched as a pair)
    half_turn = n_angles // 2 if n_angles % 2 == 0 and np.isclose(thetas_grid[n_angles // 2], np.pi) else 0
    found = search_angles(spectrum, local, thetas_grid, searched, half_turn, cell, half, n_i, n_j, per_angle)
    (t, thetas), _ = _select(found, thetas_grid, centre, mask_origin, half, cell, n_j, peaks, distinct_distance, distinct_angle_deg)
    return np.column_stack([t, wrap_angle(thetas), np.full(len(thetas), float(scale))])


def _select(found, thetas_grid, centre, mask_origin, half, cell, n_j, peaks, distinct_distance, distinct_angle_deg):
    """Greedy non-maximum suppression over every angle's peaks (best count first; ties
    by angle, then position, CPU-independent): (translations, angles) of the chosen ones
    and the count of the last one chosen."""
    counts = np.concatenate([c for _, c in found]).astype(np.float64)
    thetas = np.concatenate([np.full(len(b), th) for (b, _), th in zip(found, thetas_grid)])
    i, j = np.divmod(np.concatenate([b for b, _ in found]).astype(np.int64), n_j)
    # template cell (half, half) holds the points' centre at its corner; placed at
    # (i, j) that corner lies at mask cell (i + half, j + half)'s corner
    corners = mask_origin + (np.column_stack([j, i]) + half - 0.5) * cell
    c, s = np.cos(thetas), np.sin(thetas)
    t = corners - np.column_stack([c * centre[0] - s * centre[1], s * centre[0] + c * centre[1]])
    order = np.lexsort((t[:, 1], t[:, 0], thetas, -np.round(counts)))  # stable, CPU-independent ties
    chosen: list[int] = []
    for k in order:  # greedy non-maximum suppression on the centre's image and the angle
        far = all(
            np.hypot(*(corners[k] - corners[q])) > distinct_distance or abs(wrap_angle(thetas[k] - thetas[q])) > np.deg2rad(distinct_angle_deg)
            for q in chosen
        )
        if far:
            chosen.append(int(k))
            if len(chosen) >= peaks:
                break
    chosen = np.array(chosen, dtype=np.int64)
    last = float(counts[chosen[-1]]) if len(chosen) else -np.inf
    return (t[chosen], thetas[chosen]), last


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


