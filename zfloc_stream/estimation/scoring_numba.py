"""The scores of scoring.py as compiled loops (estimator.kernels: numba; the [fast] extra).

Each kernel does, per hypothesis and point, the float operations FloorplanScorer's numpy
code does, in the same dtypes and the same order, so every point lands in the same cell
and passes the same test; what is summed are integer counts (and the coarse grid's uint8
levels), exact in any order. The results are therefore bit-identical to the numpy path
(tests/test_scoring_numba.py). Trigonometry stays in numpy, outside the kernels (numpy's
sin/cos need not round like the C library's).

The loops need none of the (hypotheses x points) temporaries numpy builds, so chunk_size
(which bounds them there) has nothing to bound here. rank_coarse_to_fine's choice of the
hypotheses to re-score (top_distinct) sorts and poses only the prefix of the coarse order
that the greedy suppression reads: the same indices in the same order. Every kernel
releases the GIL; a call over many hypotheses is split into ranges of them, one per thread
the round was given (threads.py), each writing its own slots: the same bits.
"""

from __future__ import annotations

import math

import numpy as np

from .. import threads
from ..errors import InputError
from ..numba_support import njit
from ..ties import tie_keys
from .scoring import DEEP_FREE, FREE, implied_poses


# a kernel call is split over the round's threads (threads.py) only into pieces of at
# least this many point lookups (~0.2 ms): handing a piece to a worker costs ~0.05 ms
_MIN_LOOKUPS_PER_THREAD = 200_000
_MIN_VIOLATION_MODELS_PER_THREAD = 64  # violation: a model reads the floorplan walls under its footprint


def _model_ranges(n_models: int, n_points: int) -> list[tuple[int, int]]:
    return threads.ranges(n_models, _MIN_LOOKUPS_PER_THREAD // max(1, n_points) + 1)


@njit
def _coarse_kernel(models, c, sn, inv, ox, oy, px, py, grid, h, w, index_type, out):
    """FloorplanScorer.coarse_consistency for every model, coarse_terms included: a, b,
    cu, cv are its float64 expressions (c, sn: numpy's cos and sin of the headings)
    rounded to float32; the float32 cell coordinates a x - b y + cu and b x + a y + cv,
    clipped to the grid and truncated, index the uint8 coarse grid; out = (near - spread /
    (1 + 1/n)) / n. index_type: np.uint32 when every cell index fits in 32 bits (the
    index arithmetic then vectorises in 32-bit lanes, ~25 % faster), else np.uint64."""
    n = px.shape[0]
    col_max = np.float32(w - 1)  # np.clip's bounds, float32 like the array it clips
    row_max = np.float32(h - 1)
    zero = np.float32(0.0)
    for i in range(models.shape[0]):
        # coarse_terms: (s cos) * inv, (s sin) * inv, (t - origin) * inv, then float32
        ai = np.float32(models[i, 3] * c[i] * inv)
        bi = np.float32(models[i, 3] * sn[i] * inv)
        cui = np.float32((models[i, 0] - ox) * inv)
        cvi = np.float32((models[i, 1] - oy) * inv)
        far = 0
        total = 0
        for j in range(n):
            x = ai * px[j] - bi * py[j] + cui
            y = bi * px[j] + ai * py[j] + cvi
            # np.clip, as selects (branch-free, so the loop vectorises); the first select
            # also sends NaN (where numpy's take raises) to the border ring, which reads
            # as far from any wall, instead of an arbitrary address
            x = x if x >= zero else zero
            x = x if x <= col_max else col_max
            y = y if y >= zero else zero
            y = y if y <= row_max else row_max
            # truncation of a value in [0, w - 1], as numpy's cast to int32; the unsigned
            # index also spares numba's negative-index wraparound test
            q = grid[index_type(np.int32(y) * w + np.int32(x))]
            total += q
            far += q == 255
        near = n - far
        spread = total / (255.0 * n)
        out[i] = (near - spread / (1.0 + 1.0 / n)) / n


@njit
def _consistency_kernel(a, b, tx, ty, px, py, field, h, w, ox, oy, res, tau_c, out):
    """FloorplanScorer.consistency for every model: the points mapped by x' = s R x + t
    (a = s cos, b = s sin), f^c by Floorplan.distance's bilinear lookup, out = the share
    below tau_c. False (out unfinished) when a mapped point is not finite, where
    Floorplan.distance raises."""
    n = px.shape[0]
    for i in range(a.shape[0]):
        ai, bi, txi, tyi = a[i], b[i], tx[i], ty[i]
        below = 0
        for j in range(n):
            x = ai * px[j] - bi * py[j] + txi
            y = bi * px[j] + ai * py[j] + tyi
            if not (math.isfinite(x) and math.isfinite(y)):
                return False
            u = (x - ox) / res - 0.5
            v = (y - oy) / res - 0.5
            uc = min(max(u, 0.0), w - 1.0)
            vc = min(max(v, 0.0), h - 1.0)
            c0 = min(np.int64(uc), w - 2)
            r0 = min(np.int64(vc), h - 2)
            fu = uc - c0
            fv = vc - r0
            k = r0 * w + c0
            top = field[k] * (1.0 - fu) + field[k + 1] * fu
            bottom = field[k + w] * (1.0 - fu) + field[k + w + 1] * fu
            value = top * (1.0 - fv) + bottom * fv
            # outside the grid: plus the distance to it. Inside, numpy adds hypot(0, 0) = 0,
            # which cannot change the comparison (value >= 0), so the call is skipped.
            if u != uc or v != vc:
                value = value + math.hypot(u - uc, v - vc) * res
            if value < tau_c:
                below += 1
        out[i] = below / n
    return True


@njit
def _violation_kernel(tx, ty, c, sn, k, c0, c1, r0, r1, empty, bucket_start, n_cols, walls, state, h, w, ou, ov, observed, out):
    """FloorplanScorer.violation for every model: the floorplan wall points of the buckets
    under its footprint box (rows r0..r1, columns c0..c1; one contiguous range per row)
    pulled back into BEV cells by (R^T (x' - t)) k - origin; of those in observed free
    space (or any observed cell, `observed`), the share in deep free space."""
    for i in range(tx.shape[0]):
        if empty[i]:
            continue
        txi, tyi, ci, si, ki = tx[i], ty[i], c[i], sn[i], k[i]
        n_seen = 0
        n_bad = 0
        for r in range(r0[i], r1[i] + 1):
            for p in range(bucket_start[r * n_cols + c0[i]], bucket_start[r * n_cols + c1[i] + 1]):
                dx = walls[p, 0] - txi
                dy = walls[p, 1] - tyi
                u = (ci * dx + si * dy) * ki - ou
                v = (-si * dx + ci * dy) * ki - ov
                if not (u >= 0 and u < w and v >= 0 and v < h):
                    continue  # state 0 (unseen) in the numpy path
                # inside the grid numpy's clip changes nothing the truncation keeps
                s = state[np.int64(v) * w + np.int64(u)]
                if s == DEEP_FREE:
                    n_bad += 1
                    n_seen += 1
                elif s == FREE or (observed and s > 0):
                    n_seen += 1
        if n_seen > 0:
            out[i] = n_bad / n_seen


@njit
def _greedy_distinct_kernel(x, y, ang, max_distance, max_angle, limit, kept):
    """scoring._greedy_distinct: walks the hypotheses in order and keeps one unless a kept
    one lies within max_distance (hypot of the implied-position difference) and max_angle
    (|wrap_angle| of the heading difference), until `limit` are kept; returns how many
    (their indices in kept). A hypothesis survives the numpy loop exactly when no kept
    earlier one is near it, which is what is tested here, with the same operations:
    libm's hypot (numpy's np.hypot calls it too) and Python's float modulo (numpy's
    remainder has the same definition), so every comparison gives the same answer."""
    two_pi = 2.0 * np.pi
    n_kept = 0
    for j in range(x.shape[0]):
        if n_kept >= limit:
            break
        alone = True
        for k in range(n_kept):
            i = kept[k]
            # wrap_angle(ang[j] - ang[i]) = (d + pi) % (2 pi) - pi
            if math.hypot(x[j] - x[i], y[j] - y[i]) < max_distance and \
                    abs((ang[j] - ang[i] + np.pi) % two_pi - np.pi) < max_angle:
                alone = False
                break
        if alone:
            kept[n_kept] = j
            n_kept += 1
    return n_kept


def descending_prefix(values: np.ndarray, length: int) -> np.ndarray:
    """The first entries, at least `length` of them (all when there are fewer values), of
    ties.descending(values), the same indices in the same order, without sorting
    everything.

    descending orders by (-tie_keys(values), index), stably. With v the length-th smallest
    key (np.partition), the indices whose key is <= v are exactly a prefix of that order
    (every other key is larger, or NaN, which sorts last), and sorting them stably, in index
    order, by key orders them as descending does. Ties at v are all taken, so the prefix
    may be longer than `length`."""
    keys = -tie_keys(values)
    if length >= len(keys):
        return np.argsort(keys, kind="stable")
    v = np.partition(keys, length - 1)[length - 1]
    if np.isnan(v):  # fewer than `length` non-NaN keys: NaNs order among themselves by index
        return np.argsort(keys, kind="stable")
    candidates = np.flatnonzero(keys <= v)
    return candidates[np.argsort(keys[candidates], kind="stable")]


def top_distinct(models: np.ndarray, coarse: np.ndarray, anchor: np.ndarray, settings) -> np.ndarray:
    """rank_coarse_to_fine's choice, order[distinct(models[order], anchor, settings,
    settings.top_k)] with order = descending(coarse), the same indices in the same order.

    Greedy suppression never looks ahead, so the first top_k survivors depend only on the
    order's prefix up to the last of them (distinct itself grows its block on that
    ground): only a prefix of the order is computed (descending_prefix), only its implied
    poses (implied_poses row by row, the same numbers as on the whole list) and the
    greedy pass runs compiled. The prefix grows 4x while it yields fewer than top_k."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    n, limit = len(models), int(settings.top_k)
    if n == 0 or limit <= 0:
        return np.zeros(0, dtype=np.int64)
    max_angle = float(np.deg2rad(settings.distinct_angle_deg))
    length = min(n, max(256, 16 * limit))
    while True:
        order = descending_prefix(coarse, length)
        rows = models[order]
        pos, ang = implied_poses(rows, anchor)
        kept = np.empty(limit, dtype=np.int64)
        count = _greedy_distinct_kernel(np.ascontiguousarray(pos[:, 0]), np.ascontiguousarray(pos[:, 1]),
                                        np.ascontiguousarray(ang), float(settings.distinct_translation),
                                        max_angle, limit, kept)
        if count >= limit or len(order) >= n:
            return order[kept[:count]]
        length = min(n, 4 * len(order))


class NumbaScorer:
    """A FloorplanScorer's three scores computed by the compiled kernels above, reading the
    scorer's own arrays (and its floorplan's distance field): nothing is copied, so
    wrapping a scorer costs nothing."""

    def __init__(self, scorer):
        self.scorer = scorer

    def coarse_consistency(self, models: np.ndarray, points: np.ndarray, chunk_size: int) -> np.ndarray:
        """FloorplanScorer.coarse_consistency (same value, same tie-break)."""
        scorer = self.scorer
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0 or len(models) == 0:
            return out
        h, w = scorer.shape
        px = np.ascontiguousarray(points[:, 0], dtype=np.float32)
        py = np.ascontiguousarray(points[:, 1], dtype=np.float32)
        # numpy's cos and sin of the same column view coarse_terms takes them of; the rest
        # of coarse_terms (products, float32 rounding) is done in the kernel
        c, sn = np.cos(models[:, 2]), np.sin(models[:, 2])
        index_type = np.uint32 if h * w <= 1 << 32 else np.uint64
        inv, ox, oy = 1.0 / scorer.resolution, float(scorer.origin[0]), float(scorer.origin[1])

        def piece(r):
            i = slice(*r)
            _coarse_kernel(models[i], c[i], sn[i], inv, ox, oy, px, py, scorer.coarse_field, h, w, index_type, out[i])

        threads.run(piece, _model_ranges(len(models), len(px)))
        return out

    def consistency(self, models: np.ndarray, points: np.ndarray, tau_c: float, chunk_size: int) -> np.ndarray:
        """FloorplanScorer.consistency: Cc with the floorplan's bilinear f^c."""
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0 or len(models) == 0:
            return out
        floorplan = self.scorer._floorplan()
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        # transform_points' a and b (numpy's cos and sin)
        a = models[:, 3] * np.cos(models[:, 2])
        b = models[:, 3] * np.sin(models[:, 2])
        h, w = floorplan.shape
        tx, ty = np.ascontiguousarray(models[:, 0]), np.ascontiguousarray(models[:, 1])
        px, py = np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1])
        grid = (floorplan._flat_field, h, w, float(floorplan.origin[0]), float(floorplan.origin[1]), float(floorplan.resolution))

        def piece(r):
            i = slice(*r)
            return _consistency_kernel(a[i], b[i], tx[i], ty[i], px, py, *grid, float(tau_c), out[i])

        if not all(threads.run(piece, _model_ranges(len(models), len(p)))):
            raise InputError("points passed to Floorplan.distance contain NaN or inf")
        return out

    def violation(self, models: np.ndarray, bev, tau_v: float, chunk_size: int, per: str = "free") -> np.ndarray:
        """FloorplanScorer.violation: the same buckets per model, the same points, the same
        counts."""
        scorer = self.scorer
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        n_rows, n_cols = scorer.bucket_shape
        if len(scorer.wall_points) == 0 or len(models) == 0 or bev.radius <= 0 or n_rows == 0:
            return out
        c0, c1, r0, r1, empty = scorer.bucket_ranges(*scorer.footprint_boxes(models, bev))
        c, sn = np.cos(models[:, 2]), np.sin(models[:, 2])
        k = 1.0 / (models[:, 3] * bev.resolution)
        h, w = bev.state.shape
        tx, ty = np.ascontiguousarray(models[:, 0]), np.ascontiguousarray(models[:, 1])
        state = np.ascontiguousarray(bev.state).ravel()
        ou, ov = float(bev.origin_cells[0]), float(bev.origin_cells[1])

        def piece(r):
            i = slice(*r)
            _violation_kernel(tx[i], ty[i], c[i], sn[i], k[i], c0[i], c1[i], r0[i], r1[i], empty[i], scorer.bucket_start, n_cols,
                              scorer.wall_points, state, h, w, ou, ov, per == "observed", out[i])

        threads.run(piece, threads.ranges(len(models), _MIN_VIOLATION_MODELS_PER_THREAD))
        return out
