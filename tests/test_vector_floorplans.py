"""DXF, SVG and GeoJSON floorplans written here (ezdxf, shapely, plain SVG text) from a
built-in scene: their walls and circles match the scene's raster floorplan within one cell,
and a laser walk localizes on them as it does on the raster."""

import json
import warnings

import ezdxf
import numpy as np
import pytest
import shapely.geometry as sg
from shapely import affinity

from zfloc_stream import Localizer, load_settings
from zfloc_stream.errors import FloorplanError
from zfloc_stream.plans.loading import load_floorplan
from zfloc_stream.metrics import is_success, position_errors
from zfloc_stream.io.session import read_session, record_session
from zfloc_stream.sim import build_scene, simulate_laser
from zfloc_stream.sim.layout import wall_boxes
from zfloc_stream.tools.cli import main
from zfloc_stream.plans.vector import VectorFloorplan, load_vector_floorplan, merge_collinear

RES = 0.05  # the raster cell of the scenes and of the vector plans' rasters
CELL_DIAGONAL = RES * np.sqrt(2)


def wall_outlines(scene) -> list[np.ndarray]:
    """Each wall box of a scene as its 4 corners (metres)."""
    out = []
    for (cx, cy), (hx, hy), yaw in zip(*wall_boxes(scene.walls, scene.wall_thickness)):
        R = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
        out.append(np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]]) @ R.T + [cx, cy])
    return out


def write_dxf(scene, path, units=6, factor=1.0):
    """Walls as closed LWPOLYLINEs on WALLS, pillars as CIRCLEs on COLUMNS, a stray line on
    FURNITURE; coordinates in the drawing unit (metres / factor)."""
    doc = ezdxf.new(units=units)
    msp = doc.modelspace()
    for layer in ("WALLS", "COLUMNS", "FURNITURE"):
        doc.layers.add(layer)
    for q in wall_outlines(scene):
        msp.add_lwpolyline((q / factor).tolist(), close=True, dxfattribs={"layer": "WALLS"})
    for x, y, r in scene.pillars:
        msp.add_circle((x / factor, y / factor), r / factor, dxfattribs={"layer": "COLUMNS"})
    msp.add_line((1.0 / factor, 1.0 / factor), (3.0 / factor, 2.5 / factor), dxfattribs={"layer": "FURNITURE"})
    doc.saveas(path)
    return path


def write_geojson(scene, path):
    """Walls as shapely polygons (one MultiPolygon), pillars as buffered points (64-gons)."""
    walls = sg.MultiPolygon([sg.Polygon(q) for q in wall_outlines(scene)])
    pillars = [sg.Point(x, y).buffer(r, quad_segs=16) for x, y, r in scene.pillars]
    features = [{"type": "Feature", "properties": {"kind": "walls"}, "geometry": sg.mapping(walls)}]
    features += [{"type": "Feature", "properties": {"kind": "pillar"}, "geometry": sg.mapping(p)} for p in pillars]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return path


def write_svg(scene, path, cm_per_unit=1.0):
    """Walls as <polygon>s and pillars as <circle>s in units of cm_per_unit centimetres, y
    down (SVG: the plan's y is minus the SVG's), inside a translated group."""
    to_svg = lambda p: (p[:, 0] * 100 / cm_per_unit, -p[:, 1] * 100 / cm_per_unit)  # noqa: E731
    body = []
    for q in wall_outlines(scene):
        xs, ys = to_svg(q)
        body.append('<polygon points="' + " ".join(f"{x:.4f},{y - 50:.4f}" for x, y in zip(xs, ys)) + '"/>')
    for x, y, r in scene.pillars:
        (cx,), (cy,) = to_svg(np.array([[x, y]]))
        body.append(f'<circle cx="{cx:.4f}" cy="{cy - 50:.4f}" r="{r * 100 / cm_per_unit:.4f}"/>')
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg"><g transform="translate(0, 50)">' + "".join(body) + "</g></svg>")
    return path


def matched(a, b, tol=RES + RES / 2, angle_deg=2.0):
    """For each line of a: a line of b parallel within angle_deg whose line passes within
    tol of a's midpoint (one cell, plus the half cell face cells sit inside a face) and
    whose extent covers half of a's."""
    out = []
    for e, n in zip(a.endpoints, a.normals):
        ok = False
        for f, m, d in zip(b.endpoints, b.normals, b.offsets):
            if abs(n @ m) < np.cos(np.radians(angle_deg)) or abs(e.mean(axis=0) @ m + d) > tol:
                continue
            u = (f[1] - f[0]) / np.linalg.norm(f[1] - f[0])
            t = np.sort((e - f[0]) @ u)
            ok = min(t[1], np.linalg.norm(f[1] - f[0])) - max(t[0], 0.0) >= 0.5 * (t[1] - t[0])
            if ok:
                break
        out.append(ok)
    return np.array(out)


def assert_matches_raster(plan, raster):
    # walls: every vector wall cell within one (diagonal) cell of a raster wall cell, and
    # every raster wall face on a vector wall cell
    assert raster.distance(plan.wall_points).max() <= CELL_DIAGONAL + 1e-9
    assert plan.distance(raster.face_points).max() <= CELL_DIAGONAL + 1e-9
    # lines: nearly all raster lines have a vector line within a cell, and the reverse
    assert matched(raster.lines, plan.lines).mean() >= 0.9
    assert matched(plan.lines, raster.lines).mean() >= 0.9
    # circles: the same pillars, centres and radii within a cell
    assert len(plan.circles) == len(raster.circles)
    for c, r in zip(raster.circles.centers, raster.circles.radii):
        k = np.argmin(np.linalg.norm(plan.circles.centers - c, axis=1))
        assert np.linalg.norm(plan.circles.centers[k] - c) <= RES and abs(plan.circles.radii[k] - r) <= RES


@pytest.fixture(scope="module")
def hall():
    return build_scene("hall", seed=0)


@pytest.fixture(scope="module")
def apartment():
    return build_scene("apartment", seed=0)


def test_dxf_walls_and_pillars_match_the_raster_plan(tmp_path, hall):
    plan = load_floorplan(write_dxf(hall, tmp_path / "hall.dxf", units=4, factor=0.001), settings=None)  # millimetres
    assert isinstance(plan, VectorFloorplan) and len(plan.circles) == 8
    only_walls = load_vector_floorplan(tmp_path / "hall.dxf", layers=["WALLS", "COLUMNS"])
    assert_matches_raster(only_walls, hall.floorplan)
    skipped = load_vector_floorplan(tmp_path / "hall.dxf", skip_layers=["COLUMNS"])
    assert len(skipped.circles) == 0 and len(skipped.lines) > len(only_walls.lines) - 1


def test_geojson_and_svg_match_the_raster_plan(tmp_path, hall):
    geo = load_floorplan(write_geojson(hall, tmp_path / "hall.geojson"))
    assert_matches_raster(geo, hall.floorplan)
    svg = load_vector_floorplan(write_svg(hall, tmp_path / "hall.svg", cm_per_unit=2.0), scale=0.02)
    assert_matches_raster(svg, hall.floorplan)


def test_collinear_pieces_merge_and_round_rooms_are_walls():
    segs = np.array([[[0, 0], [2, 0]], [[2.1, 0.01], [4, 0]], [[5, 0], [6, 0]], [[0, 1], [3, 1]]], dtype=float)
    merged = merge_collinear(segs, angle_deg=5.0, offset=0.05, gap=0.3)
    lengths = sorted(np.linalg.norm(merged[:, 1] - merged[:, 0], axis=1).round(2))
    assert lengths == [1.0, 3.0, 4.0]  # the 0.1 m gap is bridged, the 1 m one is not


def test_a_wall_drawn_in_thousands_of_pieces_merges_to_one_line_each():
    """Pieces in any order, touching or up to gap apart, become one line per wall; the
    merge runs per group of nearby parallel pieces (not a rescan of all after each merge)."""
    rng = np.random.default_rng(3)
    walls = [((0.0, 2.0 * k), (40.0, 2.0 * k)) for k in range(10)] + [((3.0 * k + 1.0, -5.0), (3.0 * k + 1.0, 25.0)) for k in range(5)]
    pieces = []
    for a, b in np.array(walls):
        cuts = np.sort(rng.uniform(0, 1, 150))
        for t0, t1 in zip(np.r_[0.0, cuts], np.r_[cuts, 1.0]):
            t1 = max(t1 - rng.uniform(0, 0.2) / np.linalg.norm(b - a), t0 + 1e-3)  # gaps up to 0.2 m
            pieces.append((a + t0 * (b - a), a + t1 * (b - a)))
    pieces = np.array(pieces)[rng.permutation(len(pieces))]
    merged = merge_collinear(pieces, angle_deg=5.0, offset=0.05, gap=0.3)
    assert len(merged) == len(walls)
    lengths = np.sort(np.linalg.norm(merged[:, 1] - merged[:, 0], axis=1))
    assert np.allclose(lengths, [30.0] * 5 + [40.0] * 10, atol=0.2)  # the last piece may stop short of the end


@pytest.mark.parametrize("kind", ["dxf", "geojson"])
def test_laser_walk_localizes_on_the_vector_plan_as_on_the_raster(tmp_path, apartment, kind):
    path = write_dxf(apartment, tmp_path / "a.dxf") if kind == "dxf" else write_geojson(apartment, tmp_path / "a.geojson")
    plan = load_vector_floorplan(path, skip_layers=["FURNITURE"] if kind == "dxf" else None)
    run = simulate_laser(apartment, seed=3, n_frames=30)
    settings = load_settings(None, [], base_overrides={"estimator": {"scale_mode": "fixed"}})
    results = {}
    for name, fp in (("raster", apartment.floorplan), ("vector", plan)):
        localizer = Localizer(fp, settings)
        poses = [localizer.push(f).pose for f in run]
        results[name] = position_errors(np.array([p if p is not None else [np.nan] * 3 for p in poses]), run.poses)
    assert is_success(results["raster"], 1.0) and is_success(results["vector"], 1.0), results
    assert np.nanmax(results["vector"][-10:]) < 0.2


def test_vector_plan_travels_inside_a_session_and_replays_its_lines(tmp_path, apartment):
    plan = load_vector_floorplan(write_dxf(apartment, tmp_path / "a.dxf"), skip_layers=["FURNITURE"])
    run = simulate_laser(apartment, seed=1, n_frames=3)
    record_session(tmp_path / "s.mcap", plan, run.frames, load_settings(None, [], base_overrides={"estimator": {"scale_mode": "fixed"}}))
    session = read_session(tmp_path / "s.mcap")
    assert {"floorplan.yaml", "floorplan.png", "floorplan.dxf"} <= set(session.floorplan_files)
    again = session.floorplan
    assert isinstance(again, VectorFloorplan)
    np.testing.assert_array_equal(again.lines.endpoints, plan.lines.endpoints)
    np.testing.assert_array_equal(again.occupied, plan.occupied)


def test_bad_vector_plans_are_one_line_errors_naming_the_file(tmp_path, capsys):
    bad = tmp_path / "broken.dxf"
    bad.write_text("0\nSECTION\n2\nNOPE\n")
    with pytest.raises(FloorplanError, match="broken.dxf"):
        load_floorplan(bad)
    svg = tmp_path / "plan.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><line x1="0" y1="0" x2="100" y2="0"/></svg>')
    with pytest.raises(FloorplanError, match=r"plan.svg: an SVG floorplan has no real-world unit: pass --scale"):
        load_floorplan(svg)
    lonlat = tmp_path / "campus.geojson"
    lonlat.write_text(json.dumps({"type": "LineString", "coordinates": [[11.5761, 48.1372], [11.5763, 48.1373]]}))
    with pytest.raises(FloorplanError, match="campus.geojson: coordinates look like longitude/latitude"):
        load_floorplan(lonlat)
    empty = tmp_path / "empty.geojson"
    empty.write_text(json.dumps({"type": "FeatureCollection", "features": []}))
    with pytest.raises(FloorplanError, match="empty.geojson: no walls found"):
        load_floorplan(empty)
    doc = ezdxf.new(units=0)
    doc.modelspace().add_line((0, 0), (4, 0))
    doc.modelspace().add_line((0, 0), (0, 4))
    doc.saveas(tmp_path / "nounits.dxf")
    with pytest.warns(UserWarning, match=r"nounits.dxf: the DXF header gives no units"):
        load_floorplan(tmp_path / "nounits.dxf")
    with pytest.raises(FloorplanError, match=r"nounits.dxf: no layer\(s\) walls"):
        load_vector_floorplan(tmp_path / "nounits.dxf", layers=["walls"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        code = main(["demo", "--floorplan", str(svg), "--frames", "2", "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "plan.svg" in err


def test_demo_walks_through_a_users_dxf_plan(tmp_path, apartment, capsys):
    plan = write_dxf(apartment, tmp_path / "my-flat.dxf")
    out = tmp_path / "demo"
    code = main(["demo", "--floorplan", str(plan), "--skip-layers", "FURNITURE", "--frames", "25", "--out", str(out), "--no-progress"])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "demo my-flat: 25 frames" not in text  # the title goes to the overlay; the summary lines below
    assert "success@1m: yes" in text, text
    assert (out / "trajectory.tum").read_text().count("\n") > 10
    session = read_session(out / "session.mcap")
    assert "floorplan.dxf" in session.floorplan_files  # the user's drawing travels with the run


def test_scene_from_a_floorplan_extrudes_exactly_its_raster(apartment):
    from zfloc_stream.sim import build_scene_from_floorplan
    from zfloc_stream.sim.layout import rasterize_boxes

    scene = build_scene_from_floorplan(apartment.floorplan, seed=0)
    redrawn = rasterize_boxes(scene.grid, *wall_boxes(scene.walls, scene.wall_thickness))
    np.testing.assert_array_equal(redrawn, apartment.floorplan.occupied)
    assert scene.floorplan is apartment.floorplan and len(scene.rooms) >= 2
    assert abs(scene.floor_area - apartment.floor_area) < 0.05 * apartment.floor_area


def test_every_entity_kind_becomes_wall(tmp_path):
    doc = ezdxf.new(units=5)  # centimetres
    msp = doc.modelspace()
    msp.add_line((0, 0), (800, 0))
    msp.add_polyline2d([(800, 0), (800, 600), (0, 600)])
    msp.add_lwpolyline([(0, 600), (0, 0)])
    msp.add_arc((400, 600), 100, 180, 360)  # a bay under the top wall: raster only, it is not straight
    msp.add_lwpolyline([(300, 200), (500, 200)], format="xy")
    doc.saveas(tmp_path / "mix.dxf")
    plan = load_vector_floorplan(tmp_path / "mix.dxf")
    ends = sorted(tuple(np.round(np.sort(e, axis=0).ravel(), 6)) for e in plan.lines.endpoints)
    assert ends == [(0, 0, 0, 6), (0, 0, 8, 0), (0, 6, 8, 6), (3, 2, 5, 2), (8, 0, 8, 6)]
    assert plan.distance(np.array([[4.0, 5.0], [4.0 + np.sqrt(0.5), 6 - np.sqrt(0.5)]])).max() < RES
    svg = tmp_path / "mix.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><rect x="0" y="-600" width="800" height="600" fill="none"/>'
                   '<path d="M 100 -100 L 300 -100 A 100 100 0 0 1 500 -100"/><line x1="600" y1="-500" x2="600" y2="-300"/>'
                   '<circle cx="700" cy="-100" r="25"/><polyline points="100,-500 200,-500 200,-400"/></svg>')
    plan = load_vector_floorplan(svg, scale=0.01)
    assert len(plan.lines) == 8 and np.allclose(plan.circles.centers, [[7.0, 1.0]]) and np.allclose(plan.circles.radii, [0.25])
    assert plan.distance(np.array([[4.0, 2.0]])).max() < RES  # the arc's top
