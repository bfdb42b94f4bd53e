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
    # rotate upright (eq. 2) and warp to the upright image column (eq. 1)
    up = (rays @ R_up_cam.T.astype(rays.dtype)) * depth[:, None]
    d_hat = up[:, 2].astype(float)
    front = d_hat > settings.min_forward_depth
    kept = np.zeros(len(depth), dtype=bool)
    is_wall = is_wall & front
    if not is_wall.any():
        return kept
    u_hat = np.zeros(len(depth), dtype=np.int64)
    u_hat[front] = np.floor(K[0, 0] * up[front, 0] / d_hat[front] + K[0, 2]).astype(np.int64)
    # shift columns to a compact 0..C-1 range (warped columns may leave the image)
    column = u_hat - u_hat[front].min()
    n_cols = int(column[front].max()) + 1

    # deepest non-wall pixel per column
    other = front & ~is_wall
    deepest_other = np.full(n_cols, -np.inf)
    np.maximum.at(deepest_other, column[other], d_hat[other])

    # wall pixels sorted by (column, depth): medians and segments per column in one pass
    w_idx = np.flatnonzero(is_wall)
    w_col, w_d = column[w_idx], d_hat[w_idx]
    # one float key (column-major, then depth) sorts faster than a lexsort
    order = np.argsort(w_col * (float(w_d.max()) + 1.0) + w_d)
    w_idx, w_col, w_d = w_idx[order], w_col[order], w_d[order]
    starts = np.r_[0, np.flatnonzero(np.diff(w_col)) + 1]
    counts = np.diff(np.r_[starts, len(w_col)])
    col_ids = w_col[starts]
    median = 0.5 * (w_d[starts + (counts - 1) // 2] + w_d[starts + counts // 2])  # eq. 3

    keep_column = deepest_other[col_ids] <= median + settings.tau_d  # eq. 4
    # depth-separated segments: a new segment starts at each column start or depth gap. The
    # gap is small (a wall is one depth per column) but grows with depth like the noise;
    # a large gap would let a wall-labelled furniture top bridge its front face to the wall
    gap = settings.segment_gap + settings.segment_gap_per_m * w_d[1:]
    new_segment = np.ones(len(w_d), dtype=bool)
    new_segment[1:] = (w_col[1:] != w_col[:-1]) | (np.diff(w_d) > gap)
    segment = np.cumsum(new_segment)
    # sorted by depth, the farthest segment (largest median, eq. 5) is the column's last
    last_segment = segment[starts + counts - 1]
    group = np.repeat(np.arange(len(starts)), counts)
    kept[w_idx[keep_column[group] & (segment == last_segment[group])]] = True
    return kept
