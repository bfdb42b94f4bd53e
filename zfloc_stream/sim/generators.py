"""The built-in scene generators, each a function of the seed alone: rooms (a guillotine-cut
flat), apartment, office (an open plan with pillars), hall, symmetric (a plan with
symmetries: the localizer's ambiguous case) and offices (a corridor of identical offices).
Each lays out its rooms and doors and hands them to assembly.assemble."""

from __future__ import annotations

import numpy as np

from ..runtime.rng import make_rng
from .assembly import DOOR_WIDTH, EXTERIOR_WALL, INTERIOR_WALL, assemble, furnish, partition, random_tree_doors
from .layout import RESOLUTION, Connection, Room, build_walls, snap
from .scene import Scene


def generate_rooms(seed: int) -> Scene:
    """2-4 rooms, ~40 m2: a rectangle cut guillotine-style, doors on a random tree."""
    rng = make_rng(seed, "scene", "rooms")
    area = rng.uniform(36.0, 43.0)
    aspect = rng.uniform(1.1, 1.6)
    width = np.sqrt(area * aspect)
    x0, y0 = snap(0.0), snap(0.0)
    rects = [(x0, y0, snap(width), snap(area / width))]
    n_rooms = int(rng.integers(1, 4))  # plus a small alcove room outside the rectangle
    min_side = 2.4
    while len(rects) < n_rooms:
        order = np.argsort([-(r[2] - r[0]) * (r[3] - r[1]) for r in rects])
        for k in order:
            a, b, c, d = rects[k]
            horizontal = (c - a) >= (d - b)  # cut across the longer side
            lo, hi = (a, c) if horizontal else (b, d)
            if hi - lo < 2 * min_side + 0.1:
                continue
            cut = snap(lo + rng.uniform(max(0.35, min_side / (hi - lo)),
                                        min(0.65, 1 - min_side / (hi - lo))) * (hi - lo))
            rects[k:k + 1] = [(a, b, cut, d), (cut, b, c, d)] if horizontal else [(a, b, c, cut), (a, cut, c, d)]
            break
        else:
            break
    rooms = [Room(f"room{i}", "room", *r) for i, r in enumerate(rects)]
    rooms.append(_alcove(rooms, rng))
    connections = random_tree_doors(rooms[:-1], rng)
    connections.append(Connection(len(rooms) - 2, len(rooms) - 1, "door", DOOR_WIDTH))
    return assemble("rooms", seed, rooms, connections, rng, wall_height=rng.uniform(2.5, 2.8),
                     target_area=40.0)


def _alcove(rooms: list[Room], rng) -> Room:
    """A small room (closet, bathroom) stuck onto the outside of the building, off-centre
    along one outer wall of one room: it breaks the outline's symmetry. Returned last; it
    touches only rooms[-1] after the caller's reordering (the host room is moved last)."""
    xmin, ymin = min(r.x0 for r in rooms), min(r.y0 for r in rooms)
    xmax, ymax = max(r.x1 for r in rooms), max(r.y1 for r in rooms)
    width, depth = rng.uniform(1.8, 2.6), rng.uniform(1.6, 2.2)
    options = []  # (host index, side) with enough outer wall for the alcove
    for i, r in enumerate(rooms):
        for side, on_edge, extent in (("s", r.y0 == ymin, r.x1 - r.x0), ("n", r.y1 == ymax, r.x1 - r.x0),
                                      ("w", r.x0 == xmin, r.y1 - r.y0), ("e", r.x1 == xmax, r.y1 - r.y0)):
            if on_edge and extent >= width + 0.3:
                options.append((i, side))
    host_index, side = options[int(rng.integers(len(options)))]
    host = rooms.pop(host_index)
    rooms.append(host)  # host last, the alcove right after it
    lo, hi = (host.x0, host.x1) if side in "sn" else (host.y0, host.y1)
    slack = hi - lo - width
    # keep the alcove near one end of the host wall: never centred
    start = lo + (rng.uniform(0.0, 0.25) if rng.random() < 0.5 else rng.uniform(0.75, 1.0)) * slack
    a, b = snap(start), snap(start + width)
    if side == "s":
        return Room("alcove", "room", a, snap(host.y0 - depth), b, host.y0)
    if side == "n":
        return Room("alcove", "room", a, host.y1, b, snap(host.y1 + depth))
    if side == "w":
        return Room("alcove", "room", snap(host.x0 - depth), a, host.x0, b)
    return Room("alcove", "room", host.x1, a, snap(host.x1 + depth), b)


def generate_apartment(seed: int) -> Scene:
    """~100 m2: a hallway with rooms on both sides and a living room across one end."""
    rng = make_rng(seed, "scene", "apartment")
    width, depth = rng.uniform(11.5, 13.0), rng.uniform(8.6, 9.6)
    xa, xb, ya, yb = snap(0.0), snap(width), snap(0.0), snap(depth)
    living_w = rng.uniform(4.2, 5.2)
    living_west = bool(rng.random() < 0.5)
    if living_west:
        living = Room("living", "room", xa, ya, snap(xa + living_w), yb)
        band = (living.x1, xb)
    else:
        living = Room("living", "room", snap(xb - living_w), ya, xb, yb)
        band = (xa, living.x0)
    h0 = snap(ya + rng.uniform(3.2, 4.0))
    h1 = snap(h0 + rng.uniform(1.2, 1.5))
    hallway = Room("hallway", "corridor", band[0], h0, band[1], h1)
    rooms = [living, hallway]
    connections = [Connection(0, 1, "open")]  # the hallway opens into the living room
    south = partition(band[0], band[1], 2.4, 4.6, rng)
    north = partition(band[0], band[1], 2.6, 4.6, rng)
    for tag, cuts, lo, hi in (("south", south, ya, h0), ("north", north, h1, yb)):
        for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
            rooms.append(Room(f"{tag}{k}", "room", a, lo, b, hi))
            connections.append(Connection(1, len(rooms) - 1, "door", float(rng.choice([0.8, 0.9]))))
            touches_living = abs(a - living.x1) < 1e-6 or abs(b - living.x0) < 1e-6
            if touches_living and rng.random() < 0.5:
                connections.append(Connection(0, len(rooms) - 1, "door", 0.9))
    return assemble("apartment", seed, rooms, connections, rng, wall_height=rng.uniform(2.5, 2.8),
                     target_area=100.0, info={"living_west": living_west})


def _open_plan_pillars(room: Room, rng, margin: float = 2.5) -> list[tuple[float, float, float]]:
    """A regular pillar grid inside an open area, offset unevenly from its walls."""
    spacing_x, spacing_y = rng.uniform(6.0, 7.5), rng.uniform(5.5, 7.0)
    radius = float(rng.uniform(0.25, 0.35))
    xs = np.arange(room.x0 + rng.uniform(margin, margin + 2.0), room.x1 - margin, spacing_x)
    ys = np.arange(room.y0 + rng.uniform(margin, margin + 2.0), room.y1 - margin, spacing_y)
    return [(snap(x), snap(y), radius) for x in xs for y in ys]


def generate_office(seed: int) -> Scene:
    """~2500 m2: two long corridors joined by cross corridors, offices along the facades,
    an open-plan area with round pillars, meeting rooms and service cores in the middle."""
    rng = make_rng(seed, "scene", "office")
    width = rng.uniform(56.0, 62.0)
    depth = 2680.0 / width + rng.uniform(-1.0, 1.0)
    ds, dn = rng.uniform(5.0, 6.5), rng.uniform(5.0, 6.5)
    wc_s, wc_n = rng.uniform(1.8, 2.4), rng.uniform(1.8, 2.4)
    X0, X1 = snap(0.0), snap(width)
    y0, y5 = snap(0.0), snap(depth)
    y1 = snap(ds)
    y2 = snap(ds + wc_s)
    y4 = snap(depth - dn)
    y3 = snap(depth - dn - wc_n)
    rooms: list[Room] = []
    connections: list[Connection] = []

    def add(room: Room) -> int:
        rooms.append(room)
        return len(rooms) - 1

    cs = add(Room("corridor_s", "corridor", X0, y1, X1, y2))
    cn = add(Room("corridor_n", "corridor", X0, y3, X1, y4))
    for tag, lo, hi, corridor in (("s", y0, y1, cs), ("n", y4, y5, cn)):
        cuts = partition(X0, X1, 3.0, 6.0, rng)
        k = 0
        i = 0
        while i < len(cuts) - 1:
            # now and then two offices are one bigger room (meeting room, lab)
            j = i + 2 if (i + 2 < len(cuts) and rng.random() < 0.15) else i + 1
            idx = add(Room(f"office_{tag}{k}", "room", cuts[i], lo, cuts[j], hi))
            connections.append(Connection(corridor, idx, "door", DOOR_WIDTH))
            i, k = j, k + 1
    # cross corridors split the middle band into an end block at each side and two blocks
    wv = [rng.uniform(1.8, 2.4) for _ in range(3)]
    xa = snap(rng.uniform(6.0, 9.0))
    xc = snap(width - rng.uniform(6.0, 12.0) - wv[2])
    xb = snap(rng.uniform(0.42, 0.58) * width)
    cross_x = [(xa, snap(xa + wv[0])), (xb, snap(xb + wv[1])), (xc, snap(xc + wv[2]))]
    cross = []
    for k, (a, b) in enumerate(cross_x):
        c = add(Room(f"cross{k}", "corridor", a, y2, b, y3))
        connections += [Connection(c, cs, "open"), Connection(c, cn, "open")]
        cross.append(c)
    # end blocks: service cores (stairs, toilets, storage) opening onto the cross corridor
    for tag, a, b, corridor in (("w", X0, cross_x[0][0], cross[0]), ("e", cross_x[2][1], X1, cross[2])):
        cuts = partition(y2, y3, 3.0, 8.0, rng)
        for k, (lo, hi) in enumerate(zip(cuts[:-1], cuts[1:])):
            idx = add(Room(f"core_{tag}{k}", "core", a, lo, b, hi))
            connections.append(Connection(corridor, idx, "door", DOOR_WIDTH))
    # middle blocks: one open-plan area with pillars, one with two rows of meeting rooms
    blocks = [(cross_x[0][1], cross_x[1][0], cross[0], cross[1]), (cross_x[1][1], cross_x[2][0], cross[1], cross[2])]
    open_first = bool(rng.random() < 0.5)
    pillars: list[tuple[float, float, float]] = []
    for k, (a, b, left, right) in enumerate(blocks):
        if (k == 0) == open_first:
            idx = add(Room(f"open{k}", "open", a, y2, b, y3))
            connections += [Connection(idx, cs, "door", float(rng.uniform(2.5, 4.0))),
                            Connection(idx, cn, "door", float(rng.uniform(2.5, 4.0))),
                            Connection(idx, left, "door", 1.8)]
            pillars += _open_plan_pillars(rooms[idx], rng)
        else:
            ym = snap(0.5 * (y2 + y3) + rng.uniform(-2.0, 2.0))
            for tag, lo, hi, corridor in (("s", y2, ym, cs), ("n", ym, y3, cn)):
                cuts = partition(a, b, 4.0, 8.0, rng)
                for m, (c0, c1) in enumerate(zip(cuts[:-1], cuts[1:])):
                    idx = add(Room(f"meeting{k}_{tag}{m}", "room", c0, lo, c1, hi))
                    connections.append(Connection(corridor, idx, "door", DOOR_WIDTH))
    return assemble("office", seed, rooms, connections, rng, pillars=pillars,
                     wall_height=rng.uniform(2.7, 3.0), target_area=2500.0)


def generate_hall(seed: int) -> Scene:
    """~500 m2: a pillared hall, a row of side rooms along part of one long side and an
    entrance lobby off one short side (these break the hall's symmetry)."""
    rng = make_rng(seed, "scene", "hall")
    width, depth = rng.uniform(22.0, 26.0), rng.uniform(15.0, 18.0)
    X0, Y0, X1, Y1 = snap(0.0), snap(0.0), snap(width), snap(depth)
    rooms = [Room("hall", "hall", X0, Y0, X1, Y1)]
    connections: list[Connection] = []
    annex_end = snap(width * rng.uniform(0.55, 0.8))
    annex_top = snap(depth + rng.uniform(4.0, 5.0))
    cuts = partition(X0, annex_end, 3.0, 6.0, rng)
    for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        rooms.append(Room(f"side{k}", "room", a, Y1, b, annex_top))
        connections.append(Connection(0, len(rooms) - 1, "door", DOOR_WIDTH))
    ly0 = snap(rng.uniform(1.5, depth - 8.0))
    rooms.append(Room("lobby", "room", X1, ly0, snap(width + rng.uniform(4.0, 6.0)), snap(ly0 + rng.uniform(5.0, 7.0))))
    connections.append(Connection(0, len(rooms) - 1, "door", float(rng.uniform(2.4, 3.0))))
    pillars = _open_plan_pillars(rooms[0], rng, margin=3.5)
    return assemble("hall", seed, rooms, connections, rng, pillars=pillars,
                     wall_height=rng.uniform(2.8, 3.0), target_area=500.0)


def generate_symmetric(seed: int) -> Scene:
    """A long corridor with rooms on both sides, point-symmetric about its centre (a place
    and its 180-degree image look identical), plus an annex off the east end that is the
    only distinguishing part.

    Waypoints: 'symmetric_start' -> 'symmetric_end' runs along the corridor inside the
    symmetric part, at least `info['sym_margin']` m from both ends (so neither the annex
    nor its absent mirror image is within a 10 m sensor range); 'distinguishing' is in the
    annex.
    """
    rng = make_rng(seed, "scene", "symmetric")
    res = RESOLUTION
    q = lambda v: float(np.round(v / res) * res)  # noqa: E731, symmetric lattice: q(-v) = -q(v)
    half = q(rng.uniform(20.0, 23.0))
    hw = q(rng.uniform(1.0, 1.2))
    band = q(rng.uniform(4.0, 5.2))
    # Everything is built about (0, 0) and shifted by half a cell, so the point reflection
    # about the centre maps raster cell centres onto cell centres.
    c = res / 2
    rooms = [Room("corridor", "corridor", -half + c, -hw + c, half + c, hw + c)]
    connections: list[Connection] = []
    cuts = [q(v) for v in partition(-half, half, 3.0, 5.5, rng)]
    cuts[0], cuts[-1] = -half, half
    furniture = []
    for k, (a, b) in enumerate(zip(cuts[:-1], cuts[1:])):
        south = Room(f"south{k}", "room", a + c, -hw - band + c, b + c, -hw + c)
        north = Room(f"north{k}", "room", -b + c, hw + c, -a + c, hw + band + c)
        rooms += [south, north]
        p = q(rng.uniform(a + 0.5 + DOOR_WIDTH / 2, b - 0.5 - DOOR_WIDTH / 2))
        connections += [Connection(0, len(rooms) - 2, "door", DOOR_WIDTH, p + c),
                        Connection(0, len(rooms) - 1, "door", DOOR_WIDTH, -p + c)]
    annex = Room("annex", "room", half + c, -hw - q(rng.uniform(1.0, 2.0)) + c,
                 half + q(rng.uniform(3.5, 4.5)) + c, hw + q(rng.uniform(2.0, 3.0)) + c)
    rooms.append(annex)
    connections.append(Connection(0, len(rooms) - 1, "open"))
    segments, thickness, doors, _ = build_walls(rooms, connections, rng, EXTERIOR_WALL, INTERIOR_WALL)
    # Furniture: furnish the south rooms, then mirror it into the north rooms through the
    # centre so that the symmetric part stays symmetric in 3D as well.
    south_rooms = [r for r in rooms if r.name.startswith("south")]
    south_doors = [d for d in doors if rooms[d.rooms[1]].name.startswith("south")]
    base = furnish(south_rooms, south_doors, np.zeros((0, 3)), rng)
    mirrored = base.copy()
    mirrored[:, :2] = 2 * c - base[:, :2]
    mirrored[:, 4] = base[:, 4] + np.pi
    # One cabinet against the annex's far wall (the annex is open towards the corridor, so
    # the generic furnisher, which treats every side as a wall, is not used there).
    annex_furniture = np.array([[annex.x1 - EXTERIOR_WALL / 2 - 0.3, annex.center[1], 0.45, 1.2, 0.0, 1.1]])
    furniture = np.concatenate([base, mirrored, annex_furniture])
    margin = 13.0
    waypoints = {
        "symmetric_start": (-half + margin + c, c),
        "symmetric_end": (half - margin + c, c),
        "distinguishing": annex.center,
    }
    info = {"symmetry_center": (c, c), "symmetric_x_range": (-half + c, half + c), "sym_margin": margin}
    return assemble("symmetric", seed, rooms, connections, rng, furniture=furniture,
                     wall_height=2.7, target_area=450.0, waypoints=waypoints, info=info,
                     doors=doors, walls=(segments, thickness))


def generate_offices(seed: int) -> Scene:
    """A repetitive building: one long corridor with identical offices on both sides (the
    same width, depth, door offset and furniture in every office of a side), a stair core
    at the west end and a kitchen at the east end. A place in the corridor and the place
    whole offices along it look the same until an end comes into view (a kidnap to a place
    that looks like the old one).

    The office width `info['period']` is a whole number of raster cells, so the raster (the
    floorplan) and the 3D scene repeat exactly. Waypoints: 'west_end', 'east_end' (corridor
    ends), 'stairs', 'kitchen', one per office ('south{k}', 'north{k}'), and the door
    points 'south{k}_door', 'north{k}_door' in the corridor in front of each door.
    info: period, n_offices, corridor (x0, y0, x1, y1).
    """
    rng = make_rng(seed, "scene", "offices")
    res = RESOLUTION
    cells = lambda v: float(np.round(v / res) * res)  # noqa: E731, a whole number of cells
    period = cells(rng.uniform(3.2, 3.8))
    n = int(rng.integers(9, 12))
    hw = cells(rng.uniform(0.9, 1.1))
    depth_s, depth_n = cells(rng.uniform(4.0, 5.0)), cells(rng.uniform(4.0, 5.0))
    x0, x1 = snap(0.0), snap(0.0) + n * period
    ya, yb = snap(0.0), snap(0.0) + 2 * hw
    corridor = Room("corridor", "corridor", x0, ya, x1, yb)
    rooms = [corridor]
    connections: list[Connection] = []
    # one door offset per side, drawn once: every office of a side is the same office
    margin = 0.45 + DOOR_WIDTH / 2
    door_s = cells(rng.uniform(margin, period - margin))
    door_n = cells(rng.uniform(margin, period - margin))
    for k in range(n):
        a, b = x0 + k * period, x0 + (k + 1) * period
        rooms.append(Room(f"south{k}", "room", a, ya - depth_s, b, ya))
        connections.append(Connection(0, len(rooms) - 1, "door", DOOR_WIDTH, a + door_s))
        rooms.append(Room(f"north{k}", "room", a, yb, b, yb + depth_n))
        connections.append(Connection(0, len(rooms) - 1, "door", DOOR_WIDTH, a + door_n))
    # the ends differ from the offices and from each other (the building is not symmetric)
    stairs = Room("stairs", "core", snap(x0 - rng.uniform(3.0, 4.0)), ya - cells(rng.uniform(1.0, 2.0)),
                  x0, yb + cells(rng.uniform(2.5, 3.5)))
    kitchen = Room("kitchen", "room", x1, ya - depth_s, snap(x1 + rng.uniform(5.0, 6.5)), yb)
    rooms += [stairs, kitchen]
    connections += [Connection(0, len(rooms) - 2, "door", 1.4, 0.5 * (ya + yb)),
                    Connection(0, len(rooms) - 1, "door", 1.0, 0.5 * (ya + yb))]
    segments, thickness, doors, _ = build_walls(rooms, connections, rng, EXTERIOR_WALL, INTERIOR_WALL)
    # Furniture: the first office of each side, copied into every office of that side.
    copies = []
    for tag in ("south", "north"):
        first = next(i for i, r in enumerate(rooms) if r.name == f"{tag}0")
        base = furnish([rooms[first]], [d for d in doors if first in d.rooms], np.zeros((0, 3)), rng)
        for k in range(n):
            shifted = base.copy()
            shifted[:, 0] += k * period
            copies.append(shifted)
    ends = [i for i, r in enumerate(rooms) if r.name in ("stairs", "kitchen")]
    copies.append(furnish([rooms[i] for i in ends], [d for d in doors if set(d.rooms) & set(ends)],
                           np.zeros((0, 3)), rng, wall_kinds=("room", "core")))
    furniture = np.concatenate(copies)
    mid = 0.5 * (ya + yb)
    waypoints = {"west_end": (x0 + 0.8, mid), "east_end": (x1 - 0.8, mid)}
    for k in range(n):
        waypoints[f"south{k}_door"] = (x0 + k * period + door_s, mid)
        waypoints[f"north{k}_door"] = (x0 + k * period + door_n, mid)
    info = {"period": period, "n_offices": n, "corridor": (x0, ya, x1, yb)}
    return assemble("offices", seed, rooms, connections, rng, furniture=furniture,
                     wall_height=2.7, target_area=float(n * period * (depth_s + depth_n + 2 * hw)),
                     waypoints=waypoints, info=info, doors=doors, walls=(segments, thickness))
