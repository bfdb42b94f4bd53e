"""The candidate correspondences of the hybrid RANSAC (ransac.py, paper 3.2): floorplan
tuples built once per floorplan and settings (lines and their spatial neighbours, pairs,
triplets binned by relative normal angle, line-circle and circle pairs) and a round's BEV
samples (the same structures on the BEV's primitives), with the pruning of ransac.py's
(i)-(iii)."""

from __future__ import annotations

import warnings

import numpy as np
from typing import Sequence

from ..settings.loading import FloorplanSettings, LineSettings, Settings, SolverSettings
from ..geometry.shapes import CircleSet, LineSet
from ..observation import BevObservation
from ..primitives.extract import deduplicate_lines
from .draws import admissible_triplets
from .plan_cache import cached_per_floorplan
from .solvers.models import MIN_BASELINE, NORMAL_CONSISTENCY, PARALLEL_ANGLE_DEG, normal_angle


def normal_angles(lines: LineSet) -> np.ndarray:
    """Line orientation as the angle of its normal modulo pi (a line has no direction)."""
    return np.mod(np.arctan2(lines.normals[:, 1], lines.normals[:, 0]), np.pi)


def _parallel_mod_pi(a: np.ndarray, b: np.ndarray, max_angle: float) -> np.ndarray:
    return np.abs(np.sin(a - b)) < np.sin(max_angle)


def _point_segment_distance(p: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(P, S) distance from points (P, 2) to segments (S, 2, 2)."""
    a, b = ends[None, :, 0], ends[None, :, 1]
    d = b - a
    t = np.clip(np.sum((p[:, None] - a) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-18), 0.0, 1.0)
    return np.linalg.norm(p[:, None] - (a + t[..., None] * d), axis=-1)


def _segment_distance_matrix(ends: np.ndarray) -> np.ndarray:
    """(S, S) distance between segments (S, 2, 2): the smallest endpoint-to-segment
    distance, or 0 where two segments cross."""
    to_seg = _point_segment_distance(ends.reshape(-1, 2), ends).reshape(len(ends), 2, len(ends))
    d = to_seg.min(axis=1)  # d[i, j]: closest endpoint of i to segment j
    d = np.minimum(d, d.T)
    a, b = ends[:, None, 0], ends[:, None, 1]
    c, e = ends[None, :, 0], ends[None, :, 1]

    def side(p, q, r):  # sign of the turn p -> q -> r
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    crossing = (side(a, b, c) * side(a, b, e) < 0) & (side(c, e, a) * side(c, e, b) < 0)
    return np.where(crossing, 0.0, d)


def _neighbour_lists(lines: LineSet, distance: float) -> list[np.ndarray]:
    if len(lines) == 0:
        return []
    near = _segment_distance_matrix(lines.endpoints) < distance
    np.fill_diagonal(near, False)
    return [np.flatnonzero(row) for row in near]


def _nearest_neighbours(lines: LineSet, neighbours: Sequence[np.ndarray], max_rows: int) -> tuple[list[np.ndarray], int | None]:
    """Neighbour lists thinned so that their ordered triplets (sum of k (k - 1)) fit in
    max_rows: each line keeps its K nearest neighbours (segment distance, ties by index),
    K the largest that fits. A cluttered map (noise, a badly thresholded scan) has hundreds
    of short lines within the neighbour distance of each other, and its triplet table
    grows with the cube of its clutter. Returns (lists, K), K None when nothing was cut."""
    k = np.array([len(nb) for nb in neighbours], dtype=np.int64)
    if int((k * (k - 1)).sum()) <= max_rows:
        return list(neighbours), None
    lo, hi = 1, int(k.max())  # largest K with sum min(k, K) (min(k, K) - 1) <= max_rows
    while lo < hi:
        mid = (lo + hi + 1) // 2
        c = np.minimum(k, mid)
        lo, hi = (mid, hi) if int((c * (c - 1)).sum()) <= max_rows else (lo, mid - 1)
    ends = lines.endpoints
    out = []
    for i, nb in enumerate(neighbours):
        if len(nb) <= lo:
            out.append(nb)
            continue
        d = np.minimum(_point_segment_distance(ends[nb].reshape(-1, 2), ends[i : i + 1]).reshape(-1, 2).min(axis=1),
                       _point_segment_distance(ends[i], ends[nb]).min(axis=0))
        out.append(np.sort(nb[np.lexsort((nb, np.round(d, 9)))[:lo]]))
    return out, lo


def _ordered_pairs(neighbours: Sequence[np.ndarray]) -> np.ndarray:
    """(P, 2) rows (i, j): j a neighbour of i."""
    if not neighbours:
        return np.zeros((0, 2), dtype=np.int64)
    i = np.repeat(np.arange(len(neighbours)), [len(nb) for nb in neighbours])
    j = np.concatenate([np.asarray(nb, dtype=np.int64) for nb in neighbours]) if len(i) else np.zeros(0, dtype=np.int64)
    return np.stack([i, j], axis=1).astype(np.int64)


def _line_circle_pairs(lines: LineSet, circles: CircleSet, distance: float, min_lever: float) -> np.ndarray:
    """(P, 2) rows (line, circle): centre within `distance` of the segment and at least
    min_lever from the infinite line (the LC scale is the ratio of these levers)."""
    if len(lines) == 0 or len(circles) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    near = _point_segment_distance(circles.centers, lines.endpoints) < distance  # (C, L)
    lever = np.abs(circles.centers @ lines.normals.T + lines.offsets[None, :])
    c, li = np.nonzero(near & (lever >= min_lever))
    order = np.lexsort((c, li))
    return np.stack([li[order], c[order]], axis=1).astype(np.int64)


def _circle_pairs(circles: CircleSet, min_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs (k, l), k != l, centres at least min_distance apart; and distances."""
    n = len(circles)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    k, l = np.nonzero(~np.eye(n, dtype=bool))
    dist = np.linalg.norm(circles.centers[l] - circles.centers[k], axis=1)
    keep = dist >= min_distance
    return np.stack([k[keep], l[keep]], axis=1).astype(np.int64), dist[keep]


# --------------------------------------------------------------------------------------
# normal-consistency lookup
# --------------------------------------------------------------------------------------


def compact_rows(rows: np.ndarray) -> np.ndarray:
    """A tuple table (rows of line indices) in the smallest unsigned integer type that
    holds its indices, contiguous. The draws read rows at random, a million per round at
    free scale: a table a quarter the size of int64 stays in the cache (a free-scale 3L
    draw and solve ~30% faster on intel's 486k triplets). Indices are exact in any width."""
    top = int(rows.max()) if rows.size else 0
    dtype = np.uint16 if top <= np.iinfo(np.uint16).max else np.uint32 if top <= np.iinfo(np.uint32).max else np.int64
    return np.ascontiguousarray(rows, dtype=dtype)


class _AngleTable:
    """Floorplan tuples binned by the angles (mod pi) of their lines relative to the
    anchor line. A query returns the index ranges of the bins that can hold tuples within
    `tolerance` of the query angles: a superset of the normal-consistent tuples."""

    def __init__(self, rows: np.ndarray, relative: np.ndarray, tolerance: float):
        self.q = relative.shape[1]
        self.tolerance = tolerance
        nb = int(np.floor(np.pi / tolerance)) if tolerance > 0 else 1
        # bins at least `tolerance` wide, and >= 3 of them so a query's bins are distinct
        self.n_bins = nb if nb >= 3 else 1
        self.width = np.pi / self.n_bins
        key = self._key(np.floor(np.mod(relative, np.pi) / self.width).astype(np.int64) % self.n_bins)
        order = np.argsort(key, kind="stable")
        self.rows = compact_rows(rows[order])
        counts = np.bincount(key, minlength=self.n_bins**self.q)
        self.counts = counts
        self.start = np.cumsum(counts) - counts

    def _key(self, bins: np.ndarray) -> np.ndarray:
        key = np.zeros(bins.shape[:-1], dtype=np.int64)
        for j in range(self.q):
            key = key * self.n_bins + bins[..., j]
        return key

    def ranges(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(starts, sizes), each (B, R), for query angles (B, q)."""
        B = len(query)
        spread = 3 if self.n_bins >= 3 else 1
        per_dim_bins, per_dim_valid = [], []
        for j in range(self.q):
            if spread == 1:
                per_dim_bins.append(np.zeros((B, 1), dtype=np.int64))
                per_dim_valid.append(np.ones((B, 1), dtype=bool))
                continue
            lo = np.floor((query[:, j] - self.tolerance) / self.width).astype(np.int64)
            hi = np.floor((query[:, j] + self.tolerance) / self.width).astype(np.int64)
            offs = lo[:, None] + np.arange(3)[None, :]
            per_dim_bins.append(offs % self.n_bins)
            per_dim_valid.append(offs <= hi[:, None])
        # all combinations of per-dimension bins
        grids = np.meshgrid(*[np.arange(spread)] * self.q, indexing="ij")
        combos = np.stack([g.ravel() for g in grids], axis=1)  # (R, q)
        bins = np.stack([per_dim_bins[j][:, combos[:, j]] for j in range(self.q)], axis=-1)  # (B, R, q)
        valid = np.ones((B, len(combos)), dtype=bool)
        for j in range(self.q):
            valid &= per_dim_valid[j][:, combos[:, j]]
        key = self._key(bins)
        return self.start[key], np.where(valid, self.counts[key], 0)


# --------------------------------------------------------------------------------------
# floorplan tables (built once per floorplan object and settings)
# --------------------------------------------------------------------------------------


def settings_of(floorplan) -> Settings:
    cfg = getattr(floorplan, "settings", None)
    return cfg if isinstance(cfg, Settings) else Settings()


class FloorplanMatches:
    """Pruned floorplan tuples for every solver."""

    def __init__(self, floorplan, solvers: SolverSettings):
        fp_cfg: FloorplanSettings = settings_of(floorplan).floorplan
        self.lines: LineSet = floorplan.lines
        self.circles: CircleSet = floorplan.circles
        self.line_angles = line_angles(self.lines)  # for solve_3l_indexed
        tol = float(np.arccos(np.clip(NORMAL_CONSISTENCY, -1.0, 1.0)))
        par = np.deg2rad(PARALLEL_ANGLE_DEG)
        alpha = normal_angles(self.lines)
        neighbours = [np.asarray(nb, dtype=np.int64) for nb in floorplan.line_neighbours] if len(self.lines) else []
        # 3L: a line, two of its neighbours, not all parallel (a bounded table: _nearest_neighbours)
        near, kept = _nearest_neighbours(self.lines, neighbours, fp_cfg.max_triplets)
        if kept is not None:
            warnings.warn(f"floorplan {getattr(floorplan, 'name', '')!r}: its {len(self.lines)} lines have more line triplets than "
                          f"floorplan.max_triplets ({fp_cfg.max_triplets:,}; a cluttered map, or a dense plan): each line's triplets "
                          f"and pairs use its {kept} nearest neighbours only (raise floorplan.max_triplets to keep all)", stacklevel=3)
        tri = admissible_triplets(near, alpha, par, self.lines.lengths)[0]
        self.triplets = _AngleTable(tri, (alpha[tri[:, 1:]] - alpha[tri[:, :1]]) if len(tri) else np.zeros((0, 2)), tol)
        # the triplets' first two lines, for the two-line solve at a fixed scale
        self.triplet_heads = np.ascontiguousarray(self.triplets.rows[:, :2])
        # 2L: a line and a non-parallel neighbour, of the same bounded lists (100,000 scattered
        # pieces: 102 M pairs of all neighbours, 6.8 GiB for the table)
        pairs = _ordered_pairs(near)
        if len(pairs):
            pairs = pairs[~_parallel_mod_pi(alpha[pairs[:, 0]], alpha[pairs[:, 1]], par)]
        self.pairs = _AngleTable(pairs, (alpha[pairs[:, 1:]] - alpha[pairs[:, :1]]) if len(pairs) else np.zeros((0, 1)), tol)
        # LC: a line and a nearby circle off the line (floorplan units: lever * min_scale)
        self.line_circle = _line_circle_pairs(self.lines, self.circles, fp_cfg.neighbour_distance, MIN_BASELINE * solvers.min_scale)
        # 2C: circle pairs sorted by centre distance (scale window -> one contiguous range)
        cpairs, dist = _circle_pairs(self.circles, MIN_BASELINE * solvers.min_scale)
        order = np.argsort(dist, kind="stable")
        self.circle_pairs, self.circle_dist = cpairs[order], dist[order]


def floorplan_matches(floorplan, solvers: SolverSettings) -> FloorplanMatches:
    key = (solvers.min_scale,)  # the only setting the tables depend on
    return cached_per_floorplan(floorplan, "ransac tuples", key, lambda: FloorplanMatches(floorplan, solvers))


# --------------------------------------------------------------------------------------
# BEV samples
# --------------------------------------------------------------------------------------


class BevSamples:
    """Every admissible minimal sample of BEV primitives, per solver."""

    def __init__(self, obs: BevObservation, line_settings: LineSettings, solvers: SolverSettings, neighbour_distance: float):
        self.lines = deduplicate_lines(obs.lines, line_settings) if len(obs.lines) else obs.lines
        self.circles = obs.circles
        par = np.deg2rad(PARALLEL_ANGLE_DEG)
        alpha = normal_angles(self.lines)
        self.alpha = alpha
        # BEV segments are observed parts of floorplan walls, so two BEV lines can be
        # farther apart than their floorplan counterparts: when no admissible sample exists
        # within the neighbour distance, the restriction is lifted rather than giving up.
        def everyone():  # every other line, per line: built only when the fallback is taken
            return [np.delete(np.arange(len(self.lines)), i) for i in range(len(self.lines))]

        lengths = self.lines.lengths

        def triplets(nb):
            """The admissible triplets and their sampling weights (the shortest line's length)."""
            return admissible_triplets(nb, alpha, par, lengths)

        def pairs_of(nb):
            pairs = _ordered_pairs(nb)
            if len(pairs):
                pairs = pairs[~_parallel_mod_pi(alpha[pairs[:, 0]], alpha[pairs[:, 1]], par)]
            return pairs

        neighbours = _neighbour_lists(self.lines, neighbour_distance)
        self.triplets, triplet_weights = triplets(neighbours)
        if not len(self.triplets):
            self.triplets, triplet_weights = triplets(everyone())
        pairs = pairs_of(neighbours)
        self.pairs = pairs if len(pairs) else pairs_of(everyone())
        self.line_circle = _line_circle_pairs(self.lines, self.circles, neighbour_distance, MIN_BASELINE)
        if not len(self.line_circle):
            self.line_circle = _line_circle_pairs(self.lines, self.circles, np.inf, MIN_BASELINE)
        self.circle_pairs, self.circle_dist = _circle_pairs(self.circles, MIN_BASELINE)
        # Sampling weights: a line sample is as trustworthy as its shortest line (short
        # segments are often clutter, door jambs or fragments with no floorplan match), so
        # samples are drawn with probability proportional to that length.
        self.triplet_p = probabilities(triplet_weights)
        self.pair_p = probabilities(lengths[self.pairs].min(axis=1) if len(self.pairs) else np.zeros(0))
        self.line_circle_p = probabilities(lengths[self.line_circle[:, 0]] if len(self.line_circle) else np.zeros(0))


def probabilities(weights: np.ndarray) -> np.ndarray | None:
    total = float(np.sum(weights))
    return weights / total if len(weights) and total > 0 else None


# --------------------------------------------------------------------------------------
# model generation per solver
# --------------------------------------------------------------------------------------


def line_angles(lines: LineSet) -> np.ndarray:
    """Angle of each line's normal, as the solvers compute it for a sample's anchor."""
    return normal_angle(lines.normals)
