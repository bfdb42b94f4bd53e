"""Gravity from the floor: a robust plane fit to floor points in the odometry frame.

The paper takes the downward normal of a PCA plane fitted to the floor point cloud as
gravity. Here floor points of the first frames are accumulated (subsampled, bounded),
a 3-point RANSAC finds the floor plane, a few PCA re-fits on its inliers polish it, and
the normal is signed to point from the camera centres towards the floor.

Early frames: gravity is estimated once and then FROZEN (the BEV lives in the plane frame,
so a moving gravity would smear it). Until it is frozen the caller (RollingBEV) keeps the
frames in a bounded buffer and fuses them when it is known. With `trust_odometry` the
odometry z axis is taken as up at once (VIO output is already gravity-aligned); only the
floor height is then estimated from floor points.

Plane frame ("plane"): origin = odometry origin, z = up (-gravity), x = odometry x
projected onto the horizontal plane (odometry y when odometry x is vertical), y = z x x.
Heights are plane z; `floor_height` is the plane z of the floor.
"""

from __future__ import annotations

import numpy as np

from ..settings.loading import GravitySettings
from ..errors import InputError


def rotation_from_up(up_odom: np.ndarray) -> np.ndarray:
    """R_plane_odom for a unit up vector given in odometry coordinates."""
    z = np.asarray(up_odom, dtype=float)
    z = z / np.linalg.norm(z)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z  # odom x projected onto the plane
    if np.linalg.norm(x) < 1e-6:  # odom x is vertical: use odom y instead
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])  # rows: plane axes in odom coordinates


# The floor-plane fit and its tracking (were frontend.gravity.*; every recorded result used
# these: the replay samples' camera runs, eval_real's camera windows, the benchmark scenes).
# What a user sets is when gravity is frozen (min_floor_points, min_frames) and what is kept.
RANSAC_ITERATIONS = 100  # 3-point plane hypotheses: with half the points on the floor, P(no all-floor triple) = 0.875^100 ~ 2e-6
INLIER_DISTANCE = 0.03  # m, point-to-plane distance of a floor inlier
REFINE_ITERATIONS = 3  # PCA re-fits, each on the inliers of the previous fit
POINTS_PER_FRAME = 1000  # floor points kept per frame (random subsample): many frames' views, not one frame's pixels
FLOOR_HEIGHT_SMOOTHING = 0.2  # EMA factor of a frame's floor height once frozen: follows slow z drift, not one frame's noise


def fit_plane(points: np.ndarray, rng: np.random.Generator):
    """Robust plane (unit normal n, offset c with n.x = c) through (N, 3) points.

    3-point RANSAC picks the inlier set, PCA re-fits on it (the normal is the direction of
    least variance). Returns (n, c, inlier mask); n's sign is arbitrary.
    """
    pts = np.asarray(points, dtype=float)
    if len(pts) < 3:
        raise InputError(f"plane fit needs at least 3 points, got {len(pts)}")
    k = RANSAC_ITERATIONS
    idx = rng.integers(0, len(pts), size=(k, 3))
    a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
    normals = np.cross(b - a, c - a)
    norm = np.linalg.norm(normals, axis=1)
    ok = norm > 1e-9
    if not ok.any():
        raise InputError("floor points are degenerate (collinear), no plane")
    normals = normals[ok] / norm[ok, None]
    offsets = np.einsum("ij,ij->i", normals, a[ok])
    # inlier counts of all hypotheses at once: (k, N) distances
    counts = (np.abs(pts @ normals.T - offsets) < INLIER_DISTANCE).sum(axis=0)
    best = int(np.argmax(counts))
    n, off = normals[best], offsets[best]
    inliers = np.abs(pts @ n - off) < INLIER_DISTANCE
    for _ in range(REFINE_ITERATIONS):
        if inliers.sum() < 3:
            break
        centre = pts[inliers].mean(axis=0)
        _, _, vt = np.linalg.svd(pts[inliers] - centre, full_matrices=False)
        n = vt[2]
        off = float(n @ centre)
        inliers = np.abs(pts @ n - off) < INLIER_DISTANCE
    return n, float(off), inliers


class GravityEstimator:
    """Accumulates floor points until the floor plane (hence gravity) can be frozen."""

    def __init__(self, settings: GravitySettings, rng: np.random.Generator):
        self.settings = settings
        self._rng = rng
        self._points = np.zeros((0, 3))
        self._centre_sum = np.zeros(3)  # sum of camera centres that saw floor (for the sign)
        self._frames = 0
        self._R: np.ndarray | None = np.eye(3) if settings.trust_odometry else None
        self.floor_height: float | None = None
        self.inlier_ratio: float | None = None
        # provisional fits draw from their own stream, so asking for a pose never changes
        # the frozen gravity; cached per number of frames seen
        self._provisional_seed = int(rng.integers(2**63))
        self._provisional: tuple[int, np.ndarray] | None = None

    # ------------------------------------------------------------------------------
    @property
    def ready(self) -> bool:
        """Gravity frozen and floor height known."""
        return self._R is not None and self.floor_height is not None

    @property
    def R_plane_odom(self) -> np.ndarray:
        if self._R is None:
            raise InputError("gravity is not known yet (not enough floor points)")
        return self._R

    @property
    def up_odom(self) -> np.ndarray:
        return self.R_plane_odom[2]

    @property
    def buffered_bytes(self) -> int:
        """Memory held by the floor points waiting for the fit (bounded by max_points)."""
        return self._points.nbytes

    def provisional_R(self) -> np.ndarray:
        """Best current guess: the frozen gravity, else a fit to the points so far, else odom z up."""
        if self._R is not None:
            return self._R
        if self._provisional is not None and self._provisional[0] == self._frames:
            return self._provisional[1]
        R = np.eye(3)
        if len(self._points) >= 3 and self._frames > 0:
            try:
                R = self._fit(np.random.default_rng(self._provisional_seed))[0]
            except InputError:
                pass
        self._provisional = (self._frames, R)
        return R

    # ------------------------------------------------------------------------------
    def add_floor_points(self, points_odom: np.ndarray, camera_centre_odom: np.ndarray) -> None:
        """Floor-labelled points (N, 3) of one frame, odometry frame; may freeze gravity."""
        pts = np.asarray(points_odom, dtype=float).reshape(-1, 3)
        pts = pts[np.isfinite(pts).all(axis=1)]
        if len(pts) == 0:
            return
        if self._R is not None:
            self.observe_floor_heights(pts @ self._R[2])
            return
        cfg = self.settings
        if len(pts) > POINTS_PER_FRAME:
            pts = pts[self._rng.choice(len(pts), POINTS_PER_FRAME, replace=False)]
        self._points = np.concatenate([self._points, pts])
        if len(self._points) > cfg.max_points:  # bounded: keep a random subset
            keep = np.sort(self._rng.choice(len(self._points), cfg.max_points, replace=False))
            self._points = self._points[keep]
        self._centre_sum += np.asarray(camera_centre_odom, dtype=float)
        self._frames += 1
        if self._frames >= cfg.min_frames and len(self._points) >= cfg.min_floor_points:
            try:
                R, inliers = self._fit(self._rng)
            except InputError:
                return
            self._R = R
            self.inlier_ratio = float(inliers.mean())
            # the floor height from the plane's inliers only (table tops may be candidates)
            self._update_floor_height(self._points[inliers], smoothing=1.0)
            self._points = np.zeros((0, 3))  # no longer needed once frozen

    def observe_floor_heights(self, heights: np.ndarray) -> None:
        """Plane-frame heights of one frame's floor points (after gravity is frozen):
        follows slow vertical drift of the odometry."""
        h = np.asarray(heights, dtype=float)
        h = h[np.isfinite(h)]
        if len(h) and self._R is not None:
            a = FLOOR_HEIGHT_SMOOTHING
            m = float(np.median(h))
            self.floor_height = m if self.floor_height is None else (1 - a) * self.floor_height + a * m

    def _fit(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """(R_plane_odom, inlier mask) of the floor points so far."""
        n, off, inliers = fit_plane(self._points, rng)
        centre = self._centre_sum / max(self._frames, 1)
        # gravity points from the cameras towards the floor: the cameras are above the
        # plane along up = -gravity
        up = n if (n @ centre - off) > 0 else -n
        return rotation_from_up(up), inliers

    def _update_floor_height(self, pts: np.ndarray, smoothing: float) -> None:
        h = float(np.median(pts @ self._R[2]))
        self.floor_height = h if self.floor_height is None else (1 - smoothing) * self.floor_height + smoothing * h

    # ------------------------------------------------------------------------------
    def to_plane(self, points_odom: np.ndarray) -> np.ndarray:
        """(N, 3) odometry points -> plane frame (z = height)."""
        return np.asarray(points_odom, dtype=float) @ self.R_plane_odom.T

    def plane_pose(self, T_odom_sensor: np.ndarray, axis: str = "z", R_plane_odom=None) -> tuple[float, float, float]:
        """(x, y, yaw) of a sensor in the plane frame.

        axis: the sensor axis whose horizontal heading is the yaw: "z" (camera optical
        axis) or "x" (laser forward axis).
        """
        return plane_pose(T_odom_sensor, self.R_plane_odom if R_plane_odom is None else R_plane_odom, axis)


def plane_pose(T_odom_sensor: np.ndarray, R_plane_odom: np.ndarray, axis: str = "z") -> tuple[float, float, float]:
    """(x, y, yaw) of a sensor in the plane frame given R_plane_odom."""
    T = np.asarray(T_odom_sensor, dtype=float)
    col = {"x": 0, "y": 1, "z": 2}[axis]
    position = R_plane_odom @ T[:3, 3]
    heading = R_plane_odom @ T[:3, col]
    return float(position[0]), float(position[1]), float(np.arctan2(heading[1], heading[0]))
