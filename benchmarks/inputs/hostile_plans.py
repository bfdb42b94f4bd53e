"""Hostile floorplans for the loader fuzz tests (tests/test_floorplan_fuzz.py) and the
larger run in benchmarks/evaluation/fuzz_run.py: the inputs issue 29 found breaking the loaders,
and a seeded generator of damaged plans in every format (ROS YAML + PNG, plain image,
DXF, SVG, GeoJSON)."""

from __future__ import annotations

import json
import zlib
from pathlib import Path

import cv2
import numpy as np

SUFFIX_OF = {"ros": ".yaml", "image": ".png", "dxf": ".dxf", "svg": ".svg", "geojson": ".geojson"}


# --- small writers ------------------------------------------------------------------------------
def box_image(h: int = 60, w: int = 80) -> np.ndarray:
    """A room: dark walls on a light floor, one pillar."""
    img = np.full((h, w), 254, np.uint8)
    img[[0, 1, -2, -1], :] = 0
    img[:, [0, 1, -2, -1]] = 0
    img[h // 2 - 2 : h // 2 + 2, w // 2 - 2 : w // 2 + 2] = 0
    return img


def write_ros(path: Path, pixels: np.ndarray | None = None, image_name: str = "map.png", **meta) -> Path:
    if pixels is not None:
        cv2.imwrite(str(path.parent / image_name), pixels)
    base = {"image": image_name, "resolution": 0.05, "origin": [0.0, 0.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.196}
    base.update(meta)
    path.write_text(json.dumps(base))  # JSON is YAML: keeps NaN / nesting exactly as written
    return path


def write_dxf(path: Path, lines, insunits: int | None = 6, circles=()) -> Path:
    """A minimal ASCII DXF (header + ENTITIES) written by hand, so any value can be put in."""
    out = ["0", "SECTION", "2", "HEADER"]
    if insunits is not None:
        out += ["9", "$INSUNITS", "70", str(insunits)]
    out += ["0", "ENDSEC", "0", "SECTION", "2", "ENTITIES"]
    for (x0, y0), (x1, y1) in lines:
        out += ["0", "LINE", "8", "WALLS", "10", str(x0), "20", str(y0), "30", "0.0", "11", str(x1), "21", str(y1), "31", "0.0"]
    for x, y, r in circles:
        out += ["0", "CIRCLE", "8", "WALLS", "10", str(x), "20", str(y), "30", "0.0", "40", str(r)]
    out += ["0", "ENDSEC", "0", "EOF"]
    path.write_text("\n".join(out) + "\n")
    return path


BOX = [((0, 0), (10, 0)), ((10, 0), (10, 8)), ((10, 8), (0, 8)), ((0, 8), (0, 0))]


def write_svg(path: Path, body: str) -> Path:
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="1000" height="800">{body}</svg>')
    return path


SVG_BOX = '<rect x="0" y="0" width="1000" height="800" fill="none" stroke="black"/>'


def write_geojson(path: Path, data) -> Path:
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def feature(geometry, properties=None) -> dict:
    return {"type": "Feature", "geometry": geometry, "properties": properties if properties is not None else {}}


def collection(*features) -> dict:
    return {"type": "FeatureCollection", "features": list(features)}


GEO_BOX = feature({"type": "LineString", "coordinates": [[0, 0], [10, 0], [10, 8], [0, 8], [0, 0]]})


def big_png(path: Path, h: int, w: int) -> Path:
    """A valid h x w 8-bit grey PNG written row by row (zlib streaming): a few MB on disk
    however large the image, without ever holding it in memory."""
    import struct

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    comp = zlib.compressobj(9)
    row = b"\x00" + b"\xfe" * w
    body = bytearray()
    for _ in range(h):
        body += comp.compress(row)
    body += comp.flush()
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)))
        f.write(chunk(b"IDAT", bytes(body)) + chunk(b"IEND", b""))
    return path


def nested_list(depth: int) -> str:
    return "[" * depth + "]" * depth


# --- the issue's inputs -------------------------------------------------------------------------
def issue_floorplans(d: Path) -> list[tuple[str, Path, list[str]]]:
    """(label, plan, extra CLI args) for each input issue 29 reported as a traceback or as
    silently accepted; every one must now be one error line."""
    d.mkdir(parents=True, exist_ok=True)
    cases: list[tuple[str, Path, list[str]]] = []
    for code in (8, 9, 21, 22, 23, 24, 25):
        # converted now (8, 9, 21-24: a unit) or refused naming the code (25): the
        # converted ones hold a 10 x 8 unit box, far too large or small for one floor
        # in mils / microinches, a room in survey feet (loads)
        cases.append((f"DXF $INSUNITS {code}", write_dxf(d / f"units{code}.dxf", BOX, code), []))
    cases.append(("DXF LINE with nan", write_dxf(d / "nan.dxf", [*BOX, ((0, 0), ("nan", 3))]), []))
    cases.append(("DXF LINE with inf", write_dxf(d / "inf.dxf", [*BOX, ((0, 0), ("inf", 3))]), []))
    cases.append(("SVG line x2=1e400", write_svg(d / "huge.svg", SVG_BOX + '<line x1="0" y1="0" x2="1e400" y2="5" stroke="black"/>'), ["--scale", "0.01"]))
    cases.append(("GeoJSON features: 5", write_geojson(d / "features5.geojson", {"type": "FeatureCollection", "features": 5}), []))
    cases.append(("GeoJSON one-point LineString", write_geojson(d / "onepoint.geojson", collection(GEO_BOX, feature({"type": "LineString", "coordinates": [[1, 1]]}))), []))
    cases.append(("GeoJSON NaN coordinate", write_geojson(d / "nan.geojson", '{"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {}, '
                                                         '"geometry": {"type": "LineString", "coordinates": [[0, 0], [NaN, 8]]}}]}'), []))
    cases.append(("GeoJSON radius 'abc'", write_geojson(d / "radius_abc.geojson", collection(GEO_BOX, feature({"type": "Point", "coordinates": [5, 4]}, {"radius": "abc"}))), []))
    cases.append(("GeoJSON properties [1, 2]", write_geojson(d / "props.geojson", collection({"type": "Feature", "geometry": GEO_BOX["geometry"], "properties": [1, 2]})), []))
    deep = '{"type": "FeatureCollection", "features": ' + nested_list(100_000) + "}"
    cases.append(("GeoJSON nested 100,000 deep", write_geojson(d / "deep.geojson", deep), []))
    cases.append(("GeoJSON radius -0.5", write_geojson(d / "radius_neg.geojson", collection(GEO_BOX, feature({"type": "Point", "coordinates": [5, 4]}, {"radius": -0.5}))), []))
    cases.append(("GeoJSON radius NaN", write_geojson(d / "radius_nan.geojson", '{"type": "FeatureCollection", "features": [' + json.dumps(GEO_BOX)
                                                     + ', {"type": "Feature", "properties": {"radius": NaN}, "geometry": {"type": "Point", "coordinates": [5, 4]}}]}'), []))
    cases.append(("DXF CIRCLE radius -0.5", write_dxf(d / "circle_neg.dxf", BOX, 6, circles=[(5, 4, -0.5)]), []))
    img = box_image()
    ros = d / "ros"
    ros.mkdir(exist_ok=True)
    cv2.imwrite(str(ros / "map.png"), img)
    (ros / "deep.yaml").write_text(f"image: {nested_list(2000)}\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    cases.append(("ROS YAML image: nested 2,000 deep", ros / "deep.yaml", []))
    cases.append(("ROS YAML resolution: 1.0e+6", write_ros(ros / "res1e6.yaml", resolution=1.0e6), []))
    cases.append(("ROS YAML origin: [1e308, 1e308, 0]", write_ros(ros / "origin.yaml", origin=[1e308, 1e308, 0]), []))
    cases.append(("ROS YAML negate: 2", write_ros(ros / "negate2.yaml", negate=2), []))
    cases.append(("ROS YAML resolution: true", write_ros(ros / "restrue.yaml", resolution=True), []))
    black = d / "black"
    black.mkdir(exist_ok=True)
    cases.append(("ROS YAML all-black PNG", write_ros(black / "black.yaml", np.zeros((50, 50), np.uint8)), []))
    cases.append(("PNG --resolution 1e300", ros / "map.png", ["--resolution", "1e300", "--origin", "0", "0"]))
    cases.append(("PNG 20,000 x 20,000", big_png(d / "huge.png", 20_000, 20_000), ["--resolution", "0.05", "--origin", "0", "0"]))
    cases.append(("PNG 8,000 x 8,000 at resolution 100", big_png(d / "big8k.png", 8_000, 8_000), ["--resolution", "100", "--origin", "0", "0"]))
    return cases


# --- seeded hostile plans -----------------------------------------------------------------------
HOSTILE_NUMBERS = ("nan", "inf", "-inf", "1e400", "-1e308", "1e308", "1e-320", "0", "-0.5", "abc", "", "1e20", "12:30:45")
HOSTILE_JSON = (float("nan"), float("inf"), -1.0, 0, 1e308, 1e-320, True, "abc", None, [1, 2], {"a": 1}, 10**400, -0.5, 2)


def _hostile_json(rng: np.random.Generator):
    value = HOSTILE_JSON[int(rng.integers(len(HOSTILE_JSON)))]
    return json.loads(json.dumps(value)) if isinstance(value, float) and np.isfinite(value) else value


def _mutate_bytes(data: bytes, rng: np.random.Generator) -> bytes:
    buf = bytearray(data)
    kind = int(rng.integers(3))
    if kind in (0, 2) and buf:
        for pos in rng.integers(0, len(buf), size=int(rng.integers(1, 6))):
            buf[pos] = int(rng.integers(0, 256))
    if kind in (1, 2) and buf:
        buf = buf[: int(rng.integers(0, len(buf)))]
    return bytes(buf)


def _json_dump(data) -> str:
    try:
        return json.dumps(data)
    except (ValueError, OverflowError):
        return json.dumps(str(data))


def fuzz_floorplan(rng: np.random.Generator, d: Path, case: int) -> tuple[Path, dict]:
    """One hostile floorplan on disk: (path, Floorplan.load / load_vector_floorplan keyword
    arguments). The format is drawn, then one of its fields, coordinates or bytes is broken."""
    kind = ("ros", "image", "dxf", "svg", "geojson")[case % 5]
    path = d / f"case{case}{SUFFIX_OF[kind]}"
    how = int(rng.integers(4))
    if kind in ("ros", "image"):
        h, w = (int(v) for v in rng.integers(2, 120, size=2))
        img = box_image(max(h, 6), max(w, 6)) if rng.random() < 0.7 else rng.integers(0, 256, size=(h, w), dtype=np.uint8)
        if rng.random() < 0.1:
            img[:] = int(rng.choice([0, 255]))
        if kind == "image":
            cv2.imwrite(str(path), img)
            res = float(10 ** rng.uniform(-6, 6)) if how == 0 else 0.05
            origin = [_hostile_json(rng), 0.0] if how == 1 else [0.0, 0.0]
            if how == 2:
                path.write_bytes(_mutate_bytes(path.read_bytes(), rng))
            return path, {"resolution": _hostile_json(rng) if how == 3 else res, "origin": origin}
        meta = {}
        if how in (0, 1):
            key = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")[int(rng.integers(6))]
            meta[key] = _hostile_json(rng) if how == 0 else [_hostile_json(rng), _hostile_json(rng), 0]
        write_ros(path, img, image_name=f"case{case}.png", **meta)
        if how == 2:
            png = d / f"case{case}.png"
            png.write_bytes(_mutate_bytes(png.read_bytes(), rng))
        if how == 3:
            path.write_bytes(_mutate_bytes(path.read_bytes(), rng))
        return path, {}
    if kind == "dxf":
        lines = [list(map(list, seg)) for seg in BOX]
        circles = [[5, 4, 0.3]]
        units = 6
        if how == 0:
            i, j, k = int(rng.integers(len(lines))), int(rng.integers(2)), int(rng.integers(2))
            lines[i][j][k] = HOSTILE_NUMBERS[int(rng.integers(len(HOSTILE_NUMBERS)))]
        elif how == 1:
            circles[0][int(rng.integers(3))] = HOSTILE_NUMBERS[int(rng.integers(len(HOSTILE_NUMBERS)))]
        elif how == 2:
            units = int(rng.integers(-3, 40))
        lines = [((a[0], a[1]), (b[0], b[1])) for a, b in lines]
        write_dxf(path, lines, units, circles=[tuple(c) for c in circles])
        if how == 3:
            path.write_bytes(_mutate_bytes(path.read_bytes(), rng))
        return path, {}
    if kind == "svg":
        v = HOSTILE_NUMBERS[int(rng.integers(len(HOSTILE_NUMBERS)))]
        body = SVG_BOX + [f'<line x1="0" y1="0" x2="{v}" y2="5" stroke="black"/>', f'<circle cx="500" cy="400" r="{v}"/>',
                          f'<path d="M 0 0 C {v} 10 20 30 40 {v}"/>', f'<rect x="1" y="1" width="{v}" height="30"/>'][how]
        write_svg(path, body)
        if rng.random() < 0.3:
            path.write_bytes(_mutate_bytes(path.read_bytes(), rng))
        return path, {"scale": float(10 ** rng.uniform(-4, 1)) if rng.random() < 0.9 else _hostile_json(rng)}
    # geojson
    data = json.loads(json.dumps(collection(GEO_BOX, feature({"type": "Point", "coordinates": [5, 4]}, {"radius": 0.3}))))  # a fresh copy
    if how == 0:
        data["features"][1]["properties"]["radius"] = _hostile_json(rng)
    elif how == 1:
        data["features"][0]["geometry"]["coordinates"][int(rng.integers(5))][int(rng.integers(2))] = _hostile_json(rng)
    elif how == 2:
        target = ("features", "properties", "geometry", "type", "coordinates")[int(rng.integers(5))]
        if target == "features":
            data["features"] = _hostile_json(rng)
        elif target == "coordinates":
            data["features"][0]["geometry"]["coordinates"] = _hostile_json(rng) if rng.random() < 0.5 else [[1, 1]]
        elif target == "type":
            data["features"][0]["geometry"]["type"] = _hostile_json(rng)
        else:
            data["features"][0][target] = _hostile_json(rng)
    else:
        depth = int(rng.integers(10, 3000))
        data = '{"type": "FeatureCollection", "features": ' + nested_list(depth) + "}"
    text = data if isinstance(data, str) else _json_dump(data)
    path.write_text(text)
    if how != 3 and rng.random() < 0.2:
        path.write_bytes(_mutate_bytes(path.read_bytes(), rng))
    return path, {}


# --- hostile settings, as a user types them ---------------------------------------------------------
# YAML text after `--set key=`: booleans, YAML 1.1 base-60 and octal numbers, subnormals,
# text, deep nesting, huge and non-finite numbers, empty values.
HOSTILE_SETTING_TEXT = (
    "true", "false", "yes", "on", "~", "", "12:30:45", "-1:30", "190:20:30.15", "010", "0x1F", "0b101", "1_000",
    "4.9e-324", "-4.9e-324", "1e-310", "1e308", "1e400", "-1e400", ".nan", ".inf", "nan", "'5'", '"0.5"', "abc",
    "[1, 2]", "{a: 1}", "[[[[1]]]]", "2024-01-01", "!!binary aGk=", "0.", "-0", "1e3", "5e-2", "+7",
)


def hostile_setting(rng: np.random.Generator, keys: list[str]) -> str:
    """One `key=value` override: a seeded key and a hostile YAML text (or a nesting)."""
    key = keys[int(rng.integers(len(keys)))]
    pick = rng.random()
    if pick < 0.1:
        depth = int(rng.integers(20, 3000))
        value = "[" * depth + "1" + "]" * depth
    elif pick < 0.15:
        value = f"{rng.choice([-1, 1]) * rng.uniform(1, 10):.6f}e{int(rng.integers(-330, 330))}"  # past float range too
    else:
        value = HOSTILE_SETTING_TEXT[int(rng.integers(len(HOSTILE_SETTING_TEXT)))]
    return f"{key}={value}"
