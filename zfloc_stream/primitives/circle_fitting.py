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

Determinism: fixed operation orders, so the same circles bit for bit on one machine;
elsewhere libm's atan2 or LAPACK may round differently in the last bits, which moves a
centre by ~1e-12 m and changes a decision only for an angle within rounding of a threshold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry.shapes import CircleSet
from ..runtime.numba_support import njit

_TWO_PI = 2 * np.pi
_EPS = float(np.finfo(np.float64).eps)

# What makes a cluster of wall points a pillar (were primitives.circles.*; every recorded
# result used these: the replay samples, eval_real, the benchmark scenes). Sized for 0.05 m cells and pillars of primitives.circles.min_radius to
# max_radius (the settings a user sets: the pillars their building has); the tests below
# are what separates a pillar from a wall fragment or a corner, not a matter of taste.
GROUP_LINK_DISTANCE = 0.15  # m, points closer than this are one group (3 cells: a ring's gaps at 0.05 m cells link)
MIN_CLUSTER_SIZE = 10  # points of a cluster (and of a group), below which no circle is fitted
HDBSCAN_MIN_SAMPLES = 2  # small: a thin pillar ring has few points per neighbourhood (larger values drop arc points as noise)
RANSAC_ITERATIONS = 100  # 3-point circle hypotheses per cluster
INLIER_DISTANCE = 0.03  # m, radial distance of a RANSAC / refit inlier
REFIT_ROUNDS = 2  # least-squares refit + inlier re-selection rounds
REFIT_ITERATIONS = 10  # Gauss-Newton steps per refit (converges in a few from a RANSAC circle)
MIN_INLIER_RATIO = 0.8  # of the cluster's points on the circle: a pillar's cluster is its ring, a wall's is not
MIN_COVERAGE_DEG = 120.0  # 360 deg minus the largest angular gap: the inliers wrap at least a third of the way round
MAX_GAP_DEG = 30.0  # angular continuity: consecutive gaps below this...
MIN_SPAN_DEG = 90.0  # ...over a contiguous span at least this long (a corner's two lines leave a long hole)


@njit
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit
def _groups(pts, pairs, max_width, min_size):
    """(keep, group): keep the indices of the points in groups (connected components of the
    link pairs) no wider than max_width and holding at least min_size points, in index
    order, and group their component labels (0..G-1 in order of first appearance)."""
    n = pts.shape[0]
    parent = np.arange(n)
    for k in range(pairs.shape[0]):
        a = _root(parent, pairs[k, 0])
        b = _root(parent, pairs[k, 1])
        if a != b:
            parent[max(a, b)] = min(a, b)
    label = np.full(n, -1, np.int64)
    count = np.zeros(n, np.int64)
    lo = np.empty((n, 2))
    hi = np.empty((n, 2))
    g = 0
    for i in range(n):
        r = _root(parent, i)
        if label[r] < 0:
            label[r] = g
            lo[g, 0] = hi[g, 0] = pts[i, 0]
            lo[g, 1] = hi[g, 1] = pts[i, 1]
            g += 1
        k = label[r]
        label[i] = k
        count[k] += 1
        for j in range(2):
            lo[k, j] = min(lo[k, j], pts[i, j])
            hi[k, j] = max(hi[k, j], pts[i, j])
    small = np.empty(g, np.bool_)
    for k in range(g):
        small[k] = max(hi[k, 0] - lo[k, 0], hi[k, 1] - lo[k, 1]) <= max_width and count[k] >= min_size
    m = 0
    for i in range(n):
        if small[label[i]]:
            m += 1
    keep = np.empty(m, np.int64)
    group = np.empty(m, np.int64)
    m = 0
    for i in range(n):
        if small[label[i]]:
            keep[m] = i
            group[m] = label[i]
            m += 1
    return keep, group


@njit
def _members(labels, group, n_groups, k):
    """(work, context) row indices of cluster k, as extract_circles selects them: the
    context is every point of the groups the cluster touches, the work the cluster plus
    the HDBSCAN noise of those groups."""
    touched = np.zeros(n_groups, np.bool_)
    for i in range(labels.shape[0]):
        if labels[i] == k:
            touched[group[i]] = True
    nw = 0
    nc = 0
    for i in range(labels.shape[0]):
        if touched[group[i]]:
            nc += 1
            if labels[i] == k or labels[i] < 0:
                nw += 1
    work = np.empty(nw, np.int64)
    context = np.empty(nc, np.int64)
    nw = 0
    nc = 0
    for i in range(labels.shape[0]):
        if touched[group[i]]:
            context[nc] = i
            nc += 1
            if labels[i] == k or labels[i] < 0:
                work[nw] = i
                nw += 1
    return work, context


@njit
def _work_sizes(sub, labels, group, n_groups, n_clusters, max_width):
    """Per cluster the number of work points its RANSAC draws from, or -1 for a cluster
    wider than max_width (skipped without drawing)."""
    sizes = np.full(n_clusters, -1, np.int64)
    for k in range(n_clusters):
        lo0 = lo1 = np.inf
        hi0 = hi1 = -np.inf
        for i in range(labels.shape[0]):
            if labels[i] == k:
                lo0 = min(lo0, sub[i, 0])
                hi0 = max(hi0, sub[i, 0])
                lo1 = min(lo1, sub[i, 1])
                hi1 = max(hi1, sub[i, 1])
        if max(hi0 - lo0, hi1 - lo1) > max_width:
            continue
        work, _ = _members(labels, group, n_groups, k)
        sizes[k] = work.shape[0]
    return sizes


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
def angular_coverage_and_span(angles, max_gap):
    """(2*pi minus the largest gap between consecutive angles, longest contiguous span whose
    consecutive gaps are all < max_gap), both in radians (angles taken mod 2*pi)."""
    n = angles.shape[0]
    if n < 2:
        return 0.0, 0.0
    a = np.empty(n)
    for i in range(n):
        m = np.fmod(angles[i], _TWO_PI)  # npy_divmod with a positive divisor:
        a[i] = m + _TWO_PI if m < 0 else (m if m != 0.0 else 0.0)  # sign of the divisor, zero as +0
    a = np.sort(a)
    gaps = np.empty(n)
    for i in range(n - 1):
        gaps[i] = a[i + 1] - a[i]
    gaps[n - 1] = (a[0] + _TWO_PI) - a[n - 1]
    coverage = _TWO_PI - gaps.max()
    start = -1
    for i in range(n):
        if not gaps[i] < max_gap:
            start = i + 1
            break
    if start < 0:
        return coverage, _TWO_PI
    cum = np.empty(n + 1)
    cum[0] = 0.0
    small = np.empty(n, np.bool_)
    acc = 0.0
    for i in range(n):
        g = gaps[(i + start) % n]
        small[i] = g < max_gap
        acc += g if small[i] else 0.0
        cum[i + 1] = acc
    span = 0.0
    lo = -1
    for hi in range(n + 1):
        if hi == n or not small[hi]:
            span = max(span, cum[hi] - cum[lo + 1] if hi > lo + 1 else 0.0)
            lo = hi
    return coverage, span


@njit
def _best_two_line_sse(p, min_part):
    """Smallest total squared orthogonal residual of two lines fitted to a prefix and the
    remaining suffix of the ordered points p (every split point, by cumulative sums)."""
    n = p.shape[0]
    if n < 2 * min_part:
        return np.inf
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += p[i, 0]
        my += p[i, 1]
    mx /= n
    my /= n
    terms = np.empty((n, 6))
    total = np.zeros(6)
    for i in range(n):
        x = p[i, 0] - mx
        y = p[i, 1] - my
        terms[i, 0] = 1.0
        terms[i, 1] = x
        terms[i, 2] = y
        terms[i, 3] = x * x
        terms[i, 4] = x * y
        terms[i, 5] = y * y
        for j in range(6):
            total[j] += terms[i, j]
    best = np.inf
    prefix = np.zeros(6)
    suffix = np.empty(6)
    for k in range(n - min_part):  # prefix of k + 1 points
        for j in range(6):
            prefix[j] += terms[k, j]
        if k < min_part - 1:
            continue
        for j in range(6):
            suffix[j] = total[j] - prefix[j]
        value = _line_sse(prefix) + _line_sse(suffix)
        if value < best or k == min_part - 1:
            best = value
    return best


@njit
def _line_sse(m):
    cnt, sx, sy, sxx, sxy, syy = m[0], m[1], m[2], m[3], m[4], m[5]
    a = sxx - sx * sx / cnt
    b = sxy - sx * sy / cnt
    d = syy - sy * sy / cnt
    return max(0.5 * (a + d) - math.sqrt(0.25 * ((a - d) * (a - d)) + b * b), 0.0)


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
        a1 = angles[order[i + 1]] if i + 1 < k else angles[order[0]] + _TWO_PI
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
    if _best_two_line_sse(ordered, 3) <= np.sum(sq):
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
        work, context = _members(labels, group, n_groups, k)
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


@dataclass(frozen=True)
class CircleClusters:
    """What extract_circles finds before it takes a random number: the candidate points,
    their HDBSCAN labels and groups, and each cluster's RANSAC work size (-1: too wide)."""

    sub: np.ndarray
    labels: np.ndarray
    group: np.ndarray
    n_groups: int
    sizes: np.ndarray


def circle_clusters(pts: np.ndarray, settings) -> CircleClusters | None:
    """The first, deterministic half of extract_circles (group filter, HDBSCAN): None when
    no cluster is left. It takes no random numbers, so it can run beside the line
    extraction, whose draws come first (frontend/bev.py)."""
    s = settings
    if len(pts) < MIN_CLUSTER_SIZE:
        return None
    # here, not at import: scipy.spatial and scikit-learn cost ~1 s to import
    import sklearn
    from scipy.spatial import cKDTree
    from sklearn.cluster import HDBSCAN

    pts = np.ascontiguousarray(pts, dtype=np.float64)
    max_width = 2 * s.max_radius + 2 * INLIER_DISTANCE
    pairs = cKDTree(pts).query_pairs(GROUP_LINK_DISTANCE, output_type="ndarray").astype(np.int64)
    keep, group = _groups(pts, pairs.reshape(-1, 2), max_width, MIN_CLUSTER_SIZE)
    if len(keep) < MIN_CLUSTER_SIZE:
        return None
    sub = pts[keep]
    # sklearn's own switch (thread-local) skips re-validating parameters the settings
    # already validated: ~0.3 ms a call, the same labels
    with sklearn.config_context(skip_parameter_validation=True):
        labels = HDBSCAN(
            min_cluster_size=MIN_CLUSTER_SIZE,
            min_samples=HDBSCAN_MIN_SAMPLES,
            allow_single_cluster=True,
            copy=True,
        ).fit_predict(sub).astype(np.int64)
    n_clusters = int(labels.max()) + 1
    if n_clusters <= 0:
        return None
    n_groups = int(group.max()) + 1
    sizes = _work_sizes(sub, labels, group, n_groups, n_clusters, max_width)
    return CircleClusters(sub, labels, group, n_groups, sizes)


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
