"""From a room plan to walls: the generic part of every built-in scene.

A plan is a set of axis-aligned room rectangles (corridors and halls are rooms too) plus
the connections between them (a door of some width, or an open boundary). Walls are
derived from the room edges: an edge shared by two rooms becomes an interior wall, an edge
with a room on one side only an exterior wall; doors are gaps cut into them. Every wall is
returned as a solid box (centre segment + thickness) already extended by half its
thickness at both ends, so corners and T-junctions close without special cases.

All room coordinates are expected on the lattice `k * res + res / 2` (cell centres of a
grid whose origin is a multiple of res): then a wall of thickness 0.15 m (0.25 m) covers
exactly 3 (5) cells in the raster and the 3D render and the floorplan agree.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..geometry.grid import Grid

RESOLUTION = 0.05  # m per floorplan cell (fixed for the built-in scenes)


def snap(value: float, res: float = RESOLUTION) -> float:
    """Nearest lattice coordinate k*res + res/2 (a cell centre)."""
    return float(np.round(value / res) * res + res / 2)


@dataclass(frozen=True)
class Room:
    name: str
    kind: str  # "room", "corridor", "open", "hall", "annex", "core"
    x0: float
    y0: float
    x1: float
    y1: float

    @property
    def center(self) -> tuple[float, float]:
        return (0.5 * (self.x0 + self.x1), 0.5 * (self.y0 + self.y1))

    @property
    def size(self) -> tuple[float, float]:
        return (self.x1 - self.x0, self.y1 - self.y0)

    @property
    def area(self) -> float:
        return (self.x1 - self.x0) * (self.y1 - self.y0)


@dataclass(frozen=True)
class Connection:
    """Passage between rooms a and b. kind "door": a gap of `width` at `position` (the
    coordinate along the wall; random when None); kind "open": no wall at all between them."""

    a: int
    b: int
    kind: str = "door"
    width: float = 0.9
    position: float | None = None


@dataclass(frozen=True)
class Door:
    center: tuple[float, float]
    width: float
    axis: str  # "h": the door is in a wall running along x; "v": along y
    rooms: tuple[int, int]


def _key(value: float) -> int:
    # Coordinates live on a half-cell lattice: this integer groups equal values exactly.
    return int(np.round(value / (RESOLUTION / 2)))


def _room_edges(rooms: list[Room]):
    """Edges grouped by supporting line: {(axis, key): [(lo, hi, room, side), ...]}.
    side +1: the room lies on the positive side (above a horizontal edge, right of a
    vertical one)."""
    lines: dict[tuple[str, int], list] = defaultdict(list)
    coord: dict[tuple[str, int], float] = {}
    for i, r in enumerate(rooms):
        for axis, c, lo, hi, side in (
            ("h", r.y0, r.x0, r.x1, +1),
            ("h", r.y1, r.x0, r.x1, -1),
            ("v", r.x0, r.y0, r.y1, +1),
            ("v", r.x1, r.y0, r.y1, -1),
        ):
            k = (axis, _key(c))
            lines[k].append((lo, hi, i, side))
            coord[k] = c
    return lines, coord


def _elementary_intervals(edges):
    """Split a line into intervals between all edge endpoints, each with the rooms on its
    negative and positive side (None where there is no room)."""
    ends = sorted({e for lo, hi, _, _ in edges for e in (lo, hi)})
    out = []
    for lo, hi in zip(ends[:-1], ends[1:]):
        if hi - lo < 1e-9:
            continue
        mid = 0.5 * (lo + hi)
        neg = pos = None
        for a, b, room, side in edges:
            if a < mid < b:
                if side > 0:
                    pos = room
                else:
                    neg = room
        if neg is not None or pos is not None:
            out.append((lo, hi, neg, pos))
    return out


def _merge_runs(items):
    """Merge consecutive (lo, hi, tag) intervals that touch and share a tag."""
    merged: list[list] = []
    for lo, hi, tag in items:
        if merged and merged[-1][2] == tag and abs(merged[-1][1] - lo) < 1e-9:
            merged[-1][1] = hi
        else:
            merged.append([lo, hi, tag])
    return merged


def build_walls(rooms: list[Room], connections: list[Connection], rng: np.random.Generator,
                exterior: float = 0.25, interior: float = 0.15, door_margin: float = 0.3):
    """Walls (as boxes) and doors of a room plan.

    Returns (segments (N, 2, 2), thickness (N,), doors list[Door], openings list[Door]).
    Each segment is the centre line of a solid box of the given thickness; openings are the
    wall-free spans of "open" connections (as Door records), so furnishing can keep them
    clear like doors.
    """
    lines, coord = _room_edges(rooms)
    open_pairs = {frozenset((c.a, c.b)) for c in connections if c.kind == "open"}

    walls = []  # (axis, key, lo, hi, thickness)
    pieces_by_pair: dict[tuple, list] = defaultdict(list)  # (pair, axis, key) -> [(lo, hi, 0)]
    for (axis, k), edges in lines.items():
        tagged = []
        for lo, hi, neg, pos in _elementary_intervals(edges):
            if neg is not None and pos is not None:
                pair = frozenset((neg, pos))
                pieces_by_pair[(pair, axis, k)].append((lo, hi, 0))
                if pair in open_pairs:
                    continue
                tagged.append((lo, hi, interior))
            else:
                tagged.append((lo, hi, exterior))
        for lo, hi, t in _merge_runs(tagged):
            walls.append((axis, k, lo, hi, t))
    shared: dict[frozenset, list] = defaultdict(list)  # room pair -> [(axis, key, lo, hi)]
    for (pair, axis, k), items in pieces_by_pair.items():
        shared[pair] += [(axis, k, lo, hi) for lo, hi, _ in _merge_runs(items)]

    doors: list[Door] = []
    cuts: dict[tuple[str, int], list] = defaultdict(list)
    for c in connections:
        if c.kind != "door":
            continue
        spans = shared.get(frozenset((c.a, c.b)))
        if not spans:
            raise RuntimeError(f"rooms {rooms[c.a].name} and {rooms[c.b].name} share no wall")
        axis, k, lo, hi = max(spans, key=lambda s: s[3] - s[2])
        half = c.width / 2
        if c.position is not None:
            centre = float(c.position)
            if not lo + half <= centre <= hi - half:
                raise RuntimeError(f"door {rooms[c.a].name}-{rooms[c.b].name} outside their wall")
        else:
            margin = door_margin if hi - lo >= c.width + 2 * door_margin else 0.05
            if hi - lo < c.width + 2 * margin:
                raise RuntimeError(f"wall {rooms[c.a].name}-{rooms[c.b].name} too short for a door")
            centre = float(rng.uniform(lo + margin + half, hi - margin - half))
        cuts[(axis, k)].append((centre - half, centre + half))
        xy = (centre, coord[(axis, k)]) if axis == "h" else (coord[(axis, k)], centre)
        doors.append(Door(xy, float(c.width), axis, (c.a, c.b)))

    openings = [Door((0.5 * (lo + hi), coord[(axis, k)]) if axis == "h" else (coord[(axis, k)], 0.5 * (lo + hi)),
                     hi - lo, axis, tuple(sorted(pair)))
                for pair in open_pairs for axis, k, lo, hi in shared.get(pair, ())]
    segments, thickness = [], []
    for axis, k, lo, hi, t in walls:
        pieces = [(lo - t / 2, hi + t / 2)]
        for da, db in cuts.get((axis, k), ()):
            pieces = [p for a, b in pieces for p in ((a, min(b, da)), (max(a, db), b)) if p[1] - p[0] > 1e-6]
        c = coord[(axis, k)]
        for a, b in pieces:
            seg = [[a, c], [b, c]] if axis == "h" else [[c, a], [c, b]]
            segments.append(seg)
            thickness.append(t)
    return np.asarray(segments, dtype=float).reshape(-1, 2, 2), np.asarray(thickness, dtype=float), doors, openings


# --- rasterisation -----------------------------------------------------------------------


def grid_around(points: np.ndarray, margin: float = 1.0, res: float = RESOLUTION) -> Grid:
    lo = np.floor((points.min(axis=0) - margin) / res) * res
    hi = np.ceil((points.max(axis=0) + margin) / res) * res
    shape = tuple(int(v) for v in np.round((hi - lo) / res))[::-1]
    return Grid((float(lo[0]), float(lo[1])), res, shape)


def rasterize_boxes(grid: Grid, centers, half_sizes, yaws, out: np.ndarray | None = None) -> np.ndarray:
    """Mark cells whose centre lies strictly inside any oriented box.

    centers (N, 2), half_sizes (N, 2) along the box's own x/y axes, yaws (N,)."""
    out = np.zeros(grid.shape, dtype=bool) if out is None else out
    for (cx, cy), (hx, hy), yaw in zip(np.asarray(centers), np.asarray(half_sizes), np.asarray(yaws)):
        c, s = np.cos(yaw), np.sin(yaw)
        ex, ey = abs(c) * hx + abs(s) * hy, abs(s) * hx + abs(c) * hy  # axis-aligned half extent
        r0, r1, c0, c1 = grid.window(cx - ex, cy - ey, cx + ex, cy + ey)
        if r0 >= r1 or c0 >= c1:
            continue
        x, y = grid.centres(np.arange(r0, r1)[:, None], np.arange(c0, c1)[None, :])
        u = (x - cx) * c + (y - cy) * s
        v = -(x - cx) * s + (y - cy) * c
        out[r0:r1, c0:c1] |= (np.abs(u) < hx - 1e-9) & (np.abs(v) < hy - 1e-9)
    return out


def rasterize_discs(grid: Grid, discs, out: np.ndarray | None = None) -> np.ndarray:
    """Mark cells whose centre lies inside any disc (cx, cy, r)."""
    out = np.zeros(grid.shape, dtype=bool) if out is None else out
    for cx, cy, r in np.asarray(discs, dtype=float).reshape(-1, 3):
        r0, r1, c0, c1 = grid.window(cx - r, cy - r, cx + r, cy + r)
        if r0 >= r1 or c0 >= c1:
            continue
        x, y = grid.centres(np.arange(r0, r1)[:, None], np.arange(c0, c1)[None, :])
        out[r0:r1, c0:c1] |= (x - cx) ** 2 + (y - cy) ** 2 < r * r
    return out


def wall_boxes(segments: np.ndarray, thickness: np.ndarray):
    """(centers, half_sizes, yaws) of wall boxes from centre segments + thickness."""
    d = segments[:, 1] - segments[:, 0]
    length = np.linalg.norm(d, axis=1)
    centers = segments.mean(axis=1)
    half = np.stack([length / 2, thickness / 2], axis=1)
    return centers, half, np.arctan2(d[:, 1], d[:, 0])
