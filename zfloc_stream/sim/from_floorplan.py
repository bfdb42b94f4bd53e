"""A simulation scene from any Floorplan (a user's ROS map or DXF/SVG/GeoJSON plan):
`zfloc-stream demo --floorplan plan.dxf` walks through the user's own building.

    scene = build_scene_from_floorplan(load_floorplan("plan.dxf"), seed=0)
    sequence = simulate(scene, seed=0, n_frames=40)      # or simulate_laser(scene, ...)

The walls are the floorplan's occupied cells extruded floor to ceiling, as boxes: runs of
wall cells in a row, merged with the identical runs of the rows above, so straight walls
become a few boxes (what the renderer traces is exactly the raster the localizer sees).
Round pillars the floorplan knows as circles become cylinders instead of staircases. There
is no furniture. The walkable space is the largest free region inside the building (the
free cells not connected to the border; for a plan whose outer wall has openings, the free
cells inside the walls' convex hull). Its "rooms", which the random walk travels between,
are tiles of that space, so a walk crosses the whole plan. The scene's floorplan is the
given object itself, so the localizer sees the user's lines and circles, not re-extracted ones.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy import ndimage

from ..errors import FloorplanError
from ..geometry.grid import Grid
from .layout import Room
from .scenes import Scene

WALL_HEIGHT = 2.7  # m
ROOM_TILE = 4.0  # m, side of the tiles the walk picks its goals in
MIN_WALK_CLEARANCE = 0.5  # m, a tile is a goal when some of its free cells are this far from walls


def wall_boxes_from_raster(occupied: np.ndarray, origin, res: float) -> tuple[np.ndarray, np.ndarray]:
    """(segments (N, 2, 2), thickness (N,)) of axis-aligned boxes covering the occupied cells
    exactly: row runs merged with the same run on the following rows."""
    open_boxes: dict[tuple[int, int], int] = {}  # (c0, c1) -> first row of a box still growing
    boxes = []
    h = occupied.shape[0]
    for r in range(h + 1):
        runs = set()
        if r < h:
            row = np.concatenate([[False], occupied[r], [False]])
            edges = np.flatnonzero(row[1:] != row[:-1])
            runs = set(zip(edges[::2].tolist(), edges[1::2].tolist()))
        for run in list(open_boxes):
            if run not in runs:
                boxes.append((open_boxes.pop(run), r, *run))
        for run in runs:
            open_boxes.setdefault(run, r)
    ox, oy = origin
    segments, thickness = [], []
    for r0, r1, c0, c1 in boxes:
        x0, x1, y0, y1 = ox + c0 * res, ox + c1 * res, oy + r0 * res, oy + r1 * res
        if x1 - x0 >= y1 - y0:  # a box is a centre segment along its long side + thickness
            yc = 0.5 * (y0 + y1)
            segments.append([[x0, yc], [x1, yc]])
            thickness.append(y1 - y0)
        else:
            xc = 0.5 * (x0 + x1)
            segments.append([[xc, y0], [xc, y1]])
            thickness.append(x1 - x0)
    return np.asarray(segments, dtype=float).reshape(-1, 2, 2), np.asarray(thickness, dtype=float)


def _interior(occupied: np.ndarray) -> np.ndarray:
    free = ~occupied
    labels, _ = ndimage.label(free)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    inside = free & ~np.isin(labels, border[border > 0])
    hull = np.zeros(occupied.shape, dtype=np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(np.argwhere(occupied)[:, ::-1].astype(np.int32)), 1)
    within_hull = free & hull.astype(bool)
    if inside.sum() < 0.5 * within_hull.sum():  # the outer wall has openings (an entrance drawn open)
        inside = within_hull
    labels, count = ndimage.label(inside)
    if count == 0:
        raise FloorplanError("the floorplan encloses no free space to walk in")
    sizes = ndimage.sum(inside, labels, index=np.arange(1, count + 1))
    return labels == 1 + int(np.argmax(sizes))


def _rooms(walkable: np.ndarray, grid: Grid, clearance: np.ndarray) -> list[Room]:
    """Tiles of ROOM_TILE metres holding a well-clear free cell: goals for the walk."""
    rooms = []
    h, w = walkable.shape
    step = max(int(round(ROOM_TILE / grid.resolution)), 1)
    for r0 in range(0, h, step):
        for c0 in range(0, w, step):
            if clearance[r0:r0 + step, c0:c0 + step].max() >= MIN_WALK_CLEARANCE:
                x0, y0 = grid.origin[0] + c0 * grid.resolution, grid.origin[1] + r0 * grid.resolution
                x1 = grid.origin[0] + min(c0 + step, w) * grid.resolution
                y1 = grid.origin[1] + min(r0 + step, h) * grid.resolution
                rooms.append(Room(f"tile{len(rooms)}", "open", x0, y0, x1, y1))
    if len(rooms) < 2:
        raise FloorplanError(f"the floorplan has too little open space to walk in (needs 2 areas {MIN_WALK_CLEARANCE} m clear of walls)")
    return rooms


def build_scene_from_floorplan(floorplan, seed: int = 0, wall_height: float = WALL_HEIGHT, name: str | None = None) -> Scene:
    """A Scene whose walls are the floorplan's (see the module doc); deterministic in its input."""
    occupied = np.array(floorplan.occupied, dtype=bool)
    res = float(floorplan.resolution)
    origin = (float(floorplan.origin[0]), float(floorplan.origin[1]))
    grid = Grid(origin, res, occupied.shape)
    circles = floorplan.circles
    pillars = np.column_stack([circles.centers, circles.radii]) if len(circles) else np.zeros((0, 3))
    boxes_of = occupied.copy()
    if len(pillars):  # pillar cells are traced as cylinders, not as boxes
        rows, cols = np.nonzero(occupied)
        centres = floorplan.cell_to_world(rows, cols)
        near = np.zeros(len(rows), dtype=bool)
        for x, y, r in pillars:
            near |= np.hypot(centres[:, 0] - x, centres[:, 1] - y) <= r + res
        boxes_of[rows[near], cols[near]] = False
    segments, thickness = wall_boxes_from_raster(boxes_of, origin, res)
    interior = _interior(occupied)
    clearance = ndimage.distance_transform_edt(interior) * res
    rooms = _rooms(interior, grid, clearance)
    scene = Scene(name or floorplan.name or "floorplan", int(seed), tuple(rooms), segments, thickness, (), pillars,
                  np.zeros((0, 6)), float(wall_height), grid, occupied, interior, interior.copy(),
                  float(interior.sum()) * res * res, {}, {"source": "floorplan"})
    scene.__dict__["floorplan"] = floorplan  # the user's own object (its vector lines), not a re-extraction
    return scene
