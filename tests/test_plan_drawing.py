"""A raster map redrawn as an architect's plan (benchmarks/evaluation/plan_drawing.py): the walls become straight
segments, clutter goes, doors stay open, and the DXF loads through the vector path."""

import numpy as np

from zfloc_stream.settings.loading import Settings
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.plans.vector import load_vector_floorplan

# plan_drawing is the evaluation's (eval_real.py --plan-style), not the package's
from benchmarks.evaluation.plan_drawing import draw_plan, two_faces, write_plan_dxf

RES = 0.05


def cluttered_rooms() -> tuple[Floorplan, np.ndarray]:
    """Two 6 x 4 m rooms (walls 2 cells thick) with a 1 m door between them, plus specks
    of clutter (furniture legs, people); returns the map and the clutter centres."""
    occ = np.zeros((100, 160), dtype=bool)
    occ[10:12, 10:150] = occ[88:90, 10:150] = True  # y = 0.5 and 4.4 m
    occ[10:90, 10:12] = occ[10:90, 148:150] = True
    occ[10:40, 79:81] = occ[60:90, 79:81] = True  # the dividing wall, door from y = 2.0 to 3.0 m
    rng = make_rng(0, "clutter")  # isolated specks, about 1 m apart, jittered
    rows, cols = np.meshgrid(np.arange(22, 80, 20), np.arange(22, 140, 20), indexing="ij")
    specks = np.column_stack([rows.ravel(), cols.ravel()]) + rng.integers(-4, 5, (rows.size, 2))
    specks = specks[np.abs(specks[:, 1] - 80) > 8]
    for r, c in specks:
        occ[r : r + 3, c : c + 3] = True
    return Floorplan.from_occupancy(occ, RES, (0.0, 0.0), Settings()), (specks[:, ::-1] + 1.5) * RES


def test_walls_become_segments_and_clutter_goes(tmp_path):
    fp, clutter = cluttered_rooms()
    segs = draw_plan(fp)
    assert 6 <= len(segs) <= 12  # 4 outer walls + 2 pieces of the divider, maybe split at corners
    plan = load_vector_floorplan(write_plan_dxf(segs, tmp_path / "plan.dxf"), Settings())
    walls = fp.sample_wall_points(0.1)
    walls = walls[np.min(np.linalg.norm(walls[:, None] - clutter[None], axis=2), axis=1) > 0.2]
    assert (plan.distance(walls) < 0.15).mean() > 0.95  # the plan draws the map's walls
    assert (plan.distance(clutter) > 0.3).all()  # and none of the clutter
    door = np.column_stack([np.full(5, 4.0), np.linspace(2.1, 2.9, 5)])
    assert (plan.distance(door) > 0.08).all()  # the door is a gap


def test_two_face_walls_are_offset_both_ways():
    segs = np.array([[[0.0, 0.0], [4.0, 0.0]], [[1.0, 1.0], [1.0, 3.0]]])
    faces = two_faces(segs, 0.2)
    assert faces.shape == (4, 2, 2)
    assert np.allclose(sorted(faces[[0, 2], 0, 1]), [-0.1, 0.1])
    assert np.allclose(sorted(faces[[1, 3], 0, 0]), [0.9, 1.1])


def test_two_faces_keep_the_seen_surface_and_put_the_wall_behind_it():
    """With the map's free cells: a wall seen from one side keeps its line as that face and
    gets the other face behind it (never inside the open space the sensor saw); a wall seen
    from both sides is one map cell thick; a wall seen from neither side stays centred."""
    res, origin = 0.05, np.array([0.0, 0.0])
    free = np.zeros((120, 120), dtype=bool)  # 6 x 6 m
    free[:40, :] = True  # open below y = 2 m: the wall at y = 2 is seen from below only
    free[40:, 80:100] = True  # a corridor x in [4, 5] m above the wall
    segs = np.array([[[0.5, 2.0], [3.5, 2.0]],  # y = 2: seen from below only
                     [[4.0, 3.0], [4.0, 5.5]],  # x = 4: free on +x only (the corridor), above y = 2
                     [[1.0, 4.0], [3.0, 4.0]]])  # y = 4, x in [1, 3]: unknown on both sides
    faces = two_faces(segs, 0.2, (free, origin, res))
    assert faces.shape == (6, 2, 2)
    assert np.allclose(sorted(faces[[0, 3], 0, 1]), [2.0, 2.2])  # the room's face stays, the wall goes up
    assert np.allclose(sorted(faces[[1, 4], 0, 0]), [3.8, 4.0])  # the corridor's face stays, the wall goes to -x
    assert np.allclose(sorted(faces[[2, 5], 0, 1]), [3.9, 4.1])  # seen from neither side: centred
    free[40:, :80] = True  # now the wall at y = 2 is seen from both sides
    faces = two_faces(segs, 0.2, (free, origin, res))
    assert np.allclose(sorted(faces[[0, 3], 0, 1]), [1.975, 2.025])
