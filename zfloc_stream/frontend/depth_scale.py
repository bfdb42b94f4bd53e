"""The camera depth's scale, measured against the odometry: a monocular depth network's
depth is off by a global factor (often 5-10%), while a phone's or robot's VIO odometry is
metric. Fused as they come, each frame's walls are scaled about its own camera, so the
same wall seen from two places lands in two places, and an alignment's scale, applied to
the metric trajectory, moves the reported pose by that factor of every metre walked (the
shared fhw camera windows: 0.8 m after 9 m along a corridor at a 9% error).

The factor is observable wherever the camera moves toward or away from a wall: with the
right factor f, frame i's wall hits c_i + f r_i (r_i: the hits about the camera at the raw
depth, c_i: the camera in the odometry plane) and frame j's c_j + f r_j coincide. Divided
by f, that is r_i + (c_i - c_j) / f against r_j: each older frame's raw hits shifted by
its own baseline over f, read in a distance field of the newest frame's raw hits. Every
fused frame adds its cost curve over a grid of factors (truncated distance, mean per hit)
against the depth_scale_frames frames before it; the estimate is the curve sum's minimum
once depth_scale_min_frames frames have added one. Frames moving along walls add a flat
curve (no information), which leaves the minimum where the others put it. The BEV fuses
every later frame's depth times the estimate (bev.RollingBEV, _strided).
"""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np

from ..config import FrontendSettings
from ..field_fit import thin_points

# A hit farther than this from the newest frame's hits is a wall that frame did not see
# (another field of view): it costs the same whatever the factor.
CUTOFF = 0.3  # m
FIELD_RESOLUTION = 0.05  # m per cell of the newest frame's distance field
MIN_HITS = 30  # a frame with fewer wall hits adds nothing


class DepthScaleEstimator:
    """The running estimate of the factor camera depth is multiplied by (module docstring)."""

    def __init__(self, settings: FrontendSettings):
        self.settings = settings
        self.factors = np.arange(settings.depth_scale_min, settings.depth_scale_max + 1e-9, settings.depth_scale_step)
        self.cost = np.zeros(len(self.factors))  # summed cost curves
        self.frames_measured = 0  # frames that added a cost curve
        self._recent: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=settings.depth_scale_frames)
        self.factor = 1.0  # what the BEV multiplies the depth of the next frame by

    @property
    def enabled(self) -> bool:
        return self.settings.depth_scale == "estimate"

    def observe(self, wall_xy: np.ndarray, camera_xy: np.ndarray, used_factor: float) -> None:
        """One fused frame: its wall hits and camera (odometry plane, fused at used_factor)."""
        if len(wall_xy) < MIN_HITS:
            return
        raw = thin_points((wall_xy - camera_xy) / used_factor, self.settings.depth_scale_points)
        camera = np.asarray(camera_xy, dtype=float).copy()
        if self._recent:
            curve = self._cost_curve(raw, camera)
            if curve is not None:
                self.cost += curve
                self.frames_measured += 1
                if self.frames_measured >= self.settings.depth_scale_min_frames:
                    self.factor = float(self.factors[int(np.argmin(self.cost))])
        self._recent.append((raw, camera))

    def _cost_curve(self, raw: np.ndarray, camera: np.ndarray) -> np.ndarray | None:
        """Mean truncated distance, across each wall, of the older frames' raw hits (shifted
        by their baseline over each factor) to the newest frame's raw hits; None when no
        older hit lies near them. Only the hits within CUTOFF of the newest frame's at the
        current estimate count, and only their motion across the wall they lie on (the
        distance field's gradient there): a shift along a wall, or into a stretch the
        newest frame happens to see, says nothing about the depth's scale."""
        lo = raw.min(axis=0) - CUTOFF
        shape = np.ceil((raw.max(axis=0) + CUTOFF - lo) / FIELD_RESOLUTION).astype(int) + 1
        occupied = np.ones((shape[1], shape[0]), dtype=np.uint8)
        cells = np.floor((raw - lo) / FIELD_RESOLUTION).astype(int)
        occupied[cells[:, 1], cells[:, 0]] = 0
        field = cv2.distanceTransform(occupied, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) * FIELD_RESOLUTION
        gy, gx = np.gradient(field)
        older = np.concatenate([r for r, _ in self._recent])
        baseline = np.concatenate([np.broadcast_to(c - camera, r.shape) for r, c in self._recent])
        here = older + baseline / self.factor
        cells = np.floor((here - lo) / FIELD_RESOLUTION).astype(int)
        inside = (cells[:, 0] >= 0) & (cells[:, 0] < shape[0]) & (cells[:, 1] >= 0) & (cells[:, 1] < shape[1])
        d0 = np.full(len(older), np.inf)
        d0[inside] = field[cells[inside, 1], cells[inside, 0]]
        near = d0 < CUTOFF
        if not near.any():
            return None
        r, c = cells[near, 1], cells[near, 0]
        normal = np.stack([gx[r, c], gy[r, c]], axis=1)
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
        # each near hit's distance across its wall as the factor moves it: (factors, near)
        moved = (1.0 / self.factors[:, None] - 1.0 / self.factor) * np.einsum("ij,ij->i", baseline[near], normal)[None]
        return np.minimum(np.abs(d0[near][None] + moved), CUTOFF).mean(axis=1)
