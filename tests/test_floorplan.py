import cv2
import numpy as np
import pytest
import yaml

from zfloc_stream.settings.loading import Settings
from zfloc_stream.errors import FloorplanError, InputError, ZflocError
from zfloc_stream.plans.floorplan import Floorplan


def room_grid(h=60, w=80, thickness=2):
    """Rectangular room (walls `thickness` cells) with an inner wall stub, internal convention."""
    occ = np.zeros((h, w), dtype=bool)
    occ[:thickness], occ[-thickness:], occ[:, :thickness], occ[:, -thickness:] = True, True, True, True
    occ[20 : 20 + thickness, 10:50] = True
    return occ


@pytest.fixture(scope="module")
def room():
    return Floorplan.from_occupancy(room_grid(), 0.05, (-1.0, 2.0), name="room")


# --- loading -------------------------------------------------------------------------------


def test_ros_round_trip(tmp_path, room):
    path = room.write_ros(tmp_path, "plan")
    assert path.name == "plan.yaml" and (tmp_path / "plan.png").is_file()
    back = Floorplan.load(path)
    assert np.array_equal(back.occupied, room.occupied)
    assert back.resolution == room.resolution
    assert np.allclose(back.origin, room.origin)
    # ROS images have row 0 = largest y: the top image row holds the top wall of the grid
    img = cv2.imread(str(tmp_path / "plan.png"), cv2.IMREAD_GRAYSCALE)
    assert np.array_equal(img == 0, room.occupied[::-1])


def test_ros_round_trip_negated(tmp_path, room):
    """The same map written with negate=1 (inverted image) reads back identically."""
    path = room.write_ros(tmp_path, "plan")
    img = cv2.imread(str(tmp_path / "plan.png"), cv2.IMREAD_GRAYSCALE)
    cv2.imwrite(str(tmp_path / "neg.png"), 255 - img)
    meta = yaml.safe_load(path.read_text())
    meta.update(image="neg.png", negate=1)
    (tmp_path / "neg.yaml").write_text(yaml.safe_dump(meta))
    back = Floorplan.load(tmp_path / "neg.yaml")
    assert np.array_equal(back.occupied, room.occupied)
    assert np.array_equal(back.lines.endpoints, room.lines.endpoints)


def test_floorplan_pickles(room):
    import pickle

    back = pickle.loads(pickle.dumps(room))
    assert np.array_equal(back.occupied, room.occupied) and len(back.lines) == len(room.lines)
    q = np.array([[0.3, 3.1], [10.0, 10.0]])
    assert np.array_equal(back.distance(q), room.distance(q))


def _write_ros(tmp_path, img, **meta):
    cv2.imwrite(str(tmp_path / "m.pgm"), img)
    data = {"image": "m.pgm", "resolution": 0.1, "origin": [1.0, -2.0, 0.0], "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.196}
    data.update(meta)
    (tmp_path / "m.yaml").write_text(yaml.safe_dump(data))
    return tmp_path / "m.yaml"


def test_ros_thresholds_and_negate(tmp_path):
    # values: 0 (p=1), 100 (p=0.61), 80 (p=0.69), 255 (p=0)
    img = np.array([[0, 100], [80, 255]], dtype=np.uint8)
    fp = Floorplan.load(_write_ros(tmp_path, img))
    # image row 0 = largest y -> internal row 1
    assert fp.occupied.tolist() == [[True, False], [True, False]]
    # negate: p = v / 255, so only 255 is occupied at 0.65; 100 (0.39) is not
    fp = Floorplan.load(_write_ros(tmp_path, img, negate=1))
    assert fp.occupied.tolist() == [[False, True], [False, False]]
    # a lower occupied threshold makes 100 (p=0.61) a wall too
    fp = Floorplan.load(_write_ros(tmp_path, img, occupied_thresh=0.5))
    assert fp.occupied.tolist() == [[True, False], [True, True]]
    assert fp.resolution == 0.1 and np.allclose(fp.origin, (1.0, -2.0))


def test_image_with_resolution_and_origin(tmp_path):
    img = np.full((30, 40), 255, dtype=np.uint8)
    img[2, 5] = 0  # image row 2 from the top
    cv2.imwrite(str(tmp_path / "plan.png"), img)
    fp = Floorplan.load(tmp_path / "plan.png", resolution=0.1, origin=(3.0, 4.0))
    assert fp.shape == (30, 40)
    (row,), (col,) = np.nonzero(fp.occupied)
    assert (row, col) == (27, 5)
    x, y = fp.wall_points[0]
    assert np.isclose(x, 3.0 + 5.5 * 0.1) and np.isclose(y, 4.0 + 27.5 * 0.1)
    # without flip the image rows are taken as growing with y
    fp2 = Floorplan.load(tmp_path / "plan.png", resolution=0.1, origin=(3.0, 4.0), flip_y=False)
    assert np.nonzero(fp2.occupied)[0][0] == 2


def test_gibson_convention(tmp_path):
    h, w = 300, 400
    img = np.full((h, w), 255, dtype=np.uint8)
    # point (x, y) = (0.5, -0.3) sits at column 0.5/0.01 + 200 = 250, row -0.3/0.01 + 150 = 120
    img[120, 250] = 0
    img[120:125, 10:15] = 30  # another dark blob (a wall)
    cv2.imwrite(str(tmp_path / "map.png"), img)
    for fp in (Floorplan.from_gibson_map(tmp_path / "map.png"), Floorplan.load(tmp_path / "map.png", gibson=True)):
        assert fp.resolution == 0.01
        assert np.allclose(fp.origin, (-2.0, -1.5))
        row, col = fp.world_to_cell(np.array([[0.505, -0.295]]))
        assert (row[0], col[0]) == (120, 250) and fp.occupied[120, 250]
        # the pixel's centre is the documented point plus half a pixel
        assert np.allclose(fp.cell_to_world(120, 250), (0.505, -0.295))
        assert fp.distance(np.array([[0.505, -0.295]]))[0] == pytest.approx(0.0, abs=1e-9)


def test_load_errors_name_the_problem(tmp_path):
    with pytest.raises(FloorplanError, match="nope.png"):
        Floorplan.load(tmp_path / "nope.png", resolution=0.05, origin=(0, 0))
    (tmp_path / "a.yaml").write_text(yaml.safe_dump({"image": "missing.png", "resolution": 0.05, "origin": [0, 0, 0],
                                                     "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.2}))
    with pytest.raises(FloorplanError, match="missing.png"):
        Floorplan.load(tmp_path / "a.yaml")
    (tmp_path / "b.yaml").write_text(yaml.safe_dump({"image": "x.png", "origin": [0, 0, 0], "negate": 0}))
    with pytest.raises(FloorplanError, match="resolution, occupied_thresh, free_thresh"):
        Floorplan.load(tmp_path / "b.yaml")
    (tmp_path / "c.yaml").write_text("key: [unclosed\n")
    with pytest.raises(FloorplanError, match="c.yaml"):
        Floorplan.load(tmp_path / "c.yaml")
    (tmp_path / "junk.png").write_bytes(b"not a png at all")
    with pytest.raises(FloorplanError, match="cannot read"):
        Floorplan.load(tmp_path / "junk.png", resolution=0.05, origin=(0, 0))
    cv2.imwrite(str(tmp_path / "ok.png"), np.zeros((5, 5), np.uint8))
    with pytest.raises(FloorplanError, match="resolution and origin"):
        Floorplan.load(tmp_path / "ok.png")
    with pytest.raises(FloorplanError, match="origin"):
        Floorplan.load(tmp_path / "ok.png", resolution=0.05)
    with pytest.raises(FloorplanError, match="format"):
        Floorplan.load(tmp_path / "plan.txt")
    with pytest.raises(FloorplanError, match="resolution"):
        Floorplan.from_occupancy(room_grid(), -1.0, (0, 0))


def test_no_walls_is_an_error(tmp_path):
    with pytest.raises(FloorplanError, match="no wall"):
        Floorplan.from_occupancy(np.zeros((10, 10), bool), 0.05, (0, 0))
    cv2.imwrite(str(tmp_path / "white.png"), np.full((20, 20), 255, np.uint8))
    with pytest.raises(FloorplanError, match="no wall"):
        Floorplan.load(tmp_path / "white.png", resolution=0.05, origin=(0, 0))


# --- f^c ---------------------------------------------------------------------------------------


def test_distance_field_matches_brute_force():
    rng = np.random.default_rng(3)
    occ = rng.random((40, 50)) < 0.02
    occ[0, 0] = True
    fp = Floorplan.from_occupancy(occ, 0.1, (-2.0, 1.0))
    walls = fp.wall_points
    # exact at cell centres
    rows, cols = np.mgrid[0:40, 0:50]
    centres = fp.cell_to_world(rows.ravel(), cols.ravel())
    brute = np.min(np.linalg.norm(centres[:, None] - walls[None], axis=2), axis=1)
    assert np.allclose(fp.distance_field.ravel(), brute)
    assert np.allclose(fp.distance(centres), brute)
    # anywhere inside the grid: within half a cell of the true distance to a wall centre
    q = rng.uniform(fp.extent[:2], fp.extent[2:], size=(2000, 2))
    truth = np.min(np.linalg.norm(q[:, None] - walls[None], axis=2), axis=1)
    assert np.abs(fp.distance(q) - truth).max() <= 0.5 * fp.resolution * np.sqrt(2) + 1e-9


def test_distance_is_continuous_and_finite_outside(room):
    # a fine sweep: no jumps bigger than the path step (f^c is 1-Lipschitz)
    x = np.linspace(room.extent[0] - 1.0, room.extent[2] + 1.0, 5001)
    p = np.stack([x, np.full_like(x, 2.9)], axis=1)
    d = room.distance(p)
    assert np.isfinite(d).all()
    assert np.abs(np.diff(d)).max() <= (x[1] - x[0]) * np.sqrt(2) + 1e-9
    far = room.distance(np.array([[1e4, -1e4], [room.extent[2] + 3.0, 3.0]]))
    assert np.isfinite(far).all() and far[0] > 1e3 and far[1] >= 3.0 - 1e-9


def test_distance_rejects_nan(room):
    with pytest.raises(InputError, match="NaN"):
        room.distance(np.array([[0.0, np.nan]]))
    with pytest.raises(ZflocError):
        room.distance(np.zeros((3, 3)))


# --- geometry, primitives ----------------------------------------------------------------------


def test_grid_conversions(room):
    x0, y0, x1, y1 = room.extent
    assert (x0, y0) == (-1.0, 2.0) and np.isclose(x1, -1.0 + 80 * 0.05) and np.isclose(y1, 2.0 + 60 * 0.05)
    rows, cols = np.array([0, 5, 59]), np.array([0, 7, 79])
    r, c = room.world_to_cell(room.cell_to_world(rows, cols))
    assert np.array_equal(r, rows) and np.array_equal(c, cols)
    assert room.contains(np.array([[-0.99, 2.01], [-1.01, 2.5]])).tolist() == [True, False]


def test_floorplan_lines_cover_the_room_faces(room):
    lines = room.lines
    assert len(lines) >= 4
    # every inner wall face of the 4 x 3 m room (face cell centres 1.5 cells in) is one long line
    res = 0.05
    inner = [(1, 2.0 + 1.5 * res), (1, 5.0 - 1.5 * res), (0, -1.0 + 1.5 * res), (0, 3.0 - 1.5 * res)]  # (constant axis, value)
    for axis, value in inner:
        along = 1 - axis
        ok = (np.abs(lines.endpoints[:, :, axis] - value).max(axis=1) < 0.02) & (
            np.abs(np.diff(lines.endpoints[:, :, along], axis=1)[:, 0]) > 2.5
        )
        assert ok.sum() == 1, (axis, value)
    assert np.isclose(np.linalg.norm(lines.normals, axis=1), 1).all()
    # lines are deterministic
    again = Floorplan.from_occupancy(room_grid(), 0.05, (-1.0, 2.0))
    assert np.array_equal(again.lines.endpoints, lines.endpoints)


def test_line_neighbours_are_symmetric_and_respect_distance():
    occ = np.zeros((100, 400), bool)
    occ[10, 10:60] = True  # 2.5 m wall at x in [0.5, 3)
    occ[10, 340:390] = True  # 2.5 m wall at x in [17, 19.5): 14 m away
    occ[30, 10:60] = True  # 1 m above the first
    fp = Floorplan.from_occupancy(occ, 0.05, (0, 0))
    assert len(fp.lines) == 3
    nb = fp.line_neighbours
    assert all(i not in nb[i] and all(i in nb[j] for j in nb[i]) for i in range(3))  # symmetric, no line its own
    x_mid = fp.lines.midpoints[:, 0]
    far = int(np.argmax(x_mid))
    assert len(fp.line_neighbours[far]) == 0
    assert all(len(fp.line_neighbours[i]) == 1 for i in range(3) if i != far)


def test_pillar_in_floorplan_is_a_circle():
    yy, xx = np.mgrid[0:120, 0:120]
    occ = np.hypot(xx - 60 + 0.5, yy - 60 + 0.5) <= 6  # solid pillar, r = 0.3 m at 0.05 m/cell
    occ[0], occ[-1], occ[:, 0], occ[:, -1] = True, True, True, True
    fp = Floorplan.from_occupancy(occ, 0.05, (0, 0))
    assert len(fp.circles) == 1
    assert np.linalg.norm(fp.circles.centers[0] - (3.0, 3.0)) < 0.05
    assert abs(fp.circles.radii[0] - 0.3) < 0.06


def test_sample_wall_points_thins(room):
    dense = room.sample_wall_points(0.05)
    sparse = room.sample_wall_points(0.2)
    assert 0 < len(sparse) < len(dense) <= len(room.wall_points)
    # at the grid resolution every wall cell is its own sample
    assert len(room.sample_wall_points(room.resolution, faces_only=False)) == len(room.wall_points)
    assert len(room.sample_wall_points()) > 0  # default spacing from the settings


def test_settings_are_used():
    s = Settings.model_validate({"floorplan": {"neighbour_distance": 0.5}})
    fp = Floorplan.from_occupancy(room_grid(), 0.05, (0, 0), settings=s)
    base = Floorplan.from_occupancy(room_grid(), 0.05, (0, 0))
    assert sum(map(len, fp.line_neighbours)) < sum(map(len, base.line_neighbours))
