"""Touching collinear wall pieces merged into one segment, in near-linear time: candidate
pairs come from a k-d tree over the endpoints (cKDTree), groups from union-find over the
joins (scipy's connected components), and each group is merged in order along its line,
with the same result as merging pair by pair."""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree


def _joins(a: np.ndarray, b: np.ndarray, cos_tol: float, offset: float, gap: float) -> np.ndarray:
    """(K,) bool, pairwise over broadcast (K, 2, 2) stacks: does segment b join segment a
    (parallel within the angle, both ends within offset of a's line, extents along it
    touching up to gap)."""
    a, b = np.broadcast_arrays(a, b)
    d = (a[:, 1] - a[:, 0]) / np.linalg.norm(a[:, 1] - a[:, 0], axis=1)[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    db = (b[:, 1] - b[:, 0]) / np.linalg.norm(b[:, 1] - b[:, 0], axis=1)[:, None]
    rel_b, rel_a = b - a[:, :1], a - a[:, :1]
    tb = np.einsum("kpi,ki->kp", rel_b, d)  # positions along a's line
    ta = np.einsum("kpi,ki->kp", rel_a, d)
    return ((np.abs(np.einsum("ki,ki->k", d, db)) >= cos_tol) & (np.abs(np.einsum("kpi,ki->kp", rel_b, n)).max(axis=1) <= offset)
            & ~(tb.min(axis=1) > ta.max(axis=1) + gap) & ~(ta.min(axis=1) > tb.max(axis=1) + gap))


def _joined(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a extended along its own line over b's extent."""
    d = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
    ta, tb = sorted(((a - a[0]) @ d).tolist()), sorted(((b - a[0]) @ d).tolist())
    return np.array([a[0] + min(ta[0], tb[0]) * d, a[0] + max(ta[1], tb[1]) * d])


def _merge_in_order(segs: np.ndarray, cos_tol: float, offset: float, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """The merge rule applied in index order: repeatedly the first segment (lowest index)
    that joins a later one absorbs the first such one. Each row's later partners are found
    in one vectorised test; after a merge only the survivor's pairs have changed, so the
    scan resumes at the earliest row that now joins it instead of at row 0 (the same merges
    as restarting the scan, without the cubic rescans). Returns the survivors and their rows."""
    segs = segs.copy()
    alive = np.ones(len(segs), dtype=bool)
    i = 0
    while i < len(segs):
        if not alive[i]:
            i += 1
            continue
        later = np.flatnonzero(alive[i + 1:]) + i + 1
        hit = later[_joins(segs[i:i + 1], segs[later], cos_tol, offset, gap)] if len(later) else later
        if not len(hit):
            i += 1
            continue
        segs[i] = _joined(segs[i], segs[hit[0]])
        alive[hit[0]] = False
        while True:  # an earlier row (which joined nothing before) may join the grown one now
            earlier = np.flatnonzero(alive[:i])
            back = earlier[_joins(segs[earlier], segs[i:i + 1], cos_tol, offset, gap)] if len(earlier) else earlier
            if not len(back):
                break
            segs[back[0]] = _joined(segs[back[0]], segs[i])
            alive[i] = False
            i = int(back[0])
    return segs[alive], np.flatnonzero(alive)


def _collinear_groups(segs: np.ndarray, angle_deg: float, offset: float, gap: float) -> np.ndarray:
    """Component label per segment: segments near each other and nearly parallel. A chain of
    merges keeps every member within offset of the first one's line and within angle_deg of
    its direction, and a grown segment reaches at most gap past a member's extent, so two
    segments that can end up in one merged line lie within `reach` of each other and within
    twice the angle: components of that (loose) graph never split a merge."""
    lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    reach = math.hypot(gap, offset) + gap + 2 * offset
    spacing = max(reach, 1e-6 * float(lengths.max()))
    # points every `spacing` along each segment (ends included): two segments within reach
    # have sample points within reach + spacing of each other
    count = np.ceil(lengths / spacing).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(segs)), count)
    frac = (np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)) / np.repeat(count - 1, count)
    points = segs[owner, 0] + frac[:, None] * (segs[owner, 1] - segs[owner, 0])
    pairs = cKDTree(points).query_pairs(reach + spacing, output_type="ndarray")
    i, j = owner[pairs[:, 0]], owner[pairs[:, 1]]
    keep = i != j
    i, j = i[keep], j[keep]
    d = (segs[:, 1] - segs[:, 0]) / lengths[:, None]
    near = np.abs(np.einsum("ij,ij->i", d[i], d[j])) >= math.cos(math.radians(min(2 * angle_deg, 90.0)))
    graph = coo_matrix((np.ones(int(near.sum()), dtype=np.int8), (i[near], j[near])), shape=(len(segs), len(segs)))
    return connected_components(graph, directed=False)[1]


def merge_collinear(segments: np.ndarray, angle_deg: float, offset: float, gap: float) -> np.ndarray:
    """Join segments lying on one line whose extents touch or overlap (up to gap apart):
    a wall drawn in pieces is one line, as it is when extracted from pixels.

    Rule: in index order, the first segment that joins a later one (parallel within
    angle_deg, both ends within offset of its line, extents up to gap apart) absorbs it,
    extended along its own line; until nothing joins. Near-linear in the number of
    segments: only segments of one group (near each other and nearly parallel, found with
    a k-d tree) can merge, and the rule runs inside each group. Survivors keep the order
    of their first member."""
    segs = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    segs = segs[np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > 1e-9]
    if len(segs) < 2:
        return segs.copy()
    cos_tol = math.cos(math.radians(angle_deg))
    label = _collinear_groups(segs, angle_deg, offset, gap)
    order = np.argsort(label, kind="stable")  # each group's members in index order
    bounds = np.flatnonzero(np.diff(label[order])) + 1
    out, first = [], []
    for members in np.split(order, bounds):
        if len(members) == 1:
            out.append(segs[members])
            first.append(members[:1])
            continue
        merged, rows = _merge_in_order(segs[members], cos_tol, offset, gap)
        out.append(merged)
        first.append(members[rows])  # a survivor keeps its first member's place
    rows = np.concatenate(first)
    return np.concatenate(out)[np.argsort(rows, kind="stable")].reshape(-1, 2, 2)
