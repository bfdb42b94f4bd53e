"""Geometric labeller for frames that come without labels (no network: numpy only).

Works on an organised point cloud (the strided depth image back-projected) in the
gravity-aligned plane frame, with the floor height known:
  floor   - within floor_tolerance of the floor height, surface not vertical
  ceiling - any non-vertical surface higher than ceiling_min_height above the floor
  wall    - vertical surface higher than wall_min_height above the floor
  other   - every other valid point (furniture tops, clutter, slanted surfaces)
Walls found this way still go through the wall-mask refinement, which removes most
furniture sides that pass the "vertical" test.

Before gravity is known there is no height: `bootstrap_floor_mask` proposes floor
candidates in the camera frame (surfaces facing the camera's up axis within max_tilt_deg,
well below the camera) for the gravity plane fit, whose RANSAC rejects table tops.
"""

from __future__ import annotations

import numpy as np

from ..settings.loading import LabellerSettings
from ..frames import CEILING, FLOOR, OTHER, WALL

# a neighbour farther than this fraction of the depth is across a depth edge: no normal there
_MAX_EDGE_RATIO = 0.25
# |n_z| (plane frame) below this: a vertical surface, tilted up to ~20 deg (depth normals
# from finite differences are noisy) (was frontend.labeller.vertical_normal_max_z)
VERTICAL_NORMAL_MAX_Z = 0.35
# m, bootstrap floor candidates lie at least this far below the camera, which is carried
# well above the floor (was frontend.labeller.bootstrap_min_below)
BOOTSTRAP_MIN_BELOW = 0.5


def depth_normals(points: np.ndarray, depth: np.ndarray, valid: np.ndarray, step: int) -> np.ndarray:
    """Unit normals (H, W, 3) float32 of an organised point cloud (any frame) from
    differences over `step` pixels (central inside, one-sided at the image border, so
    borders keep their normals); NaN where a neighbour is missing or lies across a depth
    edge (farther than a fraction of the depth). The sign is arbitrary: callers use |n_z|."""
    p = np.asarray(points, dtype=np.float32)
    h, w, _ = p.shape
    s = max(int(step), 1)
    # edge padding makes the border differences one-sided without special cases
    P = np.pad(p, ((s, s), (s, s), (0, 0)), mode="edge")
    V = np.pad(valid, s, mode="edge")
    du = P[s:-s, 2 * s :] - P[s:-s, : -2 * s]
    dv = P[2 * s :, s:-s] - P[: -2 * s, s:-s]
    n = np.cross(du, dv)
    norm2 = np.einsum("ijk,ijk->ij", n, n)
    ok = valid & V[s:-s, 2 * s :] & V[s:-s, : -2 * s] & V[2 * s :, s:-s] & V[: -2 * s, s:-s] & (norm2 > 1e-20)
    # a neighbour pair spans at most 2 * step pixels: farther apart means a depth edge
    edge2 = (_MAX_EDGE_RATIO * 2 * np.nan_to_num(np.asarray(depth, dtype=np.float32))) ** 2
    ok &= (np.einsum("ijk,ijk->ij", du, du) < edge2) & (np.einsum("ijk,ijk->ij", dv, dv) < edge2)
    out = np.full((h, w, 3), np.nan, dtype=np.float32)
    out[ok] = n[ok] / np.sqrt(norm2[ok])[:, None]
    return out


def label_frame(height: np.ndarray, normals: np.ndarray, valid: np.ndarray, settings: LabellerSettings) -> np.ndarray:
    """Labels (H, W) uint8 from heights above the floor and plane-frame normals."""
    nz = np.abs(normals[..., 2])
    has_normal = np.isfinite(nz)
    nz = np.nan_to_num(nz, nan=0.5)
    vertical = has_normal & (nz < VERTICAL_NORMAL_MAX_Z)
    labels = np.where(valid, OTHER, 0).astype(np.uint8)
    labels[valid & vertical & (height > settings.wall_min_height)] = WALL
    # above head height anything not vertical is ceiling (normals blur at ceiling corners)
    labels[valid & has_normal & ~vertical & (height > settings.ceiling_min_height)] = CEILING
    # at floor height anything not vertical is floor (normals blur where the floor meets walls)
    labels[valid & ~vertical & (np.abs(height) < settings.floor_tolerance)] = FLOOR
    return labels


def bootstrap_floor_mask(points_cam: np.ndarray, settings: LabellerSettings) -> np.ndarray:
    """Floor candidates (H, W) bool before gravity is known, from camera-frame points:
    surface normal within max_tilt_deg of the camera's up axis (-y) and at least
    BOOTSTRAP_MIN_BELOW below the camera (along its down axis +y)."""
    p = np.asarray(points_cam, dtype=float)
    valid = p[..., 2] > 0
    n = depth_normals(p, p[..., 2], valid, settings.normal_step)
    up = np.array([0.0, -1.0, 0.0])
    facing = np.abs(np.nan_to_num(n) @ up)  # the floor faces the camera, so |n . up| suffices
    return valid & (facing > np.cos(np.deg2rad(settings.max_tilt_deg))) & (p[..., 1] > BOOTSTRAP_MIN_BELOW)
