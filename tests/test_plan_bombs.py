"""Issue 44, floorplan files: memory and time bombs are refused by a limit checked before
the work (named with the setting that raises it), large honest plans load, nothing is
dropped or read wrong without a word, and every refusal is one error line (exit 2).

Each family is generated small (benchmarks/inputs/plan_bombs.py); benchmarks/evaluation/fuzz_run.py runs
them at the issue's sizes with a memory budget."""

from __future__ import annotations

import numpy as np
import pytest
from benchmarks.inputs.plan_bombs import (
    BILLION_LAUGHS,
    dxf_collinear,
    dxf_insert_tree,
    dxf_nested_walls,
    dxf_pieces,
    geojson_big_int,
    geojson_dots,
    geojson_with,
    svg_long_path,
    svg_transformed_group,
    svg_use_fanout,
    svg_xxe,
)

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.errors import FloorplanError
from zfloc_stream.tools.cli import main
from zfloc_stream.plans.vector import load_vector_floorplan


def _cli_error(path, tmp_path, capsys, *extra):
    code = main(["run", "--floorplan", str(path), *extra, "--input", str(tmp_path / "absent.mcap"),
                 "--out", str(tmp_path / "o"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


def test_dxf_insert_tree_is_counted_before_it_is_expanded(tmp_path, capsys):
    """8 levels of 10 INSERTs are 1e8 lines: refused at once, naming the setting."""
    bomb = dxf_insert_tree(tmp_path / "tree8.dxf", 8)
    code, err = _cli_error(bomb, tmp_path, capsys)
    assert code == 2 and len(err) == 1 and "datasets.vector_floorplan.max_entities" in err[0] and "tree8.dxf" in err[0], err
    # 3 levels (1,000 lines) load, and are refused under a limit of 500
    assert load_vector_floorplan(dxf_insert_tree(tmp_path / "tree3.dxf", 3)).lines.endpoints.shape[0] > 0
    with pytest.raises(FloorplanError, match="max_entities"):
        load_vector_floorplan(tmp_path / "tree3.dxf", load_settings(overrides=["datasets.vector_floorplan.max_entities=500"]))


def test_walls_nested_nine_blocks_deep_are_read(tmp_path):
    """The reader stopped at depth 8 and dropped deeper walls without a word."""
    plan = load_vector_floorplan(dxf_nested_walls(tmp_path / "deep9.dxf", 9))
    lengths = sorted(np.linalg.norm(plan.lines.endpoints[:, 1] - plan.lines.endpoints[:, 0], axis=1))
    assert len(lengths) == 4 and np.allclose(lengths, [8, 8, 10, 10]), lengths
    with pytest.raises(FloorplanError, match="nested deeper than 64"):
        load_vector_floorplan(dxf_nested_walls(tmp_path / "deep100.dxf", 100))


def test_overlapping_collinear_pieces_merge_to_one_line(tmp_path):
    plan = load_vector_floorplan(dxf_collinear(tmp_path / "over.dxf", 2000))
    assert len(plan.lines) == 4


def test_a_building_in_thousands_of_pieces_loads(tmp_path):
    plan = load_vector_floorplan(dxf_pieces(tmp_path / "pieces.dxf", 5000, side=30.0))
    assert 0 < len(plan.lines) < 200


def test_svg_use_fanout_is_counted_before_it_is_expanded(tmp_path, capsys):
    code, err = _cli_error(svg_use_fanout(tmp_path / "use7.svg", 7), tmp_path, capsys, "--scale", "0.01")
    assert code == 2 and len(err) == 1 and "max_entities" in err[0] and "use7.svg" in err[0], err
    assert len(load_vector_floorplan(svg_use_fanout(tmp_path / "use2.svg", 2), scale=0.01).lines) > 0


def test_a_long_svg_path_loads(tmp_path):
    plan = load_vector_floorplan(svg_long_path(tmp_path / "path.svg", 20_000), scale=0.01)
    assert len(plan.lines) == 4


@pytest.mark.parametrize("transform", ["rotate(30)", "scale(-1, 1)", "skewX(20)", "matrix(0.5 0.3 -0.2 0.9 100 50)"])
def test_rect_in_a_transformed_group_keeps_the_transform(tmp_path, transform):
    """The <rect> and the four <line>s beside it are the same room shifted by 20 m: after
    the group's transform they are still congruent (the rect was read untransformed)."""
    plan = load_vector_floorplan(svg_transformed_group(tmp_path / "g.svg", transform), scale=0.01)
    rect, lines = np.array(plan.geometry.rings[0]), np.vstack(plan.geometry.polylines)
    lines = np.unique(lines.round(9), axis=0)
    # the transform is affine: the lines' corners are the rect's corners moved by T(20 m, 0)
    shift = lines.mean(axis=0) - rect.mean(axis=0)
    moved = np.sort((rect + shift).round(6), axis=0)
    assert np.allclose(moved, np.sort(lines.round(6), axis=0), atol=1e-6), (rect, lines)


def test_circle_in_a_rotated_group_moves_with_it(tmp_path):
    svg = tmp_path / "c.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><rect x="0" y="0" width="1000" height="800" fill="none" stroke="black"/>'
                   '<g transform="rotate(90)"><circle cx="500" cy="0" r="20"/></g></svg>')
    x, y, r = load_vector_floorplan(svg, scale=0.01).geometry.circles[0]
    assert np.allclose((x, y, r), (0.0, -5.0, 0.2)), (x, y, r)


def test_xml_bombs_and_external_entities_are_refused(tmp_path, capsys):
    (tmp_path / "laughs.svg").write_text(BILLION_LAUGHS)
    code, err = _cli_error(tmp_path / "laughs.svg", tmp_path, capsys, "--scale", "0.01")
    assert code == 2 and len(err) == 1 and "laughs.svg" in err[0], err
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET")
    code, err = _cli_error(svg_xxe(tmp_path / "xxe.svg", secret), tmp_path, capsys, "--scale", "0.01")
    assert code == 2 and len(err) == 1 and "TOPSECRET" not in err[0], err


def test_geojson_with_a_5000_digit_number_is_one_error_line(tmp_path, capsys):
    code, err = _cli_error(geojson_big_int(tmp_path / "digits.geojson"), tmp_path, capsys)
    assert code == 2 and len(err) == 1 and "digits.geojson" in err[0], err


@pytest.mark.parametrize("value", ["5", True, False, "abc"])
def test_geojson_coordinates_must_be_numbers(tmp_path, value):
    with pytest.raises(FloorplanError, match="not a number"):
        load_vector_floorplan(geojson_with(tmp_path / "c.geojson", coordinate=value))


def test_geojson_crs_is_not_ignored(tmp_path):
    feet = geojson_with(tmp_path / "feet.geojson", crs="urn:ogc:def:crs:EPSG::2263")
    with pytest.raises(FloorplanError, match="--scale"):
        load_vector_floorplan(feet)
    plan = load_vector_floorplan(feet, scale=0.3048)  # the user says feet: converted
    assert np.isclose(np.ptp(plan.geometry.rings[0][:, 0]), 10 * 0.3048)
    with pytest.raises(FloorplanError, match="longitude/latitude"):
        load_vector_floorplan(geojson_with(tmp_path / "ll.geojson", crs="urn:ogc:def:crs:OGC:1.3:CRS84"))


def test_dxf_declared_mm_but_drawn_in_metres_is_refused_naming_scale(tmp_path):
    from benchmarks.inputs.hostile_plans import BOX, write_dxf

    path = write_dxf(tmp_path / "mm.dxf", [((30 * a, 20 * b), (30 * c, 20 * d)) for (a, b), (c, d) in
                                           (((0, 0), (1, 0)), ((1, 0), (1, 1)), ((1, 1), (0, 1)), ((0, 1), (0, 0)))], 4)
    with pytest.raises(FloorplanError, match=r"(?i)millimeters.*--scale"):
        load_vector_floorplan(path)
    assert len(load_vector_floorplan(path, scale=1.0).lines) == 4
    assert len(load_vector_floorplan(write_dxf(tmp_path / "room_mm.dxf", [tuple(tuple(1000 * v for v in p) for p in s) for s in BOX], 4)).lines) == 4


def test_plan_without_walls_is_refused(tmp_path, capsys):
    code, err = _cli_error(geojson_dots(tmp_path / "dots.geojson"), tmp_path, capsys)
    assert code == 2 and len(err) == 1 and "no wall line" in err[0] and "dots.geojson" in err[0], err


def _fuzz(seed: int, n: int, d, big: bool) -> dict[str, int]:
    from benchmarks.inputs.plan_bombs import fuzz_bomb_plan

    rng = np.random.default_rng(seed)
    outcomes = {"loaded": 0, "refused": 0}
    for case in range(n):
        path, kwargs = fuzz_bomb_plan(rng, d, case, big)
        try:
            load_vector_floorplan(path, **kwargs)
            outcomes["loaded"] += 1
        except FloorplanError as err:
            assert "\n" not in str(err) and path.name in str(err), (case, str(err))
            outcomes["refused"] += 1
        path.unlink()
    return outcomes


def test_fuzzed_bomb_families_load_or_fail_in_one_line(tmp_path):
    outcomes = _fuzz(44, 36, tmp_path, big=False)
    assert outcomes["loaded"] >= 8 and outcomes["refused"] >= 8, outcomes


@pytest.mark.slow
def test_fuzzed_bomb_families_at_the_issues_sizes(tmp_path):
    """Up to 100,000 segments, 8 levels of INSERTs (benchmarks/evaluation/fuzz_run.py --bombs runs
    more with a memory budget and an alarm per case)."""
    outcomes = _fuzz(4400, 60, tmp_path, big=True)
    assert outcomes["loaded"] and outcomes["refused"], outcomes
