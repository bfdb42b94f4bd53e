"""Line and circle primitives from 2D wall points (paper 3.1), one implementation for the
BEV and the floorplan.

Lines: seeded region growing. A random unused seed gives, by PCA on its neighbourhood, an
initial line; the line then collects every still-free point within `inlier_distance` of it
that is connected to the seed along the line (no gap longer than `gap`), is refitted by
total least squares and grows again until its support stops changing.

Circles: HDBSCAN clusters; per cluster a 3-point RANSAC circle, a least-squares refit, and
acceptance only if the inliers wrap far enough around the centre (angular coverage)
without long holes (angular continuity), which is what separates a pillar from a wall
fragment or a corner.

Both are compiled (line_growing.py, circle_fitting.py); this module is their entry point.
"""

from __future__ import annotations

import numpy as np

from . import circle_fitting, line_growing
from .config import CircleSettings, LineSettings
from .geometry import CircleSet, LineSet, as_points, grid_subsample

__all__ = ["as_points", "deduplicate_lines", "extract_circles", "extract_lines", "grid_subsample"]


def extract_lines(points, settings: LineSettings, rng: np.random.Generator) -> LineSet:
    """Line segments by seeded region growing; sorted by length, longest first.

    points: (N, 2) metres. Empty input gives an empty set; NaN/inf raise InputError."""
    return line_growing.extract_lines(as_points(points), settings, rng)


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


def extract_circles(points, settings: CircleSettings, rng: np.random.Generator) -> CircleSet:
    """Circles (pillars) in 2D wall points; empty input gives an empty set."""
    return circle_fitting.extract_circles(as_points(points), settings, rng)
