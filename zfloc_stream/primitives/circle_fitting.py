"""Circle (pillar) extraction (primitives.extract_circles), compiled around two library calls.

In Python: the link pairs of the points (cKDTree.query_pairs) and sklearn's HDBSCAN, and the
random numbers: each cluster's RANSAC triplets are drawn with rng.integers(0, m,
size=(iterations, 3)), in cluster order, before the kernel runs.

Compiled: the connected components of the link pairs (union-find), the groups no wider
than a pillar (a group wider than a pillar of max_radius, a wall or a room, cannot hold an
isolated circle, so it is dropped before HDBSCAN, which keeps clustering cheap), and per
cluster a 3-point RANSAC circle, Gauss-Newton refits (LAPACK's lstsq), the inlier ratio,
and acceptance only if the inliers wrap far enough around the centre (angular coverage)
without long holes (angular span), and fit no two lines better (a corner).

Modules: point_groups.py (groups and HDBSCAN clusters, no random numbers), arc_checks.py
(coverage, span, the two-line test), this one (the RANSAC fit and fit_circles). NB numba's
disk cache does not notice a change in another file: after editing point_groups.py or
arc_checks.py, delete this module's cached kernels (__pycache__/circle_fitting.*.nbi/.nbc).

Determinism: fixed operation orders, so the same circles bit for bit on one machine;
elsewhere libm's atan2 or LAPACK may round differently in the last bits, which moves a
centre by ~1e-12 m and changes a decision only for an angle within rounding of a threshold.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry.shapes import CircleSet
from ..runtime.numba_support import njit
from .arc_checks import TWO_PI, angular_coverage_and_span, best_two_line_sse
from .point_groups import INLIER_DISTANCE, MIN_CLUSTER_SIZE, CircleClusters, circle_clusters, cluster_members

_EPS = float(np.finfo(np.float64).eps)

# What makes a cluster of wall points a pillar (were primitives.circles.*; every recorded
# result used these). The tests separate a pillar from a wall fragment or a corner; they are
# not a matter of taste.
RANSAC_ITERATIONS = 100  # 3-point circle hypotheses per cluster
REFIT_ROUNDS = 2  # least-squares refit + inlier re-selection rounds
REFIT_ITERATIONS = 10  # Gauss-Newton steps per refit (converges in a few from a RANSAC circle)
MIN_INLIER_RATIO = 0.8  # of the cluster's points on the circle: a pillar's cluster is its ring, a wall's is not
MIN_COVERAGE_DEG = 120.0  # 360 deg minus the largest angular gap: the inliers wrap at least a third of the way round
MAX_GAP_DEG = 30.0  # angular continuity: consecutive gaps below this...
MIN_SPAN_DEG = 90.0  # ...over a contiguous span at least this long (a corner's two lines leave a long hole)


@njit
def _residual(x, y, cx, cy, r):
    """|norm((x, y) - c) - r|."""
    dx = x - cx
    dy = y - cy
    return abs(math.sqrt(dx * dx + dy * dy) - r)


@njit
def _fit_circle(p, inliers, cx, cy, r, iterations):
    """Geometric least-squares circle of the rows p[inliers] (Gauss-Newton on |p - c| - r,
    lstsq steps) from the start (cx, cy, r)."""
    m = 0
    for i in range(p.shape[0]):
        if inliers[i]:
            m += 1
    q = np.empty((m, 2))
    m = 0
    for i in range(p.shape[0]):
        if inliers[i]:
            q[m, 0] = p[i, 0]
            q[m, 1] = p[i, 1]
            m += 1
    J = np.empty((m, 3))
    b = np.empty(m)
    rcond = _EPS * max(m, 3)  # numpy's default cut-off for small singular values
    for _ in range(iterations):
        for i in range(m):
            dx = q[i, 0] - cx
            dy = q[i, 1] - cy
            dist = max(math.sqrt(dx * dx + dy * dy), 1e-12)
            J[i, 0] = -dx / dist
            J[i, 1] = -dy / dist
            J[i, 2] = -1.0
            b[i] = -(dist - r)
        step = np.linalg.lstsq(J, b, rcond)[0]
        cx += step[0]
        cy += step[1]
        r += step[2]
        if max(abs(step[0]), abs(step[1]), abs(step[2])) < 1e-7:
            break
    return cx, cy, r


@njit
def _circle_in_cluster(p, context, idx, inlier, min_r, max_r, refit_rounds, refit_iterations,
                       min_size, min_ratio, max_gap, min_coverage, min_span):
    """RANSAC (the triplets idx drawn) + refit a circle on the points p; accept it only if it
    explains the context points (radius, inlier ratio, angular coverage and continuity,
    no better pair of lines): (found, cx, cy, r)."""
    m = p.shape[0]
    best = -1
    cx = cy = r = 0.0
    for j in range(idx.shape[0]):
        ax, ay = p[idx[j, 0], 0], p[idx[j, 0], 1]
        bx, by = p[idx[j, 1], 0] - ax, p[idx[j, 1], 1] - ay
        ux, uy = p[idx[j, 2], 0] - ax, p[idx[j, 2], 1] - ay  # c - a
        den = 2.0 * (bx * uy - by * ux)
        if not abs(den) > 1e-12:
            continue  # degenerate: radius inf, never valid
        b2, c2 = bx * bx + by * by, ux * ux + uy * uy
        ox = (uy * b2 - by * c2) / den
        oy = (bx * c2 - ux * b2) / den
        radius = math.hypot(ox, oy)
        if not (radius >= min_r and radius <= max_r):
            continue
        ccx, ccy = ox + ax, oy + ay
        count = 0
        for i in range(m):
            if _residual(p[i, 0], p[i, 1], ccx, ccy, radius) <= inlier:
                count += 1
        if count > best:  # np.argmax: the first of the best
            best, cx, cy, r = count, ccx, ccy, radius
    if best < 0:
        return False, 0.0, 0.0, 0.0
    inliers = np.empty(m, np.bool_)
    for i in range(m):
        inliers[i] = _residual(p[i, 0], p[i, 1], cx, cy, r) <= inlier
    for _ in range(refit_rounds):  # refit on inliers, re-select inliers
        if inliers.sum() < 3:
            return False, 0.0, 0.0, 0.0
        cx, cy, r = _fit_circle(p, inliers, cx, cy, r, refit_iterations)
        for i in range(m):
            inliers[i] = _residual(p[i, 0], p[i, 1], cx, cy, r) <= inlier
    if not (np.isfinite(r) and min_r <= r and r <= max_r):
        return False, 0.0, 0.0, 0.0
    nc = context.shape[0]
    on = np.empty(nc, np.bool_)
    k = 0
    for i in range(nc):
        on[i] = _residual(context[i, 0], context[i, 1], cx, cy, r) <= inlier
        k += on[i]
    if k < min_size or k / nc < min_ratio:
        return False, 0.0, 0.0, 0.0
    arc = np.empty((k, 2))
    angles = np.empty(k)
    k = 0
    for i in range(nc):
        if on[i]:
            arc[k, 0] = context[i, 0]
            arc[k, 1] = context[i, 1]
            angles[k] = math.atan2(context[i, 1] - cy, context[i, 0] - cx)
            k += 1
    coverage, span = angular_coverage_and_span(angles, max_gap)
    if coverage < min_coverage or span < min_span:
        return False, 0.0, 0.0, 0.0
    # _angular_order: counter-clockwise from after the largest gap
    order = np.argsort(angles, kind="mergesort")
    big = 0
    big_gap = -np.inf
    for i in range(k):
        a0 = angles[order[i]]
        a1 = angles[order[i + 1]] if i + 1 < k else angles[order[0]] + TWO_PI
        if a1 - a0 > big_gap:
            big, big_gap = i, a1 - a0
    ordered = np.empty((k, 2))
    sq = np.empty(k)
    for i in range(k):
        o = order[(i + big + 1) % k]
        ordered[i, 0] = arc[o, 0]
        ordered[i, 1] = arc[o, 1]
        dx = arc[o, 0] - cx
        dy = arc[o, 1] - cy
        e = math.sqrt(dx * dx + dy * dy) - r
        sq[i] = e * e
    if best_two_line_sse(ordered, 3) <= np.sum(sq):
        return False, 0.0, 0.0, 0.0
    return True, cx, cy, r


@njit
def _clusters(sub, labels, group, n_groups, sizes, draws, iterations, inlier, min_r, max_r, refit_rounds,
              refit_iterations, min_size, min_ratio, max_gap, min_coverage, min_span):
    """_circle_in_cluster for every cluster k with sizes[k] >= 0, in order, each with the
    next block of draws: (centres, radii) of the accepted circles."""
    n_clusters = sizes.shape[0]
    centres = np.empty((n_clusters, 2))
    radii = np.empty(n_clusters)
    found = 0
    block = 0
    for k in range(n_clusters):
        if sizes[k] < 0:
            continue
        work, context = cluster_members(labels, group, n_groups, k)
        idx = draws[block * iterations : (block + 1) * iterations]
        block += 1
        ok, cx, cy, r = _circle_in_cluster(sub[work], sub[context], idx, inlier, min_r, max_r, refit_rounds,
                                           refit_iterations, min_size, min_ratio, max_gap, min_coverage, min_span)
        if ok:
            centres[found, 0] = cx
            centres[found, 1] = cy
            radii[found] = r
            found += 1
    return centres[:found].copy(), radii[:found].copy()


def fit_circles(clusters: CircleClusters | None, settings, rng: np.random.Generator) -> CircleSet:
    """The second half of extract_circles: each cluster's RANSAC fit and tests."""
    s = settings
    if clusters is None:
        return CircleSet.empty()
    # the draws: one block per cluster that is not too wide, in cluster order
    blocks = [rng.integers(0, m, size=(RANSAC_ITERATIONS, 3)) for m in clusters.sizes.tolist() if m >= 0]
    if not blocks:
        return CircleSet.empty()
    draws = np.concatenate(blocks).astype(np.int64)
    centres, radii = _clusters(
        clusters.sub, clusters.labels, clusters.group, clusters.n_groups, clusters.sizes, draws, RANSAC_ITERATIONS,
        INLIER_DISTANCE, s.min_radius, s.max_radius, REFIT_ROUNDS, REFIT_ITERATIONS, MIN_CLUSTER_SIZE,
        MIN_INLIER_RATIO, float(np.deg2rad(MAX_GAP_DEG)), float(np.deg2rad(MIN_COVERAGE_DEG)),
        float(np.deg2rad(MIN_SPAN_DEG)))
    if len(radii) == 0:
        return CircleSet.empty()
    return CircleSet(centres, radii)


def extract_circles(pts: np.ndarray, settings, rng: np.random.Generator) -> CircleSet:
    """Circles of checked points pts (N, 2) (primitives.as_points)."""
    return fit_circles(circle_clusters(pts, settings), settings, rng)
