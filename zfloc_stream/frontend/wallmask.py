"""Gravity-aligned wall-mask refinement (paper 3.1, eqs. 1-5).

In an upright (gravity-aligned) image every column is a vertical plane through the camera
centre, so a vertical wall shows one depth per column. A column is dropped when any
non-wall pixel lies deeper than the column's median wall depth + TAU_D (the "wall" is then
furniture, or the column looks through a door: doors stay free); otherwise only the
farthest depth-separated wall segment of the column is kept.

Convention (consistent with ours, the paper writes the transpose): R_up_cam maps camera
coordinates to the upright camera, X_up = R_up_cam X_cam, so the warp is
p_hat = K R_up_cam K^-1 p and the gravity-aligned depth is d_hat = [R_up_cam K^-1 p d]_z.
The upright camera keeps the camera's heading: y = gravity (down), z = optical axis
projected onto the horizontal plane.
"""

from __future__ import annotations

import numpy as np

from ..settings.loading import WallMaskSettings
from ..frames import WALL
from ..runtime.numba_support import njit

# The filter's thresholds (were frontend.wall_mask.*; the setting left is `enabled`). Every
# recorded result used these: the replay samples' camera runs, eval_real's camera windows,
# the benchmark scenes; the paper gives tau_d, not its value.
TAU_D = 0.3  # m, a non-wall pixel deeper than the column's median wall depth + this drops the column (eqs. 3, 4)
SEGMENT_GAP = 0.1  # m, a depth gap that splits a column's wall pixels into segments...
SEGMENT_GAP_PER_M = 0.01  # ...plus this much per metre of depth (a depth camera's noise grows with depth)
MIN_FORWARD_DEPTH = 0.05  # m, points closer than this to the upright image plane are not warped (the warp divides by it)


def upright_rotation(R_odom_cam: np.ndarray, gravity_odom: np.ndarray) -> np.ndarray:
    """R_up_cam: camera -> upright camera (same heading, y along gravity)."""
    g = np.asarray(R_odom_cam, dtype=float).T @ np.asarray(gravity_odom, dtype=float)
    g /= np.linalg.norm(g)
    z = np.array([0.0, 0.0, 1.0]) - g[2] * g  # optical axis, horizontal part
    if np.linalg.norm(z) < 1e-6:  # looking straight up/down: heading from the image's -y
        z = np.array([0.0, -1.0, 0.0]) - g[1] * g
    z /= np.linalg.norm(z)
    x = np.cross(g, z)
    return np.stack([x, g, z])  # rows: upright axes in camera coordinates


def refine_wall_mask(
    depth: np.ndarray,
    labels: np.ndarray,
    K: np.ndarray,
    R_up_cam: np.ndarray,
    settings: WallMaskSettings,
) -> np.ndarray:
    """Refined wall mask (H, W) bool in the ORIGINAL image.

    depth: HxW metres (0 / NaN = none); labels: HxW codes (frames.WALL is wall, any other
    code with a depth reading is "non-wall"); K: intrinsics of this image; R_up_cam from
    `upright_rotation`.
    """
    h, w = depth.shape
    wall = labels == WALL
    valid = np.isfinite(depth) & (depth > 0)
    if not settings.enabled:
        return wall & valid
    rows, cols = np.nonzero(valid)
    rays = np.stack([cols + 0.0, rows + 0.0, np.ones(len(rows))], axis=1) @ np.linalg.inv(K).T
    keep = refine_wall_points(rays, depth[rows, cols].astype(float), wall[rows, cols], K, R_up_cam, settings)
    out = np.zeros((h, w), dtype=bool)
    out[rows[keep], cols[keep]] = True
    return out


def refine_wall_points(
    rays: np.ndarray,
    depth: np.ndarray,
    is_wall: np.ndarray,
    K: np.ndarray,
    R_up_cam: np.ndarray,
    settings: WallMaskSettings,
) -> np.ndarray:
    """The same filter on a flat list of valid pixels: rays (N, 3) = K^-1 p (z = 1),
    depth (N,) > 0, is_wall (N,) bool. Returns the kept wall pixels (N,) bool."""
    if not settings.enabled:
        return is_wall.copy()
    # rotate upright (eq. 2); the compiled passes warp to the upright image column (eq. 1)
    up = (rays @ R_up_cam.T.astype(rays.dtype)) * depth[:, None]
    w_idx, w_col, w_d, deepest_other = _wall_columns(up, np.ascontiguousarray(is_wall), float(K[0, 0]), float(K[0, 2]),
                                                     float(MIN_FORWARD_DEPTH))
    if len(w_idx) == 0:
        return np.zeros(len(depth), dtype=bool)
    # wall pixels sorted by (column, depth): one float key (column-major, then depth) sorts
    # faster than a lexsort, and numpy's sort beats a compiled one here
    order = np.argsort(w_col * (float(w_d.max()) + 1.0) + w_d)
    return _farthest_segments(order, w_idx, w_col, w_d, deepest_other, len(depth), float(TAU_D),
                              float(SEGMENT_GAP), float(SEGMENT_GAP_PER_M))


@njit
def _wall_columns(up, is_wall, fx, cx, min_forward_depth):
    """The wall pixels in front of the camera: (index, upright image column shifted to
    0.., gravity-aligned depth d_hat), and per column the deepest non-wall depth (-inf: none).
    Columns count from the leftmost pixel in front, wall or not. No wall pixel in front:
    all four empty (the non-wall pixels are then never written: issue 44's heap
    corruption)."""
    n = up.shape[0]
    column = np.empty(n, np.int64)
    lo, hi, walls = np.iinfo(np.int64).max, np.iinfo(np.int64).min, 0
    for i in range(n):
        d = np.float64(up[i, 2])
        if d > min_forward_depth:
            u = np.int64(np.floor(fx * np.float64(up[i, 0]) / d + cx))
            column[i] = u
            lo, hi = min(lo, u), max(hi, u)
            walls += is_wall[i]
    w_idx = np.empty(walls, np.int64)
    w_col = np.empty(walls, np.int64)
    w_d = np.empty(walls, np.float64)
    if walls == 0:  # no wall in front: nothing to keep (and no column range to index)
        return w_idx, w_col, w_d, np.full(0, -np.inf)
    deepest_other = np.full(hi - lo + 1, -np.inf)
    j = 0
    for i in range(n):
        d = np.float64(up[i, 2])
        if d > min_forward_depth:
            c = column[i] - lo
            if is_wall[i]:
                w_idx[j], w_col[j], w_d[j] = i, c, d
                j += 1
            elif d > deepest_other[c]:
                deepest_other[c] = d
    return w_idx, w_col, w_d, deepest_other


@njit
def _farthest_segments(order, w_idx, w_col, w_d, deepest_other, n, tau_d, segment_gap, segment_gap_per_m):
    """Kept wall pixels (n,) bool: per column (a run of `order`), none when a non-wall pixel
    lies deeper than the median wall depth + tau_d (eqs. 3, 4); else the farthest
    depth-separated segment (eq. 5). A segment ends where the next depth is farther than the
    gap, which grows with depth like the noise: a large gap would let a wall-labelled
    furniture top bridge its front face to the wall."""
    kept = np.zeros(n, np.bool_)
    m = len(order)
    s = 0
    while s < m:
        c = w_col[order[s]]
        e = s + 1
        while e < m and w_col[order[e]] == c:
            e += 1
        count = e - s
        median = 0.5 * (w_d[order[s + (count - 1) // 2]] + w_d[order[s + count // 2]])
        if deepest_other[c] <= median + tau_d:
            t = e - 1  # sorted by depth: the farthest segment is the column's last
            while t > s and not (w_d[order[t]] - w_d[order[t - 1]] > segment_gap + segment_gap_per_m * w_d[order[t]]):
                t -= 1
            for q in range(t, e):
                kept[w_idx[order[q]]] = True
        s = e
    return kept
