"""Pairs of nearby segments without an all-pairs matrix: a floorplan's line neighbours
(Floorplan.line_neighbours) and the near-duplicate lines a line set drops
(deduplicate_lines).

Both were (N, N) bool matrices: 100,000 short lines scattered in a 50 m square (issue 44)
kept ~58,000 lines, 3.4 GB per matrix and minutes of work. Here segments are registered by
their bounding boxes in a uniform grid; a row visits only the cells its box, grown by its
reach, covers, and marks the candidates that pass in a bitmap over the segment indices,
so each row's list comes out ascending (as np.flatnonzero of a matrix row gave it)
without a sort. Rows are done in blocks, each block's lists kept as one int32 array: the
memory is that of the pairs found, not of N^2.

The tests are the matrices' own, element for element: the same box prefilter, the same
segment distance (floorplan._segment_distances' arithmetic, operation for operation; the
kernels are compiled without fastmath), the same duplicate rule.
"""

from __future__ import annotations

import math

import numpy as np

from .shapes import LineSet
from ..runtime.numba_support import njit

ROW_BLOCK = 4096  # rows per kernel call: one block's pairs are one array


@njit
def _point_segment(px, py, s0x, s0y, s1x, s1y):
    """floorplan._segment_distances' point_to_segment, scalar: the same operations."""
    dx, dy = s1x - s0x, s1y - s0y
    t = ((px - s0x) * dx + (py - s0y) * dy) / max(dx * dx + dy * dy, 1e-18)
    t = min(max(t, 0.0), 1.0)
    ex, ey = px - (s0x + t * dx), py - (s0y + t * dy)
    return math.sqrt(ex * ex + ey * ey)


@njit
def _segments_within(e, i, j, reach):
    """floorplan._segment_distances(a = e[i], b = e[j]) < reach: an endpoint within reach
    of the other segment, or the two crossing (distance 0)."""
    a0x, a0y, a1x, a1y = e[i, 0, 0], e[i, 0, 1], e[i, 1, 0], e[i, 1, 1]
    b0x, b0y, b1x, b1y = e[j, 0, 0], e[j, 0, 1], e[j, 1, 0], e[j, 1, 1]
    if _point_segment(a0x, a0y, b0x, b0y, b1x, b1y) < reach or _point_segment(a1x, a1y, b0x, b0y, b1x, b1y) < reach:
        return True
    if _point_segment(b0x, b0y, a0x, a0y, a1x, a1y) < reach or _point_segment(b1x, b1y, a0x, a0y, a1x, a1y) < reach:
        return True
    dax, day, dbx, dby = a1x - a0x, a1y - a0y, b1x - b0x, b1y - b0y
    c1 = dax * (b0y - a0y) - day * (b0x - a0x)
    c2 = dax * (b1y - a0y) - day * (b1x - a0x)
    c3 = dbx * (a0y - b0y) - dby * (a0x - b0x)
    c4 = dbx * (a1y - b0y) - dby * (a1x - b0x)
    return c1 * c2 < 0 and c3 * c4 < 0


@njit
def _cell_range(v, origin, cell, count):
    k = int(math.floor((v - origin) / cell))
    return min(max(k, 0), count - 1)


@njit
def _grid(lo, hi, x0, y0, cell, nx, ny):
    """CSR (start, items) of the segments whose box touches each cell (row-major)."""
    n = len(lo)
    start = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        for cy in range(_cell_range(lo[i, 1], y0, cell, ny), _cell_range(hi[i, 1], y0, cell, ny) + 1):
            for cx in range(_cell_range(lo[i, 0], x0, cell, nx), _cell_range(hi[i, 0], x0, cell, nx) + 1):
                start[cy * nx + cx + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int32)
    for i in range(n):
        for cy in range(_cell_range(lo[i, 1], y0, cell, ny), _cell_range(hi[i, 1], y0, cell, ny) + 1):
            for cx in range(_cell_range(lo[i, 0], x0, cell, nx), _cell_range(hi[i, 0], x0, cell, nx) + 1):
                c = cy * nx + cx
                items[fill[c]] = i
                fill[c] += 1
    return start, items


# de Bruijn sequence: the index of a word's lowest set bit without a loop over its bits
_DEBRUIJN = np.uint64(0x03F79D71B4CB0A89)
_DEBRUIJN_INDEX = np.array([0, 1, 48, 2, 57, 49, 28, 3, 61, 58, 50, 42, 38, 29, 17, 4, 62, 55, 59, 36, 53, 51, 43, 22, 45, 39, 33, 30, 24,
                            18, 12, 5, 63, 47, 56, 27, 60, 41, 37, 16, 54, 35, 52, 21, 44, 32, 23, 11, 46, 26, 40, 15, 34, 20, 31, 10,
                            25, 14, 19, 9, 13, 8, 7, 6], dtype=np.int64)


@njit
def _rows(r0, r1, lo, hi, threshold, later_only, e, reach, mid, half, slack, x0, y0, cell, nx, ny, start, items, packed, bits, debruijn, index):
    """Rows r0..r1-1: the segments j (j > i with later_only; never i) whose box gap to i's,
    max(lo_j - hi_i, lo_i - hi_j) on each axis, is below threshold[i] on both axes and,
    with reach > 0, whose segment distance to i is below reach. Returns (indptr, indices),
    each row ascending. packed[s]: item s's lo, hi, midpoint and half length, beside the
    cell's other items (read in order, not gathered from four arrays)."""
    n = len(lo)
    indptr = np.zeros(r1 - r0 + 1, np.int64)
    out = np.empty(max(16 * (r1 - r0), 64), np.int32)
    k = 0
    for i in range(r0, r1):
        t = threshold[i]
        first, last = n, -1
        for cy in range(_cell_range(lo[i, 1] - t, y0, cell, ny), _cell_range(hi[i, 1] + t, y0, cell, ny) + 1):
            for cx in range(_cell_range(lo[i, 0] - t, x0, cell, nx), _cell_range(hi[i, 0] + t, x0, cell, nx) + 1):
                c = cy * nx + cx
                first_item = start[c]
                if later_only:  # a cell's items ascend (registered in index order): skip to those after i
                    lo_k, hi_k = start[c], start[c + 1]
                    while lo_k < hi_k:
                        m = (lo_k + hi_k) >> 1
                        if items[m] <= i:
                            lo_k = m + 1
                        else:
                            hi_k = m
                    first_item = lo_k
                for s in range(first_item, start[c + 1]):
                    j = items[s]
                    if j == i:
                        continue
                    word, bit = j >> 6, np.uint64(1) << np.uint64(j & 63)
                    if bits[word] & bit:
                        continue
                    gx = max(packed[s, 0] - hi[i, 0], lo[i, 0] - packed[s, 2])
                    gy = max(packed[s, 1] - hi[i, 1], lo[i, 1] - packed[s, 3])
                    if not max(gx, gy) < t:
                        continue
                    if reach > 0:
                        # the midpoints' distance bounds the segments' from above, less the
                        # half lengths from below: most pairs are decided by it (with slack
                        # for rounding: what is left is measured as the matrix measured it)
                        mx, my = mid[i, 0] - packed[s, 4], mid[i, 1] - packed[s, 5]
                        dm = math.sqrt(mx * mx + my * my)
                        if dm - half[i] - packed[s, 6] >= reach + slack:
                            continue
                        if not dm < reach - slack and not _segments_within(e, i, j, reach):
                            continue
                    bits[word] |= bit
                    first, last = min(first, j), max(last, j)
        for word in range(first >> 6, (last >> 6) + 1 if last >= 0 else 0):
            w = bits[word]
            while w:
                low = w & (~w + np.uint64(1))
                j = (word << 6) + index[np.int64((low * debruijn) >> np.uint64(58))]
                if k == len(out):
                    out = np.concatenate((out, np.empty(len(out), np.int32)))
                out[k] = j
                k += 1
                w ^= low
            bits[word] = np.uint64(0)
        indptr[i - r0 + 1] = k
    return indptr, out[:k].copy()


def _box_pairs(lo, hi, threshold, later_only, endpoints, reach, block):
    """(indptr, indices) of box_pairs' rows, in kernel calls of `block` rows."""
    lo = np.ascontiguousarray(lo, dtype=float)
    hi = np.ascontiguousarray(hi, dtype=float)
    n = len(lo)
    threshold = np.ascontiguousarray(np.broadcast_to(np.asarray(threshold, dtype=float), (n,)))
    finite = np.isfinite(threshold)
    if not finite.all():  # a row that may pair with anything: every box is within its reach
        threshold = np.where(finite, threshold, 2.0 * float((hi.max(axis=0) - lo.min(axis=0)).max()) + 1.0)
    # no more than ~4 M cells
    x0, y0 = lo.min(axis=0)
    span = float((hi.max(axis=0) - lo.min(axis=0)).max())
    # a cell about a box across, or half a reach: a row visits ~(2 reach / cell + 2)^2 cells,
    # little more area than its grown box (a 100,000-line scatter: 3 m cells for a 6 m reach)
    cell = max(float(np.median((hi - lo).max(axis=1))), 0.5 * float(np.median(threshold)), span / 2048.0, 1e-9)
    nx = int((hi[:, 0].max() - x0) // cell) + 1
    ny = int((hi[:, 1].max() - y0) // cell) + 1
    start, items = _grid(lo, hi, x0, y0, cell, nx, ny)
    e = np.zeros((0, 2, 2)) if endpoints is None else np.ascontiguousarray(endpoints, dtype=float)
    mid = e.mean(axis=1) if endpoints is not None else np.zeros((0, 2))
    half = 0.5 * np.linalg.norm(e[:, 1] - e[:, 0], axis=1) if endpoints is not None else np.zeros(0)
    # rounding of distances computed from coordinates this large, with a wide margin
    slack = 1e-9 * (float(reach) + (float(np.abs(e).max()) if len(e) else 0.0)) + 1e-12
    packed = np.zeros((len(items), 8))
    packed[:, 0:2], packed[:, 2:4] = lo[items], hi[items]
    if endpoints is not None:
        packed[:, 4:6], packed[:, 6] = mid[items], half[items]
    bits = np.zeros((n >> 6) + 1, np.uint64)
    parts, ptrs = [], [np.zeros(1, np.int64)]
    for r0 in range(0, n, block):
        r1 = min(r0 + block, n)
        indptr, indices = _rows(r0, r1, lo, hi, threshold, later_only, e, float(reach) if endpoints is not None else 0.0,
                                mid, half, slack, x0, y0, cell, nx, ny, start, items, packed, bits, _DEBRUIJN, _DEBRUIJN_INDEX)
        ptrs.append(indptr[1:] + (ptrs[-1][-1] if len(ptrs[-1]) else 0))
        parts.append(indices)
    indices = parts[0] if len(parts) == 1 else np.concatenate(parts)
    return np.concatenate(ptrs), indices


def box_pairs(lo: np.ndarray, hi: np.ndarray, threshold, later_only: bool = False) -> list[np.ndarray]:
    """For each box i (corners lo, hi: (N, 2)), the ascending int32 indices j != i (j > i
    with later_only) whose box gap to i's, max(lo_j - hi_i, lo_i - hi_j), is below
    threshold (a number, or one per box: inf for every box) on both axes."""
    n = len(lo)
    if n == 0:
        return []
    indptr, indices = _box_pairs(lo, hi, threshold, later_only, None, 0.0, ROW_BLOCK)
    return [indices[indptr[k] : indptr[k + 1]] for k in range(n)]


@njit
def _symmetric(indptr, upper, n):
    """The full rows of a symmetric relation from its upper rows (j > i, each ascending):
    row r holds the i < r whose upper rows hold r (met in ascending i), then its own upper
    row. Returns (indptr, indices)."""
    lower = np.zeros(n, np.int64)
    for k in range(len(upper)):
        lower[upper[k]] += 1
    full = np.zeros(n + 1, np.int64)
    for r in range(n):
        full[r + 1] = full[r] + lower[r] + indptr[r + 1] - indptr[r]
    lower_at = full[:-1].copy()
    out = np.empty(full[-1], np.int32)
    for i in range(n):
        at = full[i] + lower[i]
        for k in range(indptr[i], indptr[i + 1]):
            j = upper[k]
            out[at] = j
            at += 1
            out[lower_at[j]] = i
            lower_at[j] += 1
    return full, out


def segment_neighbours(endpoints: np.ndarray, reach: float) -> list[np.ndarray]:
    """For each segment (N, 2, 2), the ascending int32 indices of the others within reach
    (segment distance, 0 where they cross): row i of the (N, N) matrix
    `_segment_distances < reach` (diagonal False) whose pairs are measured only where the
    boxes come within reach on both axes (the margin keeps a pair whose distance rounds to
    just under reach). The relation is symmetric (the distance's arithmetic is), so each
    pair is measured once, j > i, and its rows are assembled from those."""
    e = np.ascontiguousarray(np.asarray(endpoints, dtype=float).reshape(-1, 2, 2))
    n = len(e)
    if n == 0:
        return []
    indptr, upper = _box_pairs(e.min(axis=1), e.max(axis=1), reach * (1 + 1e-9) + 1e-9, True, e, reach, ROW_BLOCK)
    count, full = _symmetric(indptr, upper, n)
    del upper
    return [full[count[k] : count[k + 1]] for k in range(n)]


def deduplicate_lines(lines: LineSet, settings) -> LineSet:
    """Drop lines that repeat a longer one (settings: settings/estimation.py's LineSettings): nearly parallel
    (< dedup_angle_deg), nearly the same offset (the shorter one's midpoint within
    dedup_offset of the longer line) and overlapping extents. Order (longest first) is kept.

    Only pairs whose boxes come within a bound of the rule are tested: a repeat j of line i
    has a point q projecting into i's extent, |n_i.q + d_i| < dedup_offset + |j| / 2
    (sin of the angle + eta_i) (eta_i: how far i's normal is from its ends' perpendicular),
    the point p of i beside q at most eps_i (its ends' offset) off the normal-form line, so
    |q - p| < (dedup_offset + |i| / 2 (sin + eta_i) + eps_i) / (1 - eta_i) (|j| <= |i|)."""
    m = len(lines)
    if m < 2:
        return lines
    order = np.argsort(-lines.lengths, kind="stable")
    L = lines.subset(order)
    e = L.endpoints
    d = e[:, 1] - e[:, 0]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    cos_limit = np.cos(np.deg2rad(settings.dedup_angle_deg))
    n, off, mid = L.normals, L.offsets, L.midpoints
    t_i0 = np.einsum("ij,ij->i", e[:, 0], d)
    t_i1 = np.einsum("ij,ij->i", e[:, 1], d)
    lo_i_all, hi_i_all = np.minimum(t_i0, t_i1), np.maximum(t_i0, t_i1)
    # the prefilter's reach per line (see above); a line whose normal is far off its ends
    # (eta >= 0.5) is tested against every later line
    perp = np.stack([-d[:, 1], d[:, 0]], axis=1)
    eta = np.minimum(np.linalg.norm(n - perp, axis=1), np.linalg.norm(n + perp, axis=1))
    eps = np.abs(np.einsum("kij,kj->ki", e, n) + off[:, None]).max(axis=1)
    sin_limit = math.sqrt(max(1.0 - float(cos_limit) ** 2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        reach = (settings.dedup_offset + 0.5 * L.lengths * (sin_limit + eta) + eps) / (1.0 - eta)
    reach = np.where(np.isfinite(reach) & (eta < 0.5), reach * (1 + 1e-6) + 1e-9, np.inf)
    candidates = box_pairs(e.min(axis=1), e.max(axis=1), reach, later_only=True)
    i = np.repeat(np.arange(m), [len(c) for c in candidates])
    if len(i) == 0:
        return L
    j = np.concatenate(candidates).astype(np.int64)
    parallel = np.abs(d[i, 0] * d[j, 0] + d[i, 1] * d[j, 1]) >= cos_limit
    # j's midpoint within dedup_offset of line i
    close = np.abs(mid[j, 0] * n[i, 0] + mid[j, 1] * n[i, 1] + off[i]) < settings.dedup_offset
    # extents of j projected on i's direction overlap i's extent
    pj0 = e[j, 0, 0] * d[i, 0] + e[j, 0, 1] * d[i, 1]
    pj1 = e[j, 1, 0] * d[i, 0] + e[j, 1, 1] * d[i, 1]
    overlap = (np.minimum(hi_i_all[i], np.maximum(pj0, pj1)) - np.maximum(lo_i_all[i], np.minimum(pj0, pj1))) > 0
    dup = parallel & close & overlap
    i, j = i[dup], j[dup]  # ascending i, then j
    keep = np.ones(m, dtype=bool)
    rows = np.flatnonzero(np.r_[True, i[1:] != i[:-1]]) if len(i) else np.zeros(0, np.int64)
    for a, b in zip(rows, np.r_[rows[1:], len(i)]):  # greedy from the longest: a kept line suppresses its shorter repeats
        if keep[i[a]]:
            keep[j[a:b]] = False
    return L.subset(np.flatnonzero(keep))
