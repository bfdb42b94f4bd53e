"""Reading vector plan files into plain geometry (VectorGeometry: segments, closed rings,
circles, in metres): DXF (ezdxf: LINE, LWPOLYLINE with bulges, POLYLINE, ARC, CIRCLE, also
inside INSERTs; units from $INSUNITS), SVG (svgelements; `scale` metres per user unit, y
flipped up) and GeoJSON (shapely; metres, a Point with a `radius` is a pillar). Curves are
flattened to chords within ARC_CHORD; every coordinate is checked finite and on Earth."""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.integrate import IntegrationWarning

from ..settings.documents import MAX_NESTING, real_number, too_deep
from ..errors import FloorplanError
from .raster_files import MAX_COORDINATE


VECTOR_SUFFIXES = (".dxf", ".svg", ".geojson", ".json")
ARC_CHORD = 0.05  # m, arcs and curves are flattened to chords deviating at most this much
CIRCLE_FIT_TOLERANCE = 0.02  # relative spread of a ring's vertex radii for it to be a circle
MIN_CIRCLE_VERTICES = 8
MAX_CURVE_CHORDS = 1_000_000  # a longer SVG curve (50 km at ARC_CHORD) is a unit mistake, not a wall
MIN_PLAN_SPAN = 1.0  # m: a drawing smaller than this either way is in another unit than declared


@dataclass
class VectorGeometry:
    """Drawing contents in metres: open polylines, closed rings, circles (cx, cy, r)."""

    polylines: list[np.ndarray] = field(default_factory=list)
    rings: list[np.ndarray] = field(default_factory=list)
    circles: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, points, closed: bool, what: str = "a shape") -> None:
        p = _coordinates(points, what)
        if closed and len(p) > 1 and np.allclose(p[0], p[-1]):
            p = p[:-1]
        if len(p) >= 3 and closed:
            self.rings.append(p)
        elif len(p) >= 2:
            self.polylines.append(np.vstack([p, p[:1]]) if closed else p)

    def add_circle(self, x, y, r, what: str = "a circle") -> None:
        """A circle (centre, radius) in drawing units: finite, radius > 0."""
        cx, cy = _coordinates([(x, y)], what)[0]
        radius = real_number(r)
        if radius is None or not (math.isfinite(radius) and radius > 0):
            raise FloorplanError(f"{what} has radius {r!r}: a radius must be a finite number > 0")
        self.circles.append((float(cx), float(cy), radius))

    def check_reach(self, source) -> None:
        """After scaling to metres: every coordinate within MAX_COORDINATE of 0."""
        shapes = [p for p in (*self.polylines, *self.rings) if len(p)]
        reach = max([0.0] + ([float(np.abs(np.concatenate(shapes)).max())] if shapes else [])
                    + [abs(x) + r for x, _, r in self.circles] + [abs(y) + r for _, y, r in self.circles])
        if not math.isfinite(reach) or reach > MAX_COORDINATE:
            raise FloorplanError(f"{source}: the drawing reaches {reach:.3g} m from 0 (more than {MAX_COORDINATE:.0e} m): "
                                 "a wrong unit, or a stray coordinate")

    def check_span(self, source, unit: str) -> None:
        """A floor is metres across: a drawing under MIN_PLAN_SPAN both ways was drawn in a
        larger unit than the one it is read in (metres under a millimetre header)."""
        points = np.vstack([*self.polylines, *self.rings, np.zeros((0, 2))])
        ends = [points.min(axis=0), points.max(axis=0)] if len(points) else []
        for x, y, r in self.circles:
            ends += [np.array([x - r, y - r]), np.array([x + r, y + r])]
        if not ends:
            return
        span = np.max(ends, axis=0) - np.min(ends, axis=0)
        if span.max() < MIN_PLAN_SPAN:
            raise FloorplanError(f"{source}: the drawing spans {span[0]:.3g} x {span[1]:.3g} m read in {unit}: too small for a floor; "
                                 "if it is drawn in another unit, pass --scale METRES_PER_UNIT (1 for metres)")

    def scaled(self, factor: float, flip_y: bool = False) -> VectorGeometry:
        s = np.array([factor, -factor if flip_y else factor])
        with np.errstate(over="ignore"):  # a coordinate scaled past float range: check_reach refuses it
            return VectorGeometry([p * s for p in self.polylines], [r * s for r in self.rings],
                                  [(x * s[0], y * s[1], r * factor) for x, y, r in self.circles])

    def is_empty(self) -> bool:
        return not (self.polylines or self.rings or self.circles)


def _coordinates(points, what: str) -> np.ndarray:
    """(N, 2) float coordinates; FloorplanError naming `what` when they are not finite numbers."""
    try:
        with np.errstate(over="ignore"):
            p = np.asarray(points, dtype=float).reshape(-1, 2)
    except (TypeError, ValueError, OverflowError):
        raise FloorplanError(f"{what} has coordinates that are not pairs of numbers") from None
    if not np.isfinite(p).all():
        raise FloorplanError(f"{what} has a coordinate that is not a finite number ({_first_bad(p)})")
    return p


def _first_bad(p: np.ndarray) -> str:
    row = p[~np.isfinite(p).all(axis=1)][0]
    return f"({float(row[0])!r}, {float(row[1])!r})"


# Metres per unit of the $INSUNITS codes ezdxf names but cannot convert (exact definitions:
# 1 in = 0.0254 m; a US survey foot is 1200/3937 m).
_DXF_EXTRA_UNITS = {
    8: ("microinches", 0.0254e-6),
    9: ("mils", 0.0254e-3),
    21: ("US survey feet", 1200 / 3937),
    22: ("US survey inches", 100 / 3937),
    23: ("US survey yards", 3600 / 3937),
    24: ("US survey miles", 6336000 / 3937),
}


# --- readers ------------------------------------------------------------------------------------
def _dxf_units(raw, path: Path, scale: float | None) -> float:
    """Metres per drawing unit: scale, else the header's $INSUNITS (raw: its value as read)."""
    import ezdxf.units

    if scale is not None:
        return scale
    code = real_number(raw)
    if code is None or not float(code).is_integer():
        raise FloorplanError(f"{path}: DXF header $INSUNITS = {raw!r} is not a unit code: pass --scale")
    code = int(code)
    if code == 0:
        warnings.warn(f"{path}: the DXF header gives no units ($INSUNITS = 0): taking drawing units as metres (--scale to change)", stacklevel=3)
        return 1.0
    if code in _DXF_EXTRA_UNITS:
        return _DXF_EXTRA_UNITS[code][1]
    try:
        return float(ezdxf.units.conversion_factor(code, ezdxf.units.M))
    except (KeyError, ValueError, IndexError, TypeError):
        try:
            name = f" ({ezdxf.units.unit_name(code)})"
        except (KeyError, ValueError, IndexError, TypeError):
            name = " (a code ezdxf does not know)"
        raise FloorplanError(f"{path}: DXF header $INSUNITS = {code}{name} is not a length unit this reader converts: pass --scale METRES_PER_UNIT") from None


def _dxf_expansion(doc, path: Path, max_entities: int) -> int:
    """Entities the model space expands to, every INSERT counted as its block's expansion
    (times its MINSERT grid), computed per block once, before anything is expanded:
    FloorplanError past max_entities, or for a block that contains itself."""
    counts: dict[str, int] = {}

    def count(entities, inside: tuple[str, ...]) -> int:
        total = 0
        for e in entities:
            if e.dxftype() != "INSERT":
                total += 1
                continue
            name = e.dxf.get("name", "")
            if len(inside) >= MAX_NESTING:
                raise FloorplanError(f"{path}: DXF blocks nested deeper than {MAX_NESTING} levels")
            if name in inside:
                raise FloorplanError(f"{path}: DXF block {name!r} contains itself (INSERT cycle through {' > '.join(inside)})")
            if name not in counts:
                block = doc.blocks.get(name)
                counts[name] = 0 if block is None else count(block, (*inside, name))
            grid = max(int(e.dxf.get("row_count", 1) or 1), 1) * max(int(e.dxf.get("column_count", 1) or 1), 1)
            total += 1 + grid * counts[name]
            if total > max_entities:
                raise FloorplanError(
                    f"{path}: the DXF expands to more than {max_entities:,} entities (block references nested in blocks): "
                    "a bomb, not a floor (--set datasets.vector_floorplan.max_entities=N raises the limit)")
        return total

    return count(doc.modelspace(), ())


_DXF_SECTIONS = {b"HEADER", b"CLASSES", b"TABLES", b"BLOCKS", b"ENTITIES", b"OBJECTS", b"THUMBNAILIMAGE", b"ACDSDATA"}


def _dxf_lines_only(path: Path) -> tuple[int, np.ndarray] | None:
    """A drawing whose model space holds LINEs only (a generated plan, an export of
    100,000 wall pieces), read from its group codes directly: ($INSUNITS, (N, 2, 2) start
    and end of every LINE in file order), what ezdxf's document and paths give for such a
    drawing (ezdxf takes ~9 s to build 100,000 entity objects; this scan ~0.5 s). None for
    anything else: a binary DXF, another entity in ENTITIES (INSERT, LWPOLYLINE, TEXT...),
    a paper-space entity, a LINE missing a coordinate or holding one that is not a finite
    number, a tag out of place: ezdxf then reads the file (and words any error)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if data.startswith(b"AutoCAD Binary DXF"):
        return None
    lines = data.split(b"\n")
    if lines and not lines[-1].strip():
        lines.pop()
    if len(lines) % 2:
        return None
    try:
        codes = list(map(int, lines[0::2]))  # every group code an integer, or not a DXF this scan reads
    except ValueError:
        return None
    values = lines[1::2]
    n = len(codes)
    units = 0  # ezdxf's header.get("$INSUNITS", 0) for a header without it
    ends: list[float] = []
    try:
        i = 0
        while i < n:
            code, value = codes[i], values[i].strip()
            if code == 999:  # a comment
                i += 1
                continue
            if code != 0:
                return None
            if value == b"EOF":
                break
            if value != b"SECTION" or i + 1 >= n or codes[i + 1] != 2 or values[i + 1].strip() not in _DXF_SECTIONS:
                return None
            name = values[i + 1].strip()
            i += 2
            while i < n and not (codes[i] == 0 and values[i].strip() == b"ENDSEC"):
                code = codes[i]
                if name == b"HEADER" and code == 9 and values[i].strip() == b"$INSUNITS":
                    if i + 1 >= n or codes[i + 1] != 70:
                        return None
                    units = int(values[i + 1])
                    i += 2
                    continue
                if name == b"ENTITIES" and code == 0:
                    if values[i].strip() != b"LINE":
                        return None
                    point = {}
                    i += 1
                    while i < n and codes[i] != 0:
                        c = codes[i]
                        if c in (10, 20, 11, 21, 30, 31):
                            if c in point:
                                return None
                            point[c] = float(values[i])
                        elif c == 67 and int(values[i]) != 0:  # paper space: not the model space
                            return None
                        i += 1
                    if len(point) < 4 or any(c not in point for c in (10, 20, 11, 21)):
                        return None
                    ends += (point[10], point[20], point[11], point[21])
                    continue
                i += 1
            if i >= n:
                return None
            i += 1
        else:
            return None  # no EOF
    except (ValueError, OverflowError):
        return None
    segments = np.array(ends, dtype=float).reshape(-1, 2, 2)
    if len(segments) == 0 or not np.isfinite(segments).all():
        return None
    return units, segments


def read_dxf(path: Path, scale, layers, skip_layers, max_entities: int = 1_000_000) -> VectorGeometry:
    if not layers and not skip_layers:
        fast = _dxf_lines_only(path)
        if fast is not None:
            units, segments = fast
            factor = _dxf_units(units, path, scale)
            # as ezdxf's LINE paths, (start, end), scaled as VectorGeometry.scaled scales them (one product, not 100,000)
            with np.errstate(over="ignore"):  # a coordinate scaled past float range: check_reach refuses it
                geometry = VectorGeometry(polylines=list(segments * np.array([factor, factor])))
            return _dxf_checked(geometry, path, scale, units)
    import ezdxf
    from ezdxf import path as ezpath

    try:
        doc = ezdxf.readfile(path)
    except OSError as err:
        raise FloorplanError(f"cannot read DXF floorplan {path}: {err.strerror or err}") from None
    except ezdxf.DXFError as err:
        raise FloorplanError(f"{path}: not a valid DXF file ({err})") from None
    except Exception as err:  # noqa: BLE001 - ezdxf's parser raises StopIteration, ValueError... on damaged files
        raise FloorplanError(f"{path}: not a readable DXF file ({type(err).__name__}: {err})") from None
    units = doc.header.get("$INSUNITS", 0)
    factor = _dxf_units(units, path, scale)
    _dxf_expansion(doc, path, max_entities)  # also bounds the nesting: each level is an entity
    wanted = None if not layers else {name.lower() for name in layers}
    skipped = {name.lower() for name in skip_layers or ()}
    # a layer exists when the LAYER table names it or an entity sits on it (a table may
    # lack layers its entities use: ezdxf reads and audits such files clean)
    names = {layer.dxf.name for layer in doc.layers}
    names |= {e.dxf.get("layer", "0") for space in (doc.modelspace(), *doc.blocks) for e in space}
    known = {name.lower() for name in names}
    for option, asked in (("--layers", wanted or set()), ("--skip-layers", skipped)):
        missing = sorted(asked - known)
        if missing:
            raise FloorplanError(f"{path}: no layer(s) {', '.join(missing)} ({option}); "
                                 f"its layers: {', '.join(sorted(names, key=str.lower))}")
    geometry = VectorGeometry()
    chord = ARC_CHORD / factor

    def visit(entities, depth: int = 0):
        for e in entities:
            layer = e.dxf.get("layer", "0").lower()
            kind = e.dxftype()
            what = f"{path}: DXF {kind} (handle {e.dxf.get('handle', '?')})"
            try:
                if kind == "INSERT":  # a block reference: its entities, placed (counted and cycle-free: _dxf_expansion)
                    visit(e.virtual_entities(), depth + 1)
                    continue
                if (wanted is not None and layer not in wanted) or layer in skipped:
                    continue
                if kind == "CIRCLE":
                    c = e.dxf.center
                    geometry.add_circle(c.x, c.y, e.dxf.radius, what)
                elif kind in ("LINE", "LWPOLYLINE", "POLYLINE", "ARC"):
                    for v in _dxf_defining_points(e):  # NaN / inf would hang or break the flattening
                        _coordinates([v], what)
                    p = ezpath.make_path(e)
                    points = [(v.x, v.y) for v in p.flattening(distance=chord)]
                    geometry.add(points, closed=kind in ("LWPOLYLINE", "POLYLINE") and bool(e.is_closed), what=what)
            except FloorplanError:
                raise
            except (ValueError, OverflowError, ZeroDivisionError, TypeError, ArithmeticError, ezdxf.DXFError) as err:
                raise FloorplanError(f"{what} cannot be read ({type(err).__name__}: {err})".replace("\n", " ")) from None

    visit(doc.modelspace())
    return _dxf_checked(geometry.scaled(factor), path, scale, units)


def _dxf_checked(geometry: VectorGeometry, path: Path, scale, units) -> VectorGeometry:
    """The drawing in metres, checked: within reach of 0, and (units from the header, not
    --scale) spanning at least a metre in the declared unit."""
    geometry.check_reach(path)
    if scale is None:
        geometry.check_span(path, _dxf_unit_name(units))
    return geometry


def _dxf_unit_name(raw) -> str:
    """The header's unit ($INSUNITS: raw), as the span check names it."""
    import ezdxf.units

    code = int(real_number(raw) or 0)
    if code in _DXF_EXTRA_UNITS:
        return f"{_DXF_EXTRA_UNITS[code][0]} ($INSUNITS = {code})"
    try:
        return f"{ezdxf.units.unit_name(code)} ($INSUNITS = {code})"
    except (KeyError, ValueError, IndexError, TypeError):
        return f"$INSUNITS = {code}"


def _dxf_defining_points(e) -> list[tuple[float, float]]:
    """The coordinates (and radii, as points) an entity is defined by."""
    kind = e.dxftype()
    if kind == "LINE":
        return [(e.dxf.start.x, e.dxf.start.y), (e.dxf.end.x, e.dxf.end.y)]
    if kind == "ARC":
        r, a0, a1 = e.dxf.radius, e.dxf.start_angle, e.dxf.end_angle
        return [(e.dxf.center.x, e.dxf.center.y), (r, a0), (a1, r if r > 0 else float("nan"))]
    if kind == "LWPOLYLINE":
        return [(x, y) for x, y, *_ in e.get_points("xyb")] + [(b, 0.0) for *_, b in e.get_points("xyb")]
    if kind == "POLYLINE":
        return [(v.dxf.location.x, v.dxf.location.y) for v in e.vertices]
    return []


def _svg_expansion(path: Path, max_entities: int) -> int:
    """Elements the SVG expands to, every <use> counted as what it references (per id
    once), before svgelements expands anything: FloorplanError past max_entities or for a
    <use> that references itself. expat refuses entity bombs and reads no external entity."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except OSError as err:
        raise FloorplanError(f"cannot read SVG floorplan {path}: {err.strerror or err}") from None
    except (ET.ParseError, ValueError, RecursionError) as err:
        raise FloorplanError(f"{path}: not a readable SVG file ({type(err).__name__}: {err})") from None
    by_id = {e.get("id"): e for e in root.iter() if e.get("id")}
    counts: dict[int, int] = {}
    href_keys = ("href", "{http://www.w3.org/1999/xlink}href")

    def count(element, inside: tuple[int, ...]) -> int:
        key = id(element)
        if key in counts:
            return counts[key]
        if key in inside:
            raise FloorplanError(f"{path}: an SVG <use> references an element that contains it (a cycle)")
        if len(inside) > 4 * MAX_NESTING:
            raise FloorplanError(f"{path}: SVG elements nested deeper than {4 * MAX_NESTING} levels (with <use> references)")
        total = 1
        for child in element:
            total += count(child, (*inside, key))
        if element.tag.rsplit("}", 1)[-1] == "use":
            ref = next((element.get(k) for k in href_keys if element.get(k)), "")
            target = by_id.get(ref[1:]) if ref.startswith("#") else None
            if target is not None:
                total += count(target, (*inside, key))
        if total > max_entities:
            raise FloorplanError(f"{path}: the SVG expands to more than {max_entities:,} elements (<use> of groups of <use>): "
                                 "a bomb, not a floor (--set datasets.vector_floorplan.max_entities=N raises the limit)")
        counts[key] = total
        return total

    return count(root, ())


def read_svg(path: Path, scale, max_entities: int = 1_000_000) -> VectorGeometry:
    import svgelements as se

    if scale is None:
        raise FloorplanError(f"{path}: an SVG floorplan has no real-world unit: pass --scale METRES_PER_UNIT (e.g. 0.01 when 1 unit = 1 cm)")
    _svg_expansion(path, max_entities)
    try:
        svg = se.SVG.parse(str(path), reify=True)
    except OSError as err:
        raise FloorplanError(f"cannot read SVG floorplan {path}: {err.strerror or err}") from None
    except Exception as err:  # noqa: BLE001 - svgelements raises XML and value errors of many kinds
        raise FloorplanError(f"{path}: not a readable SVG file ({type(err).__name__}: {err})") from None
    if not isinstance(svg, se.SVG):  # a damaged file parses to a bare element, or to nothing
        raise FloorplanError(f"{path}: not an SVG drawing (no <svg> root element)")
    geometry = VectorGeometry()
    with warnings.catch_warnings():
        # svgelements measures curves by numerical integration, which warns on extreme values
        # (refused below by their own checks): not the user's business
        warnings.simplefilter("ignore", IntegrationWarning)
        _svg_elements(svg, se, path, scale, geometry)
    geometry = geometry.scaled(scale, flip_y=True)
    geometry.check_reach(path)
    return geometry


def _svg_elements(svg, se, path: Path, scale: float, geometry: VectorGeometry) -> None:
    for k, element in enumerate(svg.elements()):
        what = f"{path}: SVG element {k} <{type(element).__name__.lower()}>"
        try:
            round_shape = isinstance(element, se.Circle) or (isinstance(element, se.Ellipse) and abs(element.rx - element.ry) < 1e-9 * max(element.rx, 1))
            m = element.transform if isinstance(element, se.Shape) else None
            similar = m is not None and abs(m.a - m.d) <= 1e-9 * (abs(m.a) + abs(m.b)) and abs(m.b + m.c) <= 1e-9 * (abs(m.a) + abs(m.b))
            mirrored = m is not None and abs(m.a + m.d) <= 1e-9 * (abs(m.a) + abs(m.b)) and abs(m.b - m.c) <= 1e-9 * (abs(m.a) + abs(m.b))
            if round_shape and (similar or mirrored):  # a circle stays a circle: its centre and radius moved
                centre = m.point_in_matrix_space((element.cx, element.cy))
                geometry.add_circle(centre.x, centre.y, element.rx * math.sqrt(abs(m.a * m.d - m.b * m.c)), what)
            elif isinstance(element, se.Shape):
                # reify leaves a rotation or skew on rects and ellipses: abs() applies it (a
                # copy of every segment: a path reify has already placed is read as it is)
                placed = isinstance(element, se.Path) and element.transform.is_identity()
                for sub in (element if placed else abs(se.Path(element))).as_subpaths():
                    sub = se.Path(sub)
                    points, closed = [], False
                    for seg in sub:
                        if isinstance(seg, se.Move):
                            points.append((seg.end.x, seg.end.y))
                        elif isinstance(seg, se.Close):
                            closed = True
                        elif isinstance(seg, se.Line):
                            points.append((seg.end.x, seg.end.y))
                        else:  # curves: enough chords for ARC_CHORD at this scale
                            _coordinates([(seg.start.x, seg.start.y), (seg.end.x, seg.end.y)], what)
                            chords = seg.length() * scale / (4 * ARC_CHORD)
                            if not math.isfinite(chords) or chords > MAX_CURVE_CHORDS:
                                raise FloorplanError(f"{what}: a curve {seg.length() * scale:.3g} m long: not a wall of one floor")
                            n = max(int(math.ceil(chords)), 2)
                            points += [(q.x, q.y) for q in (seg.point(t) for t in np.linspace(0, 1, n + 1)[1:])]
                    geometry.add(points, closed, what)
        except FloorplanError:
            raise
        except (ValueError, OverflowError, ZeroDivisionError, TypeError, ArithmeticError, AttributeError) as err:
            raise FloorplanError(f"{what} cannot be read ({type(err).__name__}: {err})".replace("\n", " ")) from None


def read_geojson(path: Path, scale) -> VectorGeometry:
    from shapely.errors import ShapelyError
    from shapely.geometry import shape

    try:
        data = json.loads(path.read_text())
    except OSError as err:
        raise FloorplanError(f"cannot read GeoJSON floorplan {path}: {err.strerror or err}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise FloorplanError(f"{path}: not valid JSON ({err})") from None
    except RecursionError:
        raise FloorplanError(f"{path}: nested deeper than the JSON parser can follow (GeoJSON needs a few levels)") from None
    except ValueError as err:  # an integer of thousands of digits (Python's int-digits limit)
        raise FloorplanError(f"{path}: not usable JSON ({err})") from None
    if too_deep(data, MAX_NESTING):
        raise FloorplanError(f"{path}: nested deeper than {MAX_NESTING} levels (GeoJSON needs a few)")
    if not isinstance(data, dict) or not isinstance(data.get("type"), str):
        raise FloorplanError(f"{path}: not GeoJSON (expected an object with a 'type')")
    if data["type"] == "FeatureCollection":
        features = data.get("features")
        if features is None:
            features = []
        if not isinstance(features, list):
            raise FloorplanError(f"{path}: 'features' must be a list of features, got {type(features).__name__}")
    else:
        features = [data if data["type"] == "Feature" else {"geometry": data}]
    scale = _geojson_crs_scale(data, path, scale)
    geometry = VectorGeometry()

    def visit(geom, props, what):
        kind = geom.geom_type
        if kind in ("MultiLineString", "MultiPolygon", "GeometryCollection", "MultiPoint"):
            for part in geom.geoms:
                visit(part, props, what)
        elif kind == "LineString":
            geometry.add(np.asarray(geom.coords)[:, :2], closed=geom.is_ring, what=what)
        elif kind == "LinearRing":
            geometry.add(np.asarray(geom.coords)[:, :2], closed=True, what=what)
        elif kind == "Polygon":
            for ring in [geom.exterior, *geom.interiors]:
                geometry.add(np.asarray(ring.coords)[:, :2], closed=True, what=what)
        elif kind == "Point" and props.get("radius") is not None:
            geometry.add_circle(geom.x, geom.y, props["radius"], what)

    for k, feature in enumerate(features):
        what = f"{path}: feature {k}"
        if not isinstance(feature, dict):
            raise FloorplanError(f"{what} is a {type(feature).__name__}, not a GeoJSON object")
        if feature.get("geometry") is None:
            continue
        props = feature.get("properties")
        if props is None:
            props = {}
        if not isinstance(props, dict):
            raise FloorplanError(f"{what}: 'properties' must be an object, got {type(props).__name__}")
        _check_coordinate_types(feature["geometry"], what)
        try:
            with np.errstate(all="ignore"):  # NaN coordinates: refused below, not warned about by shapely
                geom = shape(feature["geometry"])
            visit(geom, props, what)
        except FloorplanError:
            raise
        except (ShapelyError, ValueError, TypeError, KeyError, AttributeError, IndexError, OverflowError) as err:
            raise FloorplanError(f"{what} has an invalid geometry ({type(err).__name__}: {err})".replace("\n", " ")) from None
    geometry = geometry.scaled(1.0 if scale is None else scale)
    points = np.vstack([*geometry.polylines, *geometry.rings, np.zeros((0, 2))])
    if scale is None and len(points) and np.abs(points).max() <= 180 and np.ptp(points, axis=0).max() < 0.05:
        raise FloorplanError(f"{path}: coordinates look like longitude/latitude; a floorplan needs metres (project it to a metric CRS, or pass --scale)")
    geometry.check_reach(path)
    return geometry


def _check_coordinate_types(geometry, what: str) -> None:
    """Every GeoJSON coordinate a JSON number: shapely would read "5" and true as 5.0 and
    1.0 without a word."""
    stack = [geometry]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack += [item[k] for k in ("coordinates", "geometries") if k in item]
        elif isinstance(item, list):
            for v in item:
                if isinstance(v, (list, dict)):
                    stack.append(v)
                elif real_number(v) is None:
                    raise FloorplanError(f"{what} has a coordinate {str(v)[:40]!r} that is not a number")


_GEOGRAPHIC_CRS = ("crs84", "epsg::4326", "epsg:4326", "epsg::4269", "epsg:4269", "epsg::4258", "epsg:4258")


def _geojson_crs_scale(data: dict, path: Path, scale):
    """The scale to read a GeoJSON with a (2008-style) `crs` member: this reader converts no
    coordinate system, so one that is not lon/lat (refused) needs --scale to say its unit."""
    crs = data.get("crs")
    if crs is None or scale is not None:
        return scale
    name = crs.get("properties", {}).get("name") if isinstance(crs, dict) and isinstance(crs.get("properties"), dict) else None
    label = str(name)[:80] if name is not None else str(crs)[:80]
    if any(g in label.lower() for g in _GEOGRAPHIC_CRS):
        raise FloorplanError(f"{path}: crs {label} is longitude/latitude; a floorplan needs metres (project it to a metric CRS)")
    raise FloorplanError(f"{path}: declares crs {label}, whose unit this reader cannot know (it converts no coordinate system): "
                         "pass --scale METRES_PER_UNIT (1 for metres, 0.3048 for feet, 0.3048006 for US survey feet)")


# --- primitives from the vectors ----------------------------------------------------------------
