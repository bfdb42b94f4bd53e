"""Gravity-aligned wall-mask refinement (paper 3.1, eqs. 1-5).

In an upright (gravity-aligned) image every column is a vertical plane through the camera
centre, so a vertical wall shows one depth per column. A column is dropped when any
non-wall pixel lies deeper than the column's median wall depth + tau_d (the "wall" is then
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

from ..config import WallMaskSettings
from ..frames import WALL


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
    if not settings.enabled:
        return wall & np.isfinite(depth) & (depth > 0)
    valid = np.isfinite(depth) & (depth > 0)
    rows, cols = np.nonzero(valid)
    d = depth[rows, cols].astype(float)
    # back-project, rotate upright (eq. 2), and warp to the upright image column (eq. 1)
    K_inv = np.linalg.inv(K)
    rays = K_inv @ np.stack([cols + 0.0, rows + 0.0, np.ones(len(d))])
    up = (R_up_cam @ rays) * d
    d_hat = up[2]
    front = d_hat > settings.min_forward_depth
    u_hat = np.full(len(d), -1, dtype=np.int64)
    u_hat[front] = np.floor(K[0, 0] * up[0, front] / d_hat[front] + K[0, 2]).astype(np.int64)
    is_wall = wall[rows, cols] & front

    out = np.zeros((h, w), dtype=bool)
    if not is_wall.any():
        return out
    # shift columns to a compact 0..C-1 range (warped columns may leave the image)
    c_min = u_hat[front].min()
    column = u_hat - c_min
    n_cols = int(column[front].max()) + 1

    # deepest non-wall pixel per column
    other = front & ~is_wall
    deepest_other = np.full(n_cols, -np.inf)
    np.maximum.at(deepest_other, column[other], d_hat[other])

    # wall pixels sorted by (column, depth): medians and segments per column in one pass
    w_idx = np.nonzero(is_wall)[0]
    w_col, w_d = column[w_idx], d_hat[w_idx]
    order = np.lexsort((w_d, w_col))
    w_idx, w_col, w_d = w_idx[order], w_col[order], w_d[order]
    starts = np.r_[0, np.nonzero(np.diff(w_col))[0] + 1]
    counts = np.diff(np.r_[starts, len(w_col)])
    col_ids = w_col[starts]
    median = 0.5 * (w_d[starts + (counts - 1) // 2] + w_d[starts + counts // 2])  # eq. 3

    keep_column = deepest_other[col_ids] <= median + settings.tau_d  # eq. 4
    # depth-separated segments: a new segment starts at each column start or depth gap
    new_segment = np.ones(len(w_d), dtype=bool)
    new_segment[1:] = (w_col[1:] != w_col[:-1]) | (np.diff(w_d) > settings.segment_gap)
    segment = np.cumsum(new_segment)
    # sorted by depth, the farthest segment (largest median, eq. 5) is the column's last
    last_segment = segment[starts + counts - 1]
    group = np.repeat(np.arange(len(starts)), counts)
    kept = keep_column[group] & (segment == last_segment[group])
    keep_idx = w_idx[kept]
    out[rows[keep_idx], cols[keep_idx]] = True
    return out
