"""Depth and label images of a scene from a pinhole camera, by vectorised ray casting.

World frame = floorplan frame with z up (floor at z = 0, ceiling at z = wall_height).
Camera: OpenCV axes (x right, y down, z forward), pose T_world_cam (camera -> world).

Walls and pillars are vertical and span floor to ceiling, so where a ray meets them depends
only on its azimuth. They are cast once for a fine fan of azimuths (a few per pixel
column); each pixel then takes the two fan neighbours' nearest primitives as candidates
and intersects them exactly. Floor, ceiling and furniture boxes (not full height) are
intersected per pixel; furniture only over its projected bounding rectangle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..frames import CEILING, FLOOR, OTHER, UNKNOWN, WALL
from ..geometry.sim2 import wrap_angle

# camera axes expressed in a world frame whose yaw, pitch and roll are zero: optical axis
# along world +x, image x (right) along world -y, image y (down) along world -z
_R_LEVEL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
_TINY = 1e-12


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """Pinhole K with square pixels and the principal point at the image centre."""
    f = (width / 2.0) / np.tan(np.radians(hfov_deg) / 2.0)
    return np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def camera_pose(x: float, y: float, yaw: float, height: float, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """T_world_cam of a camera at (x, y, height) whose optical axis has heading `yaw`
    (radians, CCW from world x) and elevation `pitch` (up positive), rolled by `roll`."""
    cz, sz = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    rz = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
    rx_cam = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    rz_cam = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = rz @ _R_LEVEL @ rx_cam @ rz_cam
    T[:3, 3] = (x, y, height)
    return T


@dataclass(frozen=True)
class VerticalPrimitives:
    """Floor-to-ceiling obstacles of a scene in one table: kind 0 = box (wall), 1 = cylinder.

    centers (N, 2); half (N, 2) box half sizes or (r, r); yaw (N,)."""

    kind: np.ndarray
    centers: np.ndarray
    half: np.ndarray
    yaw: np.ndarray

    @classmethod
    def of(cls, scene) -> VerticalPrimitives:
        cached = scene.__dict__.get("_vertical_primitives")
        if cached is not None:
            return cached
        wc, wh, wy = scene.wall_box_params
        p = scene.pillars
        out = cls(np.concatenate([np.zeros(len(wc), int), np.ones(len(p), int)]),
                  np.concatenate([wc, p[:, :2]]),
                  np.concatenate([wh, np.repeat(p[:, 2:3], 2, axis=1)]),
                  np.concatenate([wy, np.zeros(len(p))]))
        scene.__dict__["_vertical_primitives"] = out  # scenes are immutable: safe to memoise
        return out

    @property
    def bounding_radius(self) -> np.ndarray:
        return np.hypot(self.half[:, 0], self.half[:, 1])

    def subset(self, index) -> VerticalPrimitives:
        return VerticalPrimitives(self.kind[index], self.centers[index], self.half[index], self.yaw[index])


def box_distance(origin, dirs, centers, half, yaw, with_face: bool = False):
    """Horizontal distance along unit 2D directions to oriented boxes (slab test in the box
    frame); arrays broadcast, inf on a miss, 0 from inside. with_face: also which of the
    four faces is hit (0..3)."""
    rel = origin - centers
    c, s = np.cos(yaw), np.sin(yaw)
    px, py = rel[..., 0] * c + rel[..., 1] * s, -rel[..., 0] * s + rel[..., 1] * c
    dx, dy = dirs[..., 0] * c + dirs[..., 1] * s, -dirs[..., 0] * s + dirs[..., 1] * c
    dx = np.where(np.abs(dx) < _TINY, _TINY, dx)
    dy = np.where(np.abs(dy) < _TINY, _TINY, dy)
    tx1, tx2 = (-half[..., 0] - px) / dx, (half[..., 0] - px) / dx
    ty1, ty2 = (-half[..., 1] - py) / dy, (half[..., 1] - py) / dy
    tx_in, ty_in = np.minimum(tx1, tx2), np.minimum(ty1, ty2)
    t_in = np.maximum(tx_in, ty_in)
    t_out = np.minimum(np.maximum(tx1, tx2), np.maximum(ty1, ty2))
    t = np.where((t_in <= t_out) & (t_out > 0), np.maximum(t_in, 0.0), np.inf)
    if not with_face:
        return t
    face = np.where(tx_in >= ty_in, np.where(dx > 0, 0, 1), np.where(dy > 0, 2, 3))
    return t, face


def _cylinder_distance(origin, dirs, centers, radius) -> np.ndarray:
    """Horizontal distance along unit 2D directions to vertical cylinders: |rel + t d| = r."""
    rel = origin - centers
    b = rel[..., 0] * dirs[..., 0] + rel[..., 1] * dirs[..., 1]
    disc = b * b - (rel[..., 0] ** 2 + rel[..., 1] ** 2 - radius ** 2)
    root = np.sqrt(np.maximum(disc, 0.0))
    t = -b - root
    t = np.where(t > 0, t, -b + root)  # from inside a pillar: its far side
    return np.where((disc >= 0) & (t > 0), t, np.inf)


def _fan_distances(origin, fan, prims: VerticalPrimitives, with_face: bool = False):
    """(n_fan, N) distances from origin along each fan direction to each primitive (and,
    with_face, a face id per pair: 4 * primitive + box face; cylinders have one face)."""
    out = np.full((len(fan), len(prims.kind)), np.inf)
    face = np.zeros(out.shape, dtype=np.int64)
    box = prims.kind == 0
    d = fan[:, None, :]
    if box.any():
        out[:, box], face[:, box] = box_distance(origin, d, prims.centers[box], prims.half[box],
                                                  prims.yaw[box], with_face=True)
    if (~box).any():
        out[:, ~box] = _cylinder_distance(origin, d, prims.centers[~box], prims.half[~box, 0])
    if with_face:
        return out, face + 4 * np.arange(len(prims.kind))[None, :]
    return out


def _ray_distances(origin, dirs, idx, prims: VerticalPrimitives) -> np.ndarray:
    """(M,) distances along dirs (M, 2) to one primitive each, prims[idx]."""
    out = np.full(len(idx), np.inf)
    box = prims.kind[idx] == 0
    if box.any():
        i = idx[box]
        out[box] = box_distance(origin, dirs[box], prims.centers[i], prims.half[i], prims.yaw[i])
    if (~box).any():
        i = idx[~box]
        out[~box] = _cylinder_distance(origin, dirs[~box], prims.centers[i], prims.half[i, 0])
    return out


# the 12 edges of a box whose 8 corners are ordered as in _furniture_hits (bits: u, v, z)
_BOX_EDGES = np.array([(a, a | bit) for a in range(8) for bit in (1, 2, 4) if not a & bit])
_NEAR = 0.05  # m, near plane used to bound a box's image


def _clip_to_near_plane(cam: np.ndarray) -> np.ndarray:
    """Corners in front of the near plane plus the points where box edges cross it: their
    projections bound the image of the box's visible part."""
    z = cam[:, 2]
    a, b = cam[_BOX_EDGES[:, 0]], cam[_BOX_EDGES[:, 1]]
    za, zb = z[_BOX_EDGES[:, 0]], z[_BOX_EDGES[:, 1]]
    crossing = (za > _NEAR) != (zb > _NEAR)
    f = (_NEAR - za[crossing]) / (zb[crossing] - za[crossing])
    cut = a[crossing] + f[:, None] * (b[crossing] - a[crossing])
    cut[:, 2] = _NEAR
    return np.concatenate([cam[z > _NEAR], cut])


def _furniture_hits(origin, rays, furniture, K, T_world_cam, shape) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ray parameter t of the nearest furniture hit (inf if none) and the row of
    `furniture` hit (-1 if none), tested only inside each box's projected bounding box."""
    h, w = shape
    best = np.full(shape, np.inf)
    which = np.full(shape, -1, dtype=np.int64)
    R, t = T_world_cam[:3, :3], T_world_cam[:3, 3]
    for index, (cx, cy, sx, sy, yaw, height) in enumerate(furniture):
        c, s = np.cos(yaw), np.sin(yaw)
        corners = np.array([[cx + c * u - s * v, cy + s * u + c * v, z]
                            for z in (0.0, height) for v in (-sy / 2, sy / 2) for u in (-sx / 2, sx / 2)])
        cam = (corners - t) @ R  # world -> camera
        visible = _clip_to_near_plane(cam)
        if len(visible) == 0:
            continue
        uv = visible[:, :2] / visible[:, 2:3] @ K[:2, :2].T + K[:2, 2]
        u0, v0 = np.floor(uv.min(axis=0)).astype(int) - 1
        u1, v1 = np.ceil(uv.max(axis=0)).astype(int) + 2
        u0, u1, v0, v1 = max(u0, 0), min(u1, w), max(v0, 0), min(v1, h)
        if u0 >= u1 or v0 >= v1:
            continue
        d = rays[v0:v1, u0:u1]  # (hh, ww, 3), not normalised: t is z-depth
        rel = origin - np.array([cx, cy, 0.0])
        px, py, pz = rel[0] * c + rel[1] * s, -rel[0] * s + rel[1] * c, rel[2]
        dx = d[..., 0] * c + d[..., 1] * s
        dy = -d[..., 0] * s + d[..., 1] * c
        dz = d[..., 2]
        t_in = np.full(dx.shape, -np.inf)
        t_out = np.full(dx.shape, np.inf)
        for p, dd, lo, hi in ((px, dx, -sx / 2, sx / 2), (py, dy, -sy / 2, sy / 2), (pz, dz, 0.0, height)):
            dd = np.where(np.abs(dd) < _TINY, _TINY, dd)
            a, b = (lo - p) / dd, (hi - p) / dd
            t_in = np.maximum(t_in, np.minimum(a, b))
            t_out = np.minimum(t_out, np.maximum(a, b))
        closer = (t_in <= t_out) & (t_in > 0) & (t_in < best[v0:v1, u0:u1])
        best[v0:v1, u0:u1][closer] = t_in[closer]
        which[v0:v1, u0:u1][closer] = index
    return best, which


_RAY_CACHE: dict = {}


def pixel_rays(K: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """(3, H*W) camera-frame rays K^-1 [u, v, 1] (z = 1, so ray parameter = z-depth), pixel
    centres at integer (u, v); memoised per (K, shape) since a sequence reuses one camera."""
    key = (np.asarray(K, dtype=float).tobytes(), tuple(shape))
    rays = _RAY_CACHE.get(key)
    if rays is None:
        h, w = shape
        v, u = np.mgrid[0:h, 0:w].astype(float)
        uv1 = np.stack([u.ravel(), v.ravel(), np.ones(h * w)])
        rays = np.ascontiguousarray(np.linalg.inv(K) @ uv1)
        rays.setflags(write=False)
        if len(_RAY_CACHE) >= 8:
            _RAY_CACHE.clear()
        _RAY_CACHE[key] = rays
    return rays


def render(scene, T_world_cam, K, shape: tuple[int, int], max_range: float = 10.0,
           fan_oversampling: int = 4, brute_force: bool = False, return_furniture_index: bool = False):
    """Depth (float32, metres along the optical axis, 0 = beyond max_range) and labels
    (uint8: 1 wall/pillar, 2 floor, 3 ceiling, 4 furniture, 0 beyond max_range).

    max_range is the Euclidean distance along a ray. brute_force intersects every pixel
    with every vertical primitive (slow reference for tests). return_furniture_index adds
    an (H, W) int map: the row of scene.furniture seen at each pixel, -1 elsewhere."""
    T = np.asarray(T_world_cam, dtype=float)
    K = np.asarray(K, dtype=float)
    h, w = shape
    R, origin = T[:3, :3], T[:3, 3]
    rays = R @ pixel_rays(K, shape)  # (3, P) world-frame rays, z-depth parameterised
    rx, ry, rz = rays
    n_h = np.hypot(rx, ry)

    # --- walls and pillars: cull, cast the azimuth fan, per pixel interpolate/intersect ------
    prims = VerticalPrimitives.of(scene)
    o2 = origin[:2]
    rel = prims.centers - o2
    dist = np.hypot(rel[:, 0], rel[:, 1])
    fwd = np.arctan2(R[1, 2], R[0, 2]) if np.hypot(R[0, 2], R[1, 2]) > 1e-9 else 0.0
    az = np.arctan2(ry, rx) - fwd
    az = (az + np.pi) % (2 * np.pi) - np.pi
    a_lo, a_hi = float(az.min()), float(az.max())
    a_mid, a_half = 0.5 * (a_lo + a_hi), 0.5 * (a_hi - a_lo)
    radius = prims.bounding_radius
    with np.errstate(invalid="ignore"):
        spread = np.arcsin(np.clip(radius / np.maximum(dist, _TINY), 0.0, 1.0))
    in_range = dist - radius < max_range
    in_view = (dist <= radius) | (np.abs(wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) - fwd - a_mid))
                                  <= a_half + spread + 1e-3)
    prims = prims.subset(np.nonzero(in_range & in_view)[0])

    def horizontal_dirs(index=slice(None)):
        return np.stack([rx[index], ry[index]], axis=1) / np.maximum(n_h[index], _TINY)[:, None]

    if len(prims.kind) == 0:
        s_vert = np.full(h * w, np.inf)
    elif brute_force:
        s_vert = _fan_distances(o2, horizontal_dirs(), prims).min(axis=1)
    else:
        step = 1.0 / (K[0, 0] * fan_oversampling)  # rad per fan ray: a fraction of a pixel
        n_fan = int(np.ceil((a_hi - a_lo) / step)) + 2
        fan_angles = fwd + a_lo + step * np.arange(n_fan)
        fan = np.stack([np.cos(fan_angles), np.sin(fan_angles)], axis=-1)
        s_fan, face_fan = _fan_distances(o2, fan, prims, with_face=True)
        nearest = np.argmin(s_fan, axis=1)  # (n_fan,)
        fan_rows = np.arange(n_fan)
        s_near, face_near = s_fan[fan_rows, nearest], face_fan[fan_rows, nearest]
        pos = (az - a_lo) / step
        b0 = np.minimum(pos.astype(np.int64), n_fan - 2)  # pos >= 0: truncation = floor
        frac = pos - b0
        # Between two fan rays hitting the same face, distance is smooth in azimuth and the
        # fan is a fraction of a pixel apart: interpolate. Elsewhere (edges, corners,
        # occlusion boundaries) intersect both candidate primitives exactly.
        s0, s1 = s_near[b0], s_near[b0 + 1]
        with np.errstate(invalid="ignore"):  # inf - inf where a fan ray misses: exact below
            s_vert = s0 + frac * (s1 - s0)
        edge = np.nonzero((face_near[b0] != face_near[b0 + 1]) | ~np.isfinite(s_vert))[0]
        if len(edge):
            d_edge = horizontal_dirs(edge)
            s_vert[edge] = np.minimum(_ray_distances(o2, d_edge, nearest[b0[edge]], prims),
                                      _ray_distances(o2, d_edge, nearest[b0[edge] + 1], prims))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = s_vert / n_h  # n_h = 0 (straight up/down): inf, the floor or ceiling wins
        # --- floor / ceiling -------------------------------------------------------------------
        down = rz < 0
        t_fc = np.where(down, -origin[2] / rz, (scene.wall_height - origin[2]) / rz)
    labels = np.full(h * w, WALL, dtype=np.uint8)
    closer = t_fc < t
    t = np.where(closer, t_fc, t)
    labels[closer] = np.where(down[closer], FLOOR, CEILING)

    # --- furniture -------------------------------------------------------------------------
    furn = scene.furniture
    near = np.nonzero(np.hypot(furn[:, 0] - o2[0], furn[:, 1] - o2[1])
                      - 0.5 * np.hypot(furn[:, 2], furn[:, 3]) < max_range)[0]
    t = t.reshape(shape)
    labels = labels.reshape(shape)
    furn_row = None
    if len(near):
        t_furn, furn_row = _furniture_hits(origin, rays.T.reshape(h, w, 3), furn[near], K, T, shape)
        closer = t_furn < t
        t = np.where(closer, t_furn, t)
        labels[closer] = OTHER

    ray_len = np.sqrt(n_h * n_h + rz * rz).reshape(shape)
    beyond = ~(t * ray_len <= max_range)  # also catches inf / nan
    depth = np.where(beyond, 0.0, t).astype(np.float32)
    labels[beyond] = UNKNOWN
    if return_furniture_index:
        index = np.full(shape, -1, dtype=np.int64)
        if furn_row is not None:
            seen = (labels == OTHER) & (furn_row >= 0)
            index[seen] = near[furn_row[seen]]
        return depth, labels, index
    return depth, labels
