"""What the estimator aligns: a snapshot of the BEV in the odometry plane.

Produced by RollingBEV (streaming) or built directly in tests. Grid convention (shared
with Floorplan): cell (row, col) covers x in [origin_x + col*res, +res), y in
[origin_y + row*res, +res); row 0 is the smallest y (unlike an image of a ROS map).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import InputError
from .geometry.grid import Grid
from .geometry.shapes import CircleSet, LineSet


@dataclass(frozen=True)
class BevObservation:
    wall_points: np.ndarray  # (N, 2) metres, odometry plane: BEV wall cell centres
    origin: np.ndarray  # (2,) metres: lower-left corner of cell (0, 0)
    resolution: float  # metres per cell
    free: np.ndarray  # (H, W) bool: observed free space
    clearance: np.ndarray  # (H, W) float: f^v, metres to the nearest occupied cell
    lines: LineSet = field(default_factory=LineSet.empty)
    circles: CircleSet = field(default_factory=CircleSet.empty)
    trajectory: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (K, 3) x, y, yaw

    def __post_init__(self):
        pts = np.asarray(self.wall_points, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            raise InputError("BEV observation has no wall points")
        if not np.isfinite(pts).all():
            raise InputError("BEV wall points contain NaN or inf")
        object.__setattr__(self, "wall_points", pts)
        if self.free.shape != self.clearance.shape:
            raise InputError("BEV free mask and clearance field differ in shape")

    @property
    def grid(self) -> Grid:
        """The BEV's cells (grid.py's convention)."""
        return Grid(self.origin, self.resolution, self.free.shape)

    def cells(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) of the cells holding the given (N, 2) points."""
        return self.grid.cells(points)

    def free_at(self, points) -> np.ndarray:
        row, col, inside = self.cells(points)
        return inside & self.free[row, col]

    def clearance_at(self, points) -> np.ndarray:
        """f^v at the points; 0 outside the grid (unknown space never violates)."""
        row, col, inside = self.cells(points)
        return np.where(inside, self.clearance[row, col], 0.0)
