"""One grid of square cells in the plane: origin, resolution, shape; the cell of a point,
the centres of cells, and the bilinear lookup of a field sampled at the cell centres.

Convention (shared by the floorplan, the BEV and the simulator): cell (row, col) covers
x in [origin_x + col * res, + res), y in [origin_y + row * res, + res); row 0 is the
smallest y (an image of a ROS map is flipped on load). A field on the grid (a distance
field, f^c) holds one value per cell, sampled at the cell's centre.

The bilinear lookup itself is compiled (numba) and lives in geometry/bilinear.py, so that
the estimator's kernels (scoring, the LM of field_fit) call the very same scalar code that
Grid.bilinear and Floorplan.distance run over arrays; it is imported when first used, so
a module that only needs cells (a CLI error, the plan readers) never pays for numba.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Grid:
    """origin: (x, y) metres of the lower-left corner of cell (0, 0); resolution: metres
    per cell; shape: (rows, cols), rows along y."""

    origin: tuple[float, float] | np.ndarray
    resolution: float
    shape: tuple[int, int]

    def cell_of(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) int64 indices of the cells holding (N, 2) points; points outside the
        grid get indices outside [0, rows) x [0, cols)."""
        p = (np.asarray(points, dtype=float).reshape(-1, 2) - self.origin) / self.resolution
        return np.floor(p[:, 1]).astype(np.int64), np.floor(p[:, 0]).astype(np.int64)

    def inside(self, row: np.ndarray, col: np.ndarray) -> np.ndarray:
        """Whether cell indices (from cell_of) lie on the grid."""
        h, w = self.shape
        return (row >= 0) & (row < h) & (col >= 0) & (col < w)

    def cells(self, points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) for (N, 2) points, row and col clipped onto the grid so they
        can index an array of this shape (read with `inside`)."""
        row, col = self.cell_of(points)
        h, w = self.shape
        return np.clip(row, 0, h - 1), np.clip(col, 0, w - 1), self.inside(row, col)

    def centres(self, rows, cols) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) metric centres of cells (rows and cols broadcast together)."""
        return (self.origin[0] + (cols + 0.5) * self.resolution,
                self.origin[1] + (rows + 0.5) * self.resolution)

    def window(self, xmin, ymin, xmax, ymax) -> tuple[int, int, int, int]:
        """(r0, r1, c0, c1): row and column index ranges of the cells whose centres may lie
        in the box (one cell of slack on each side, clipped to the grid)."""
        res = self.resolution
        c0 = max(int(np.floor((xmin - self.origin[0]) / res)) - 1, 0)
        c1 = min(int(np.ceil((xmax - self.origin[0]) / res)) + 1, self.shape[1])
        r0 = max(int(np.floor((ymin - self.origin[1]) / res)) - 1, 0)
        r1 = min(int(np.ceil((ymax - self.origin[1]) / res)) + 1, self.shape[0])
        return r0, r1, c0, c1

    def bilinear(self, field: np.ndarray, points) -> np.ndarray:
        """The field (this grid's shape, one value per cell centre) at (N, 2) finite metric
        points: bilinear between the four nearest cell centres; outside the centres' hull
        the value at the nearest point of it plus the distance to it (finite, grows
        outward, so a distance field stays a distance). Compiled (bilinear.py)."""
        from .bilinear import bilinear_lookup  # compiled (numba): imported when first needed

        p = np.asarray(points, dtype=float).reshape(-1, 2)
        flat = np.ascontiguousarray(field).ravel()  # a view for a C-contiguous field
        h, w = self.shape
        out = np.empty(len(p))
        bilinear_lookup(flat, h, w, float(self.origin[0]), float(self.origin[1]), float(self.resolution),
                        np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1]), out)
        return out
