"""The deterministic half of the circle (pillar) extraction (circle_fitting.py): the points
linked into groups (cKDTree.query_pairs, then union-find, compiled), the groups no wider
than a pillar (a group wider than a pillar of max_radius, a wall or a room, cannot hold an
isolated circle, so it is dropped before HDBSCAN, which keeps clustering cheap), sklearn's
HDBSCAN clusters of what is left, and each cluster's work points and context. It takes no
random numbers."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..runtime.numba_support import njit

# Which wall points may form a pillar (were primitives.circles.*; every recorded result used
# these: the replay samples, eval_real, the benchmark scenes). Sized for 0.05 m cells and
# pillars of primitives.circles.min_radius to max_radius (what a user sets: the pillars
# their building has).
GROUP_LINK_DISTANCE = 0.15  # m, points closer than this are one group (3 cells: a ring's gaps at 0.05 m cells link)
MIN_CLUSTER_SIZE = 10  # points of a cluster (and of a group), below which no circle is fitted
HDBSCAN_MIN_SAMPLES = 2  # small: a thin pillar ring has few points per neighbourhood (larger values drop arc points as noise)
INLIER_DISTANCE = 0.03  # m, radial distance of a RANSAC / refit inlier (a group may be this much wider than a pillar)


@njit
def _root(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]  # path halving
        i = parent[i]
    return i


@njit
def link_groups(pts, pairs, max_width, min_size):
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
def cluster_members(labels, group, n_groups, k):
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
def work_sizes(sub, labels, group, n_groups, n_clusters, max_width):
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
        work, _ = cluster_members(labels, group, n_groups, k)
        sizes[k] = work.shape[0]
    return sizes


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
    keep, group = link_groups(pts, pairs.reshape(-1, 2), max_width, MIN_CLUSTER_SIZE)
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
    sizes = work_sizes(sub, labels, group, n_groups, n_clusters, max_width)
    return CircleClusters(sub, labels, group, n_groups, sizes)
