"""Generators of the plan families issue 44 found breaking the vector loaders (memory and
time bombs, silent drops, wrong units), small by default; the tests
(tests/test_plan_bombs.py), benchmarks/evaluation/fuzz_run.py and bench_plan_load.py --honest
draw from them with seeds."""

from __future__ import annotations

import json
from pathlib import Path

import ezdxf
import numpy as np

from benchmarks.inputs.hostile_plans import GEO_BOX, collection, feature, write_dxf, write_svg


def dxf_insert_tree(path: Path, levels: int, fanout: int = 10) -> Path:
    """Block L_k holds `fanout` INSERTs of L_(k-1); L_0 one LINE; the model space one
    INSERT of L_levels: fanout ** levels lines from a file of a few KB."""
    doc = ezdxf.new(units=6)
    doc.blocks.new("L0").add_line((0, 0), (1, 0))
    for k in range(1, levels + 1):
        block = doc.blocks.new(f"L{k}")
        for j in range(fanout):
            block.add_blockref(f"L{k - 1}", (0.01 * j, 0.1 * j))
    msp = doc.modelspace()
    for (a, b) in [((0, 0), (10, 0)), ((10, 0), (10, 8)), ((10, 8), (0, 8)), ((0, 8), (0, 0))]:
        msp.add_line(a, b)
    msp.add_blockref(f"L{levels}", (2, 2))
    doc.saveas(path)
    return path


def dxf_nested_walls(path: Path, depth: int) -> Path:
    """The room's walls inside block B_0, each B_k inserting B_(k-1) once, the model space
    inserting B_(depth-1): walls `depth` block levels deep."""
    doc = ezdxf.new(units=6)
    b0 = doc.blocks.new("B0")
    for (a, b) in [((0, 0), (10, 0)), ((10, 0), (10, 8)), ((10, 8), (0, 8)), ((0, 8), (0, 0))]:
        b0.add_line(a, b)
    for k in range(1, depth):
        doc.blocks.new(f"B{k}").add_blockref(f"B{k - 1}", (0, 0))
    doc.modelspace().add_blockref(f"B{depth - 1}", (0, 0))
    doc.saveas(path)
    return path


def dxf_collinear(path: Path, n: int, seed: int = 0) -> Path:
    """A room plus n overlapping 5 m pieces of one wall, drawn on top of each other."""
    rng = np.random.default_rng(seed)
    pieces = [((float(x), 0.0), (float(x) + 5.0, 0.0)) for x in rng.uniform(0, 5, n)]
    return write_dxf(path, [((0, 0), (0, 8)), ((0, 8), (10, 8)), ((10, 8), (10, 0))] + pieces)


def dxf_pieces(path: Path, n: int, side: float = 50.0, seed: int = 0) -> Path:
    """n wall pieces 0.2-1 m long on a 2 m grid of walls in a side x side square (a large
    building drawn in small pieces: honest, however many)."""
    rng = np.random.default_rng(seed)
    lines = []
    for _ in range(n):
        along = float(rng.uniform(0, side - 1))
        at = 2.0 * float(rng.integers(0, int(side / 2) + 1))
        length = float(rng.uniform(0.2, 1.0))
        lines.append(((along, at), (along + length, at)) if rng.random() < 0.5 else ((at, along), (at, along + length)))
    return write_dxf(path, lines)


def dxf_scatter(path: Path, n: int, side: float = 50.0, seed: int = 0) -> Path:
    """n short lines at random places and angles in a side x side square (the issue's
    100,000 short LINEs in a 50 m square)."""
    rng = np.random.default_rng(seed)
    p = rng.uniform(0, side, size=(n, 2))
    a = rng.uniform(0, np.pi, n)
    q = p + np.c_[np.cos(a), np.sin(a)] * rng.uniform(0.2, 1.0, n)[:, None]
    return write_dxf(path, [((float(x0), float(y0)), (float(x1), float(y1))) for (x0, y0), (x1, y1) in zip(p, q)])


def svg_long_path(path: Path, n: int) -> Path:
    """One <path> of n segments tracing a 40 x 30 m room's outline (at scale 0.01) in
    equal steps: a large honest path."""
    t = np.linspace(0, 1, n + 1)
    perimeter = 2 * (4000 + 3000)
    s = t * perimeter
    x = np.select([s < 4000, s < 7000, s < 11000], [s, 4000, 4000 - (s - 7000)], 0)
    y = np.select([s < 4000, s < 7000, s < 11000], [0, s - 4000, 3000], 3000 - (s - 11000))
    d = "M " + " L ".join(f"{a:.2f} {b:.2f}" for a, b in zip(x, y))
    return write_svg(path, f'<path d="{d}" fill="none" stroke="black"/>')


def svg_use_fanout(path: Path, levels: int, fanout: int = 10) -> Path:
    """<g id=gk> holds `fanout` <use> of g(k-1); g0 one line; the drawing uses g(levels)."""
    defs = ['<g id="g0"><line x1="0" y1="0" x2="100" y2="0" stroke="black"/></g>']
    for k in range(1, levels + 1):
        defs.append(f'<g id="g{k}">' + "".join(f'<use href="#g{k - 1}" x="{j}" y="{10 * j}"/>' for j in range(fanout)) + "</g>")
    return write_svg(path, '<rect x="0" y="0" width="1000" height="800" fill="none" stroke="black"/>'
                     f'<defs>{"".join(defs)}</defs><use href="#g{levels}"/>')


def svg_transformed_group(path: Path, transform: str) -> Path:
    """A 10 x 8 m room (scale 0.01) drawn as a <rect> and, beside it, the same room's four
    <line>s, both inside one group with the transform."""
    lines = "".join(f'<line x1="{a}" y1="{b}" x2="{c}" y2="{d}" stroke="black"/>'
                    for a, b, c, d in ((2000, 0, 3000, 0), (3000, 0, 3000, 800), (3000, 800, 2000, 800), (2000, 800, 2000, 0)))
    return write_svg(path, f'<g transform="{transform}"><rect x="0" y="0" width="1000" height="800" fill="none" stroke="black"/>{lines}</g>')


BILLION_LAUGHS = ('<?xml version="1.0"?><!DOCTYPE svg [<!ENTITY a "aaaaaaaaaa">'
                  + "".join(f'<!ENTITY {chr(98 + k)} "{("&" + chr(97 + k) + ";") * 10}">' for k in range(9))
                  + ']><svg xmlns="http://www.w3.org/2000/svg"><rect x="0" y="0" width="1000" height="800"/><desc>&j;</desc></svg>')


def svg_xxe(path: Path, target: Path) -> Path:
    path.write_text(f'<?xml version="1.0"?><!DOCTYPE svg [<!ENTITY x SYSTEM "file://{target}">]>'
                    '<svg xmlns="http://www.w3.org/2000/svg"><rect x="0" y="0" width="1000" height="800"/><desc>&x;</desc></svg>')
    return path


def geojson_big_int(path: Path, digits: int = 5000) -> Path:
    path.write_text('{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, "geometry": '
                    '{"type": "LineString", "coordinates": [[0, 0], [' + "9" * digits + ', 8]]}}]}')
    return path


def geojson_with(path: Path, coordinate=None, crs=None) -> Path:
    """The box, one coordinate replaced (a string, a bool...), or a `crs` member added."""
    data = json.loads(json.dumps(collection(GEO_BOX)))
    if coordinate is not None:
        data["features"][0]["geometry"]["coordinates"][1][0] = coordinate
    if crs is not None:
        data["crs"] = {"type": "name", "properties": {"name": crs}}
    path.write_text(json.dumps(data))
    return path


def geojson_dots(path: Path) -> Path:
    """Only wall pieces shorter than a line (0.2 m): a drawing with nothing to localize on."""
    feats = [feature({"type": "LineString", "coordinates": [[x, 0], [x + 0.2, 0]]}) for x in range(0, 10, 2)]
    feats += [feature({"type": "LineString", "coordinates": [[0, y], [0, y + 0.2]]}) for y in range(0, 8, 2)]
    path.write_text(json.dumps(collection(*feats)))
    return path


def fuzz_bomb_plan(rng: np.random.Generator, d: Path, case: int, big: bool = False) -> tuple[Path, dict]:
    """One seeded plan of issue 44's families: (path, load_vector_floorplan keyword
    arguments). Small sizes by default (CI); big=True draws up to the issue's sizes."""
    family = case % 12
    n = int(rng.integers(10, 100_000 if big else 2_000))
    p = d / f"bomb{case}"
    if family == 0:
        return dxf_insert_tree(p.with_suffix(".dxf"), int(rng.integers(1, 9 if big else 7)), int(rng.integers(2, 11))), {}
    if family == 1:
        return dxf_nested_walls(p.with_suffix(".dxf"), int(rng.integers(1, 80))), {}
    if family == 2:
        return dxf_collinear(p.with_suffix(".dxf"), n, seed=case), {}
    if family == 3:
        return dxf_pieces(p.with_suffix(".dxf"), n, side=float(rng.uniform(10, 60)), seed=case), {}
    if family == 4:
        return dxf_scatter(p.with_suffix(".dxf"), n // 10 if not big else n, side=float(rng.uniform(10, 60)), seed=case), {}
    if family == 5:
        return svg_long_path(p.with_suffix(".svg"), 2 * n), {"scale": 0.01}
    if family == 6:
        return svg_use_fanout(p.with_suffix(".svg"), int(rng.integers(1, 8)), int(rng.integers(2, 11))), {"scale": 0.01}
    if family == 7:
        transform = ("rotate({})", "scale(-1, {})", "skewX({})", "skewY({})", "matrix(1 0 0.5 1 {} 0)")[int(rng.integers(5))]
        return svg_transformed_group(p.with_suffix(".svg"), transform.format(round(float(rng.uniform(-80, 80)), 2))), {"scale": 0.01}
    if family == 8:
        path = p.with_suffix(".svg")
        path.write_text(BILLION_LAUGHS if rng.random() < 0.5 else BILLION_LAUGHS.replace("&j;", "&" + "abcdefghij"[int(rng.integers(10))] + ";"))
        return path, {"scale": 0.01}
    if family == 9:
        return geojson_big_int(p.with_suffix(".geojson"), int(rng.integers(1, 20_000))), {}
    if family == 10:
        value = ("5", True, False, "", None, [1], {"x": 1}, "1e3", 1e308)[int(rng.integers(9))]
        crs = None if rng.random() < 0.5 else ("EPSG:2263", "urn:ogc:def:crs:OGC:1.3:CRS84", "EPSG:32633", 5)[int(rng.integers(4))]
        return geojson_with(p.with_suffix(".geojson"), coordinate=value, crs=crs), ({"scale": 0.3048} if rng.random() < 0.3 else {})
    # family 11: a room in a declared unit, drawn in another
    from benchmarks.inputs.hostile_plans import BOX

    factor = 10.0 ** int(rng.integers(-4, 4))
    unit = int(rng.choice([1, 2, 4, 5, 6, 14]))
    return write_dxf(p.with_suffix(".dxf"), [tuple(tuple(factor * v for v in q) for q in s) for s in BOX], unit), {}
