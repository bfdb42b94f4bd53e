"""How a room plan becomes a Scene: doors on a random tree of the rooms, furniture placed
along the walls and in the open, the walls built and rasterised, the interior and walkable
masks, a waypoint per room (assemble); make_scene for a hand-made plan. The generators
(generators.py) lay out the rooms and call assemble."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..runtime.rng import make_rng
from .layout import Connection, Room, build_walls, grid_around, rasterize_boxes, rasterize_discs, snap, wall_boxes
from .scene import Scene

EXTERIOR_WALL = 0.25  # m, 5 cells
INTERIOR_WALL = 0.15  # m, 3 cells
DOOR_WIDTH = 0.9  # m


def partition(lo: float, hi: float, wmin: float, wmax: float, rng, tries: int = 100) -> list[float]:
    """Lattice cut positions splitting [lo, hi] into parts of random width in [wmin, wmax]."""
    length = hi - lo
    nmin, nmax = max(int(np.ceil(length / wmax)), 1), max(int(np.floor(length / wmin)), 1)
    # prefer part counts whose mean width is well inside [wmin, wmax]: more variety
    counts = [n for n in range(nmin, max(nmin, nmax) + 1)
              if wmin + 0.2 * (wmax - wmin) <= length / n <= wmax - 0.2 * (wmax - wmin)] or [nmin]
    n = int(rng.choice(counts))
    widths = np.full(n, length / n)
    slack = length - n * wmin
    for _ in range(tries):
        # wmin each plus a random (Dirichlet) share of the rest: sums to length, >= wmin
        w = wmin + slack * rng.dirichlet(np.full(n, 2.0))
        if w.max() <= wmax:
            widths = w
            break
    cuts = [snap(lo + c) for c in np.cumsum(widths)[:-1]]
    return [lo, *cuts, hi]


def _shared_length(a: Room, b: Room) -> float:
    """Length of the boundary two touching rectangles share (0 when they do not touch)."""
    eps = 1e-6
    if abs(a.x1 - b.x0) < eps or abs(b.x1 - a.x0) < eps:
        return max(0.0, min(a.y1, b.y1) - max(a.y0, b.y0))
    if abs(a.y1 - b.y0) < eps or abs(b.y1 - a.y0) < eps:
        return max(0.0, min(a.x1, b.x1) - max(a.x0, b.x0))
    return 0.0


def random_tree_doors(rooms: list[Room], rng, extra_prob: float = 0.3, min_shared: float = 1.6):
    """Doors along a random spanning tree of the room adjacency graph, plus a few extra."""
    pairs = [(i, j) for i in range(len(rooms)) for j in range(i + 1, len(rooms))
             if _shared_length(rooms[i], rooms[j]) >= min_shared]
    order = rng.permutation(len(pairs))
    parent = list(range(len(rooms)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    out = []
    for k in order:
        i, j = pairs[k]
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[ri] = rj
            out.append(Connection(i, j, "door", DOOR_WIDTH))
        elif rng.random() < extra_prob:
            out.append(Connection(i, j, "door", DOOR_WIDTH))
    return out


# Furniture catalogue: (name, length along the wall, depth, height)
_WALL_ITEMS = (
    ("wardrobe", 1.2, 0.6, 2.0),
    ("shelf", 1.0, 0.4, 1.8),
    ("desk", 1.4, 0.7, 0.75),
    ("cabinet", 0.8, 0.45, 1.1),
    ("sofa", 2.0, 0.9, 0.85),
    ("bed", 2.0, 1.4, 0.55),
    ("counter", 2.4, 0.6, 0.9),
)
_FREE_ITEMS = (("table", 1.6, 0.9, 0.75), ("table_small", 1.2, 0.7, 0.75), ("crate", 0.8, 0.8, 1.0))


def _door_keepouts(doors, depth: float = 1.3, side: float = 0.3) -> np.ndarray:
    """Axis-aligned (xmin, ymin, xmax, ymax) rectangles in front of every door."""
    out = []
    for d in doors:
        cx, cy = d.center
        half = d.width / 2 + side
        if d.axis == "h":
            out.append((cx - half, cy - depth, cx + half, cy + depth))
        else:
            out.append((cx - depth, cy - half, cx + depth, cy + half))
    return np.asarray(out, dtype=float).reshape(-1, 4)


def _overlaps(box, boxes: np.ndarray, gap: float = 0.0) -> bool:
    if len(boxes) == 0:
        return False
    b = np.asarray(boxes)
    return bool(np.any((box[0] < b[:, 2] + gap) & (box[2] > b[:, 0] - gap)
                       & (box[1] < b[:, 3] + gap) & (box[3] > b[:, 1] - gap)))


def furnish(rooms: list[Room], doors, pillars: np.ndarray, rng,
             wall_kinds=("room",), free_kinds=("open", "hall")) -> np.ndarray:
    """Furniture boxes (K, 6): against the walls of ordinary rooms, and free-standing
    tables far from everything in open areas, so that no door or passage gets blocked.
    doors: every passage (doors and open spans) to keep clear."""
    keepouts = _door_keepouts(doors)
    placed: list[tuple] = []  # axis-aligned footprints, for overlap tests
    items: list[tuple] = []
    inset = EXTERIOR_WALL / 2 + 0.05
    for room in rooms:
        x0, y0, x1, y1 = room.x0 + inset, room.y0 + inset, room.x1 - inset, room.y1 - inset
        small = min(x1 - x0, y1 - y0)
        if room.kind in wall_kinds:
            max_depth = min(0.3 * small, 1.0)
            n_items = int(rng.integers(1, 2 + min(3, int(room.area // 8))))
            for _ in range(n_items):
                for _try in range(20):
                    name, length, depth, height = _WALL_ITEMS[rng.integers(len(_WALL_ITEMS))]
                    side = int(rng.integers(4))  # 0 south, 1 north, 2 west, 3 east
                    wall_len = (x1 - x0) if side < 2 else (y1 - y0)
                    if depth > max_depth or length > 0.8 * wall_len:
                        continue
                    along = rng.uniform(length / 2, wall_len - length / 2)
                    if side == 0:
                        cx, cy, sx, sy = x0 + along, y0 + depth / 2, length, depth
                    elif side == 1:
                        cx, cy, sx, sy = x0 + along, y1 - depth / 2, length, depth
                    elif side == 2:
                        cx, cy, sx, sy = x0 + depth / 2, y0 + along, depth, length
                    else:
                        cx, cy, sx, sy = x1 - depth / 2, y0 + along, depth, length
                    box = (cx - sx / 2, cy - sy / 2, cx + sx / 2, cy + sy / 2)
                    if _overlaps(box, keepouts) or _overlaps(box, placed, gap=0.1):
                        continue
                    if len(pillars) and np.any(np.hypot(pillars[:, 0] - cx, pillars[:, 1] - cy)
                                               < pillars[:, 2] + 0.5 * np.hypot(sx, sy) + 0.3):
                        continue
                    placed.append(box)
                    items.append((cx, cy, sx, sy, 0.0, height))
                    break
        elif room.kind in free_kinds:
            clear = 1.5  # m of free space kept around every free-standing piece
            n_items = int(rng.integers(1, 2 + int(room.area // 40)))
            for _ in range(n_items):
                for _try in range(20):
                    name, length, depth, height = _FREE_ITEMS[rng.integers(len(_FREE_ITEMS))]
                    radius = 0.5 * np.hypot(length, depth)
                    lo_x, hi_x = x0 + clear + radius, x1 - clear - radius
                    lo_y, hi_y = y0 + clear + radius, y1 - clear - radius
                    if lo_x >= hi_x or lo_y >= hi_y:
                        break
                    cx, cy = rng.uniform(lo_x, hi_x), rng.uniform(lo_y, hi_y)
                    box = (cx - radius, cy - radius, cx + radius, cy + radius)
                    if _overlaps(box, keepouts) or _overlaps(box, placed, gap=clear):
                        continue
                    if len(pillars) and np.any(np.hypot(pillars[:, 0] - cx, pillars[:, 1] - cy)
                                               < pillars[:, 2] + radius + clear):
                        continue
                    placed.append(box)
                    items.append((cx, cy, length, depth, float(rng.uniform(-np.pi, np.pi)), height))
                    break
    return np.asarray(items, dtype=float).reshape(-1, 6)


def assemble(name: str, seed: int, rooms: list[Room], connections: list[Connection], rng,
              pillars=(), furniture=None, wall_height: float = 2.7, target_area: float = 0.0,
              waypoints: dict | None = None, info: dict | None = None, doors=None, walls=None) -> Scene:
    """Walls from the plan, raster, interior and walkable masks, waypoints."""
    if walls is None:
        segments, thickness, doors, openings = build_walls(rooms, connections, rng, EXTERIOR_WALL, INTERIOR_WALL)
    else:
        segments, thickness = walls
        openings = []
    pillars = np.asarray(pillars, dtype=float).reshape(-1, 3)
    if furniture is None:
        furniture = furnish(rooms, list(doors) + list(openings), pillars, rng)
    corners = np.array([[r.x0, r.y0] for r in rooms] + [[r.x1, r.y1] for r in rooms])
    grid = grid_around(corners, margin=1.0)
    occupied = rasterize_boxes(grid, *wall_boxes(segments, thickness))
    rasterize_discs(grid, pillars, out=occupied)
    # Outside = free cells connected to the grid border; the building is closed.
    labels, _ = ndimage.label(~occupied)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    interior = ~occupied & ~np.isin(labels, border[border > 0])
    furn_cells = rasterize_boxes(grid, furniture[:, :2], furniture[:, 2:4] / 2, furniture[:, 4])
    free = interior & ~furn_cells
    scene = Scene(name, int(seed), tuple(rooms), segments, thickness, tuple(doors), pillars,
                  furniture, float(wall_height), grid, occupied, interior, free,
                  float(target_area), {}, dict(info or {}))
    wp = {r.name: _best_point(scene, r) for r in rooms}
    wp.update(waypoints or {})
    object.__setattr__(scene, "waypoints", wp)
    return scene


def _best_point(scene: Scene, room: Room) -> tuple[float, float]:
    """The room centre, or the free cell of the room farthest from obstacles if the centre
    is blocked (pillar, table)."""
    cx, cy = room.center
    if scene.clearance_at([[cx, cy]])[0] >= 0.5:
        return (cx, cy)
    r0, r1, c0, c1 = scene.grid.window(room.x0, room.y0, room.x1, room.y1)
    sub = scene.clearance[r0:r1, c0:c1]
    i, j = np.unravel_index(np.argmax(sub), sub.shape)
    x, y = scene.grid.centres(np.array(r0 + i), np.array(c0 + j))
    return (float(x), float(y))


def make_scene(name: str, rooms: list[Room], connections: list[Connection], seed: int = 0, pillars=(),
               furniture=None, wall_height: float = 2.7, waypoints: dict | None = None) -> Scene:
    """A scene from a hand-made room plan (tests, custom layouts). Room coordinates should
    lie on the lattice given by layout.snap; furniture None = seeded automatic furnishing,
    an (K, 6) array = exactly these pieces."""
    rng = make_rng(seed, "scene", name)
    furniture = None if furniture is None else np.asarray(furniture, dtype=float).reshape(-1, 6)
    return assemble(name, seed, list(rooms), list(connections), rng, pillars=pillars, furniture=furniture,
                     wall_height=wall_height, waypoints=waypoints)
