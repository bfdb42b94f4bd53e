"""A small synthetic building and a BEV observation of it seen through a known alignment:
the scoring, RANSAC, refinement and torch-scoring tests' shared world."""

import numpy as np
from scipy.ndimage import distance_transform_edt

from zfloc_stream.settings.loading import Settings
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.observation import BevObservation
from zfloc_stream.geometry.sim2 import Sim2

RES = 0.05


def building() -> Floorplan:
    """12 x 8 m, 0.2 m outer walls; an interior wall at x = 5 with a door, and a short
    wall stub in the right room (so the layout has no symmetry)."""
    w, h = int(13 / RES), int(9 / RES)
    occ = np.zeros((h, w), dtype=bool)

    def box(x0, y0, x1, y1):
        occ[int(round(y0 / RES)) : int(round(y1 / RES)), int(round(x0 / RES)) : int(round(x1 / RES))] = True

    box(0.5, 0.5, 12.5, 0.7)
    box(0.5, 8.3, 12.5, 8.5)
    box(0.5, 0.5, 0.7, 8.5)
    box(12.3, 0.5, 12.5, 8.5)
    box(5.0, 0.5, 5.15, 3.0)  # interior wall with a door between y = 3 and 4
    box(5.0, 4.0, 5.15, 8.5)
    box(9.0, 5.5, 12.5, 5.65)  # stub
    return Floorplan.from_occupancy(occ, RES, (0.0, 0.0), Settings())


def observe(fp: Floorplan, truth: Sim2, centre, radius: float) -> BevObservation:
    """A BEV of the floorplan around `centre` (floorplan frame) seen through `truth`:
    floorplan wall faces within `radius` seen from inside (no occlusion otherwise) mapped
    into the BEV frame, free
    space = non-wall floorplan cells inside the building within the radius."""
    inv = truth.inverse()
    faces = fp.face_points[np.linalg.norm(fp.face_points - centre, axis=1) < radius]
    # only faces seen from inside (the outer faces of the exterior walls are at 0.525 / 12.475 / 8.475)
    faces = faces[(faces[:, 0] > 0.6) & (faces[:, 0] < 12.4) & (faces[:, 1] > 0.6) & (faces[:, 1] < 8.4)]
    walls = inv.apply(faces)
    lo = walls.min(axis=0) - 1.0
    n = np.ceil((walls.max(axis=0) + 1.0 - lo) / RES).astype(int)
    rows, cols = np.mgrid[0 : n[1], 0 : n[0]]
    centres = lo + (np.stack([cols, rows], axis=-1) + 0.5) * RES
    mapped = truth.apply(centres.reshape(-1, 2))
    inside = fp.contains(mapped)
    r, c = fp.world_to_cell(mapped)
    x0, y0, x1, y1 = 0.7, 0.7, 12.3, 8.3
    in_building = (mapped[:, 0] > x0) & (mapped[:, 0] < x1) & (mapped[:, 1] > y0) & (mapped[:, 1] < y1)
    wall = np.zeros(len(mapped), dtype=bool)
    wall[inside] = fp.occupied[r[inside], c[inside]]
    near = np.linalg.norm(mapped - centre, axis=1) < radius - 0.3
    free = (~wall & in_building & near).reshape(n[1], n[0])
    occupied = np.zeros_like(free)
    wr = np.floor((walls - lo) / RES).astype(int)
    occupied[wr[:, 1], wr[:, 0]] = True
    clearance = np.where(free, distance_transform_edt(~occupied) * RES, 0.0)
    return BevObservation(walls, lo, RES, free & ~occupied, clearance)
