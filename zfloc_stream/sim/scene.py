"""A built scene: the building's 3D primitives (walls, pillars, furniture, for the renderer)
and its 0.05 m occupancy raster (the floorplan the localizer sees: walls and pillars, not
furniture), with the free space a walk may use."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
from scipy import ndimage

from ..errors import InputError
from ..geometry.grid import Grid
from .layout import Door, Room, wall_boxes


@dataclass(frozen=True, eq=False)
class Scene:
    """A building: 3D primitives + its rasterised floorplan.

    walls: (N, 2, 2) centre segments of solid wall boxes; wall_thickness (N,).
    pillars: (M, 3) cx, cy, radius (floor to ceiling cylinders).
    furniture: (K, 6) cx, cy, size_x, size_y, yaw, height (boxes standing on the floor;
    not in the floorplan).
    occupied: (H, W) bool floorplan raster (walls + pillars), row 0 = smallest y.
    free: (H, W) bool walkable space (inside the building, no wall, pillar or furniture).
    """

    name: str
    seed: int
    rooms: tuple[Room, ...]
    walls: np.ndarray
    wall_thickness: np.ndarray
    doors: tuple[Door, ...]
    pillars: np.ndarray
    furniture: np.ndarray
    wall_height: float
    grid: Grid
    occupied: np.ndarray
    interior: np.ndarray
    free: np.ndarray
    target_area: float
    waypoints: dict = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    # --- raster helpers ---------------------------------------------------------------
    @property
    def resolution(self) -> float:
        return self.grid.resolution

    @property
    def origin(self) -> tuple[float, float]:
        return self.grid.origin

    @property
    def floor_area(self) -> float:
        """Net floor area inside the building (m2): interior cells not wall or pillar."""
        return float(self.interior.sum()) * self.resolution ** 2

    def cells(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside-grid) of the cells holding (N, 2) points."""
        return self.grid.cells(points)

    def is_free(self, points) -> np.ndarray:
        row, col, inside = self.cells(points)
        return inside & self.free[row, col]

    @cached_property
    def clearance(self) -> np.ndarray:
        """Metres from each free cell to the nearest non-free cell (0 outside free space)."""
        return ndimage.distance_transform_edt(self.free) * self.resolution

    def clearance_at(self, points) -> np.ndarray:
        row, col, inside = self.cells(points)
        return np.where(inside, self.clearance[row, col], 0.0)

    # --- geometry views for the renderer ---------------------------------------------------
    @cached_property
    def wall_box_params(self):
        """(centers (N, 2), half sizes (N, 2), yaws (N,)) of the wall boxes."""
        return wall_boxes(self.walls, self.wall_thickness)

    # --- floorplan --------------------------------------------------------------------------
    @cached_property
    def floorplan(self):
        """The Floorplan of this scene (walls + pillars occupied, doors free, no furniture)."""
        from ..plans.floorplan import Floorplan  # late: floorplan.py depends on settings only

        return Floorplan.from_occupancy(self.occupied, self.resolution, self.origin, name=self.name)

    def write_ros(self, directory, name: str | None = None):
        """Write the floorplan as ROS map_server YAML + PNG into `directory`."""
        Path(directory).mkdir(parents=True, exist_ok=True)
        return self.floorplan.write_ros(directory, name or self.name)

    def room(self, name: str) -> Room:
        for r in self.rooms:
            if r.name == name:
                return r
        raise InputError(f"scene '{self.name}' has no room '{name}'")
