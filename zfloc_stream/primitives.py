"""Line and circle primitives from 2D wall points (paper 3.1), one implementation for the
BEV and the floorplan.

Lines: seeded region growing. A random unused seed gives, by PCA on its neighbourhood, an
initial line; the line then collects every still-free point within `inlier_distance` of it
that is connected to the seed along the line (no gap longer than `gap`), is refitted by
total least squares and grows again until its support stops changing.

Circles: HDBSCAN clusters; per cluster a vectorised 3-point RANSAC circle, a least-squares
refit, and acceptance only if the inliers wrap far enough around the centre (angular
coverage) without long holes (angular continuity), which is what separates a pillar from a
wall fragment or a corner.
"""

from __future__ import annotations

import numpy as np

# scipy.sparse / scipy.spatial / scikit-learn are imported where they are used: together
# about 1.5 s, which a CLI that only reports a bad argument must not pay.
from .config import CircleSettings, LineSettings
from .errors import InputError
from .geometry import CircleSet, LineSet


def as_points(points, name: str = "points") -> np.ndarray:
    """(N, 2) float array of finite points, or InputError naming what is wrong."""
    try:
        p = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be an (N, 2) array of numbers") from None
    if p.size == 0:
        return np.zeros((0, 2))
    if p.ndim != 2 or p.shape[1] != 2:
        raise InputError(f"{name} must have shape (N, 2), got {p.shape}")
    if not np.isfinite(p).all():
        raise InputError(f"{name} contain NaN or inf")
    return p


def grid_subsample(points: np.ndarray, spacing: float) -> np.ndarray:
    """Keep the first point of each spacing x spacing cell (deterministic, order-preserving)."""
    if len(points) == 0 or spacing <= 0:
        return points
    cells = np.floor(points / spacing).astype(np.int64)
    _, first = np.unique(cells, axis=0, return_index=True)
    return points[np.sort(first)]


# --------------------------------------------------------------------------------------
# Lines
# --------------------------------------------------------------------------------------


def _pca_line(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid and unit direction of the total-least-squares line through p."""
    c = p.sum(axis=0) / len(p)
    q = p - c
    cov = q.T @ q
    # Closed-form principal direction of a symmetric 2x2 matrix (faster than eigh here).
    angle = 0.5 * np.arctan2(2.0 * cov[0, 1], cov[0, 0] - cov[1, 1])
    return c, np.array([np.cos(angle), np.sin(angle)])


def _canonical(c: np.ndarray, direction: np.ndarray, t_lo: float, t_hi: float):
    """Normal form + ordered endpoints; direction points into the upper half plane so the
    same wall gives the same parameters whichever way it was grown."""
    if direction[1] < 0 or (direction[1] == 0 and direction[0] < 0):
        direction, t_lo, t_hi = -direction, -t_hi, -t_lo
    normal = np.array([-direction[1], direction[0]])
    ends = np.stack([c + t_lo * direction, c + t_hi * direction])
    return normal, -float(normal @ c), ends


def _connected_run(t: np.ndarray, t_ref: float, gap: float) -> np.ndarray | None:
    """Indices into t of the run of values (consecutive spacing <= gap) holding the value
    nearest t_ref, or None if that value is farther than gap from t_ref."""
    order = np.argsort(t, kind="stable")
    ts = t[order]
    n = len(ts)
    k = int(np.searchsorted(ts, t_ref))
    i = 0 if k == 0 else n - 1 if k == n else (k - 1 if t_ref - ts[k - 1] <= ts[k] - t_ref else k)
    if abs(ts[i] - t_ref) > gap:
        return None
    breaks = np.flatnonzero(np.diff(ts) > gap)  # a run ends at each break index
    j = int(np.searchsorted(breaks, i))  # runs before i's run
    lo = breaks[j - 1] + 1 if j > 0 else 0
    hi = breaks[j] if j < len(breaks) else n - 1
    return order[lo : hi + 1]


def extract_lines(points, settings: LineSettings, rng: np.random.Generator, kernels: str = "numpy") -> LineSet:
    """Line segments by seeded region growing; sorted by length, longest first.

    points: (N, 2) metres. Empty input gives an empty set; NaN/inf raise InputError.
    kernels="numba": the compiled seed loop (primitives_numba: the same lines, the same
    random numbers; coordinates may differ in the last bits, see there).
    """
    pts = as_points(points)
    if kernels == "numba":
        from .primitives_numba import extract_lines as compiled

        return compiled(pts, settings, rng)
    from scipy.spatial import cKDTree

    n = len(pts)
    if n < max(settings.min_points, 2):
        return LineSet.empty()
    tree = cKDTree(pts)
    taken = np.zeros(n, dtype=bool)  # owned by an accepted line
    tried = np.zeros(n, dtype=bool)  # used as a seed (so every seed is tried once)
    pool = np.arange(n)  # indices of points not taken; compacted after each accepted line
    pool_pts = pts
    found = []
    for seed in rng.permutation(n).tolist():
        if taken[seed] or tried[seed]:
            continue
        tried[seed] = True
        neigh = np.asarray(tree.query_ball_point(pts[seed], settings.neighbourhood_radius, return_sorted=False), dtype=np.int64)
        neigh = neigh[~taken[neigh]]
        if len(neigh) < settings.min_seed_neighbours:
            continue  # isolated point: noise
        # Grow inside a local window first: most seeds end there (short fragments, noise)
        # and a window is far cheaper than scanning every free point. Only a line that
        # reaches the window's rim regrows over all free points.
        window = np.asarray(tree.query_ball_point(pts[seed], settings.local_radius, return_sorted=False), dtype=np.int64)
        window = window[~taken[window]]
        rim = settings.local_radius - settings.gap
        support = _grow(pts[window], pts[neigh], pts[seed], settings, rim)
        if support is not None:
            members = window[support]
            if np.max(np.sum((pts[members] - pts[seed]) ** 2, axis=1)) > rim * rim:
                support = _grow(pool_pts, pts[members], pts[seed], settings)
                members = None if support is None else pool[support]
        if support is None:
            tried[neigh] = True  # nothing grows here: its neighbours would fail the same way
            continue
        c, direction = _pca_line(pts[members])
        t = (pts[members] - c) @ direction
        if len(members) < settings.min_points or t.max() - t.min() < settings.min_length:
            # A fragment: neither its points nor the seed's neighbours need to seed again
            # (they stay free, so a line grown elsewhere may still absorb them).
            tried[members] = True
            tried[neigh] = True
            continue
        found.append((*_canonical(c, direction, t.min(), t.max()), len(members)))
        taken[members] = True
        keep = ~taken[pool]
        pool, pool_pts = pool[keep], pool_pts[keep]
    if not found:
        return LineSet.empty()
    normals, offsets, ends, support = (np.array(v) for v in zip(*found))
    lines = LineSet(normals.reshape(-1, 2), offsets.astype(float), ends.reshape(-1, 2, 2), support.astype(int))
    return lines.subset(np.argsort(-lines.lengths, kind="stable"))


def _grow(pool_pts, initial: np.ndarray, seed_pt: np.ndarray, settings: LineSettings, rim: float | None = None):
    """Indices into pool_pts of the converged support of the line grown from the points
    `initial`, anchored at seed_pt (the run of collinear points nearest the seed).

    Converged: the support stopped changing, or the refit moved the line by less than
    converge_tolerance over the support's extent (the next round would select the same
    points, so it is skipped). With `rim`, growth also stops, unconverged, as soon as the
    support reaches farther than rim from the seed (the caller regrows it more widely)."""
    c, direction = _pca_line(initial)
    previous = None
    for _ in range(settings.max_grow_iterations):
        normal = np.array([-direction[1], direction[0]])
        cand = np.flatnonzero(np.abs(pool_pts @ normal - c @ normal) <= settings.inlier_distance)
        if len(cand) < 2:
            return None
        t = pool_pts[cand] @ direction - c @ direction
        t_seed = float((seed_pt - c) @ direction)
        run = _connected_run(t, t_seed, settings.gap)
        if run is None or len(run) < 2:
            return None
        support = np.sort(cand[run])
        if previous is not None and len(support) == len(previous) and np.array_equal(support, previous):
            break
        previous = support
        t_lo, t_hi = t[run].min(), t[run].max()
        if rim is not None and max(t_seed - t_lo, t_hi - t_seed) > rim:
            break
        new_c, new_direction = _pca_line(pool_pts[support])
        # Largest displacement of the line over the support's extent after the refit.
        shift = abs(float((new_c - c) @ normal)) + 0.5 * (t_hi - t_lo) * abs(float(new_direction @ normal))
        c, direction = new_c, new_direction
        if shift < settings.converge_tolerance:
            break
    return previous


def deduplicate_lines(lines: LineSet, settings: LineSettings) -> LineSet:
    """Drop lines that repeat a longer one: nearly parallel (< dedup_angle_deg), nearly the
    same offset (the shorter one's midpoint within dedup_offset of the longer line) and
    overlapping extents. Order (longest first) is kept."""
    m = len(lines)
    if m < 2:
        return lines
    order = np.argsort(-lines.lengths, kind="stable")
    L = lines.subset(order)
    d = L.endpoints[:, 1] - L.endpoints[:, 0]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    cos = np.abs(d @ d.T)
    parallel = cos >= np.cos(np.deg2rad(settings.dedup_angle_deg))
    mid = L.midpoints
    # offset[i, j]: distance of j's midpoint to line i
    offset = np.abs(mid @ L.normals.T + L.offsets[None, :]).T
    close = offset < settings.dedup_offset
    # extents of j projected on i's direction overlap i's extent
    t_i0 = np.einsum("ij,ij->i", L.endpoints[:, 0], d)
    t_i1 = np.einsum("ij,ij->i", L.endpoints[:, 1], d)
    pj0 = L.endpoints[:, 0] @ d.T  # [j, i]
    pj1 = L.endpoints[:, 1] @ d.T
    lo_j, hi_j = np.minimum(pj0, pj1).T, np.maximum(pj0, pj1).T  # [i, j]
    lo_i, hi_i = np.minimum(t_i0, t_i1)[:, None], np.maximum(t_i0, t_i1)[:, None]
    overlap = (np.minimum(hi_i, hi_j) - np.maximum(lo_i, lo_j)) > 0
    dup = parallel & close & overlap
    np.fill_diagonal(dup, False)
    keep = np.ones(m, dtype=bool)
    for i in range(m):  # greedy from the longest: a kept line suppresses its shorter repeats
        if keep[i]:
            later = dup[i].copy()
            later[: i + 1] = False
            keep &= ~later
    return L.subset(np.flatnonzero(keep))


# --------------------------------------------------------------------------------------
# Circles
# --------------------------------------------------------------------------------------


def _circles_through(a: np.ndarray, b: np.ndarray, c: np.ndarray):
    """Circumcircles of K triangles (K, 2) each; degenerate triangles get radius inf."""
    bx, by = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    cx, cy = c[:, 0] - a[:, 0], c[:, 1] - a[:, 1]
    den = 2.0 * (bx * cy - by * cx)
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    b2, c2 = bx * bx + by * by, cx * cx + cy * cy
    ux = (cy * b2 - by * c2) / den
    uy = (bx * c2 - cx * b2) / den
    centres = np.stack([ux + a[:, 0], uy + a[:, 1]], axis=1)
    radii = np.where(ok, np.hypot(ux, uy), np.inf)
    return centres, radii


def _fit_circle(p: np.ndarray, centre: np.ndarray, radius: float, iterations: int):
    """Geometric least-squares circle (Gauss-Newton on |p - c| - r), from a start."""
    c, r = centre.astype(float).copy(), float(radius)
    for _ in range(iterations):
        diff = p - c
        dist = np.maximum(np.linalg.norm(diff, axis=1), 1e-12)
        res = dist - r
        J = np.column_stack([-diff / dist[:, None], -np.ones(len(p))])
        step, *_ = np.linalg.lstsq(J, -res, rcond=None)
        c += step[:2]
        r += step[2]
        if np.abs(step).max() < 1e-7:
            break
    return c, r


def angular_coverage_and_span(angles: np.ndarray, max_gap: float) -> tuple[float, float]:
    """(2*pi minus the largest gap between consecutive angles, longest contiguous span whose
    consecutive gaps are all < max_gap), both in radians."""
    if len(angles) < 2:
        return 0.0, 0.0
    a = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * np.pi]]))  # gaps[i]: a[i] -> a[i+1] (cyclic)
    coverage = 2 * np.pi - gaps.max()
    small = gaps < max_gap
    if small.all():
        return coverage, 2 * np.pi
    # Longest cyclic run of small gaps: rotate so the sequence starts after a big gap.
    start = int(np.argmin(small)) + 1
    g = np.roll(gaps, -start)
    s = np.roll(small, -start)
    cum = np.concatenate([[0.0], np.cumsum(np.where(s, g, 0.0))])
    big = np.flatnonzero(~s)
    bounds = np.concatenate([[-1], big, [len(s)]])
    span = 0.0
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        span = max(span, cum[hi] - cum[lo + 1] if hi > lo + 1 else 0.0)
    return coverage, span


def _candidate_groups(pts: np.ndarray, settings: CircleSettings) -> tuple[np.ndarray, np.ndarray]:
    """(indices, group labels) of the points in spatially separated groups small enough to
    be a pillar.

    Groups are connected components at link distance `group_link_distance`; a group wider
    than a pillar of max_radius (a wall, a room) cannot hold an isolated circle, so it is
    dropped before HDBSCAN, which keeps clustering cheap on large BEVs and floorplans.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    n = len(pts)
    pairs = cKDTree(pts).query_pairs(settings.group_link_distance, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    lo = np.full((label.max() + 1, 2), np.inf)
    hi = np.full((label.max() + 1, 2), -np.inf)
    np.minimum.at(lo, label, pts)
    np.maximum.at(hi, label, pts)
    count = np.bincount(label)
    width = (hi - lo).max(axis=1)
    small = (width <= 2 * settings.max_radius + 2 * settings.inlier_distance) & (count >= settings.min_cluster_size)
    keep = np.flatnonzero(small[label])
    return keep, label[keep]


def extract_circles(points, settings: CircleSettings, rng: np.random.Generator, kernels: str = "numpy") -> CircleSet:
    """Circles (pillars) in 2D wall points; empty input gives an empty set.

    kernels="numba": the group filter and the per-cluster fits compiled (circles_numba:
    the same circles from the same random numbers; HDBSCAN is the same sklearn call)."""
    pts = as_points(points)
    if kernels == "numba":
        from .circles_numba import extract_circles as compiled

        return compiled(pts, settings, rng)
    if len(pts) < settings.min_cluster_size:
        return CircleSet.empty()
    keep, group = _candidate_groups(pts, settings)
    if len(keep) < settings.min_cluster_size:
        return CircleSet.empty()
    from sklearn.cluster import HDBSCAN

    sub = pts[keep]
    # allow_single_cluster: after the group filter one pillar may be all that is left.
    labels = HDBSCAN(
        min_cluster_size=settings.min_cluster_size,
        min_samples=settings.hdbscan_min_samples,
        allow_single_cluster=True,
        copy=True,
    ).fit_predict(sub)
    centres, radii = [], []
    for k in range(labels.max() + 1):
        in_cluster = labels == k
        cluster = sub[in_cluster]
        width = (cluster.max(axis=0) - cluster.min(axis=0)).max()
        if width > 2 * settings.max_radius + 2 * settings.inlier_distance:
            continue
        # The circle is judged against the whole isolated structure the cluster belongs
        # to: HDBSCAN may cut the rounded-looking corner out of an L-shaped wall piece, and
        # only the rest of that piece shows it is not a pillar.
        in_groups = np.isin(group, np.unique(group[in_cluster]))
        context = sub[in_groups]
        # HDBSCAN calls the sparse part of a short arc noise; those points still belong to
        # the pillar, so the fit sees the cluster plus the noise of its own groups.
        work = sub[in_cluster | (in_groups & (labels < 0))]
        circle = _circle_in_cluster(work, context, settings, rng)
        if circle is not None:
            centres.append(circle[0])
            radii.append(circle[1])
    if not radii:
        return CircleSet.empty()
    return CircleSet(np.array(centres), np.array(radii))


def _circle_in_cluster(p: np.ndarray, context: np.ndarray, s: CircleSettings, rng: np.random.Generator):
    """RANSAC + refit a circle on the points p; accept it only if it explains the
    context points (radius, inlier ratio, angular coverage and continuity)."""
    m = len(p)
    idx = rng.integers(0, m, size=(s.ransac_iterations, 3))
    centres, radii = _circles_through(p[idx[:, 0]], p[idx[:, 1]], p[idx[:, 2]])
    valid = (radii >= s.min_radius) & (radii <= s.max_radius)
    if not valid.any():
        return None
    centres, radii = centres[valid], radii[valid]
    residual = np.abs(np.linalg.norm(p[None, :, :] - centres[:, None, :], axis=2) - radii[:, None])
    best = int(np.argmax((residual <= s.inlier_distance).sum(axis=1)))
    c, r = centres[best], radii[best]
    inliers = residual[best] <= s.inlier_distance
    for _ in range(s.refit_rounds):  # refit on inliers, re-select inliers
        if inliers.sum() < 3:
            return None
        c, r = _fit_circle(p[inliers], c, r, s.refit_iterations)
        inliers = np.abs(np.linalg.norm(p - c, axis=1) - r) <= s.inlier_distance
    if not (np.isfinite(r) and s.min_radius <= r <= s.max_radius):
        return None
    on_circle = np.abs(np.linalg.norm(context - c, axis=1) - r) <= s.inlier_distance
    if on_circle.sum() < s.min_cluster_size or on_circle.mean() < s.min_inlier_ratio:
        return None
    q = context[on_circle] - c
    angles = np.arctan2(q[:, 1], q[:, 0])
    coverage, span = angular_coverage_and_span(angles, np.deg2rad(s.max_gap_deg))
    if coverage < np.deg2rad(s.min_coverage_deg) or span < np.deg2rad(s.min_span_deg):
        return None
    # A corner (two straight legs) can hug a circle within the inlier band; a pillar
    # cannot be followed by two straight pieces. Reject when two lines fit the arc's
    # points, taken in angular order, at least as well as the circle does.
    arc_pts = context[on_circle][_angular_order(angles)]
    circle_sse = float(np.sum((np.linalg.norm(arc_pts - c, axis=1) - r) ** 2))
    if _best_two_line_sse(arc_pts) <= circle_sse:
        return None
    return c, r


def _angular_order(angles: np.ndarray) -> np.ndarray:
    """Order of the angles read counter-clockwise starting after their largest gap, so an
    open arc is one unbroken sequence."""
    order = np.argsort(angles)
    a = angles[order]
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * np.pi]]))
    return np.roll(order, -(int(np.argmax(gaps)) + 1))


def _best_two_line_sse(p: np.ndarray, min_part: int = 3) -> float:
    """Smallest total squared orthogonal residual of two lines fitted to a prefix and the
    remaining suffix of the ordered points p (all split points at once via cumulative sums)."""
    n = len(p)
    if n < 2 * min_part:
        return np.inf
    q = p - p.mean(axis=0)  # centred: keeps the cumulative sums well conditioned
    x, y = q[:, 0], q[:, 1]
    terms = np.stack([np.ones(n), x, y, x * x, x * y, y * y], axis=1)
    total = terms.sum(axis=0)
    prefix = np.cumsum(terms, axis=0)[min_part - 1 : n - min_part]  # prefix of k points, k = min_part .. n - min_part
    suffix = total - prefix

    def sse(m):
        cnt, sx, sy, sxx, sxy, syy = m.T
        a = sxx - sx * sx / cnt
        b = sxy - sx * sy / cnt
        d = syy - sy * sy / cnt
        return np.maximum(0.5 * (a + d) - np.sqrt(0.25 * (a - d) ** 2 + b * b), 0.0)

    return float(np.min(sse(prefix) + sse(suffix)))
