"""The BEV observation's grid passes, compiled (BevSnapshot.observation).

The wall test, the known cells' extent, the crop's free and occupied masks and the wall
points (row-major) in two passes, the clearance in a third around OpenCV's exact distance
transform: no full-grid temporaries. A float32 grid is compared with its threshold rounded
to float32; the clearance is float64 sqrt(rint(d * d)) of the float32 transform, which is
the exact Euclidean distance in cells while d * d < 2^22 (2,048 cells, 102 m at 5 cm).
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.numba_support import njit


@njit
def _is_wall(w, h, lo, min_obs, ratio, occupied):
    """bev.wall_cells for one cell (w, h uint16, lo float32, occupied a float32): a wall cell."""
    return w >= min_obs and w >= ratio * np.float64(h) and lo > occupied


@njit
def known_extent(logodds, wall, hits, seen, min_obs, ratio, occupied, use_recent, oldest):
    """(any wall cell, first row, last row, first col, last col) of the known cells
    (logodds != 0 or wall > 0; with use_recent only cells with seen > oldest count, for
    both). The extent is (0, -1, 0, -1) when nothing is known."""
    n, m = logodds.shape
    any_wall = False
    r0, r1, c0, c1 = n, -1, m, -1
    for r in range(n):
        for c in range(m):
            if use_recent and not seen[r, c] > oldest:
                continue
            lo = logodds[r, c]
            w = wall[r, c]
            if lo != 0 or w > 0:
                r0 = min(r0, r)
                r1 = max(r1, r)
                c0 = min(c0, c)
                c1 = max(c1, c)
                if not any_wall and _is_wall(w, hits[r, c], lo, min_obs, ratio, occupied):
                    any_wall = True
    if r1 < 0:
        return any_wall, 0, -1, 0, -1
    return any_wall, r0, r1, c0, c1


@njit
def crop_masks(logodds, wall, hits, seen, r0, r1, c0, c1, min_obs, ratio, occupied, free_threshold,
               use_recent, oldest, x0, y0, resolution):
    """On the crop [r0:r1, c0:c1]: free (bool), not_occupied (uint8 0/1, the distance
    transform's input) and the wall points (cell centres, row-major as np.nonzero) at
    origin (x0, y0): origin + (col + 0.5, row + 0.5) * resolution."""
    h, w = r1 - r0, c1 - c0
    free = np.empty((h, w), np.bool_)
    not_occupied = np.empty((h, w), np.uint8)
    points = np.empty((h * w, 2))
    k = 0
    for i in range(h):
        for j in range(w):
            r, c = r0 + i, c0 + j
            lo = logodds[r, c]
            recent = (not use_recent) or seen[r, c] > oldest
            is_wall = recent and _is_wall(wall[r, c], hits[r, c], lo, min_obs, ratio, occupied)
            free[i, j] = recent and lo < free_threshold
            not_occupied[i, j] = 0 if recent and (lo > occupied or is_wall) else 1
            if is_wall:
                points[k, 0] = x0 + (np.float64(j) + 0.5) * resolution
                points[k, 1] = y0 + (np.float64(i) + 0.5) * resolution
                k += 1
    return free, not_occupied, points[:k].copy()


@njit
def clearance(distance, free, resolution):
    """np.where(free, sqrt(rint(d * d)) * resolution, 0.0) with d the float32 distance
    transform widened to float64 (see the module docstring)."""
    h, w = distance.shape
    out = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            if free[i, j]:
                d = np.float64(distance[i, j])
                out[i, j] = math.sqrt(np.rint(d * d)) * resolution
            else:
                out[i, j] = 0.0
    return out
