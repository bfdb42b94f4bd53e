"""Vector floorplans: DXF (ezdxf), SVG (svgelements), GeoJSON (shapely), as architects and
facilities offices hand them out.

    plan = load_vector_floorplan("plan.dxf", settings, layers=["WALLS"])   # or plan_loading.load_floorplan

What is read:
- DXF: LINE, LWPOLYLINE (bulges as arcs), POLYLINE, ARC, CIRCLE, also inside block
  references (INSERT); other entities (text, hatches, dimensions) are ignored. Units come
  from the header ($INSUNITS); a unitless drawing is taken as metres with a warning unless
  `scale` says otherwise. `layers` keeps only those layers, `skip_layers` drops some.
- SVG: paths, lines, polylines, polygons, rects, circles (transforms applied). SVG has no
  real-world unit, so `scale` (metres per user unit) is required. SVG y points down, the
  floorplan's up: the point (u, v) of the drawing is (u * scale, -v * scale) in metres.
- GeoJSON: LineString, Polygon (every ring), Multi* and collections, in metres (a
  projected CRS); a Point with a `radius` property is a round pillar.

Wall lines and pillar circles come straight from the vectors: touching collinear pieces
are merged, lines shorter than the line extractor's min_length dropped and near-duplicates
(the two faces of a thin wall) merged exactly as for a raster plan. A closed ring whose
vertices lie on a circle of pillar size (a polygonised column) is a circle; other small
closed rings are filled (square columns). The occupancy raster (distance field f^c, Cv,
overlay, simulation) is the geometry drawn at datasets.vector_floorplan.resolution, walls
drawn as lines wall_thickness thick.

A vector floorplan written into a session (write_ros) carries its source file and a YAML
that is both a ROS map_server file (image, resolution, origin: the raster) and names the
vector source (`vector:`), so a replay rebuilds the same lines and circles.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree
from scipy.integrate import IntegrationWarning

from .config import Settings
from .documents import MAX_NESTING, real_number, too_deep
from .errors import FloorplanError
from .floorplan import MAX_COORDINATE, Floorplan, check_plan_budget
from .geometry import CircleSet, LineSet, deduplicate_lines

VECTOR_SUFFIXES = (".dxf", ".svg", ".geojson", ".json")
ARC_CHORD = 0.05  # m, arcs and curves are flattened to chords deviating at most this much
CIRCLE_FIT_TOLERANCE = 0.02  # relative spread of a ring's vertex radii for it to be a circle
MIN_CIRCLE_VERTICES = 8
MAX_CURVE_CHORDS = 1_000_000  # a longer SVG curve (50 km at ARC_CHORD) is a unit mistake, not a wall


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
        reach = max([0.0] + [float(np.abs(p).max()) for p in (*self.polylines, *self.rings) if len(p)]
                    + [abs(x) + r for x, _, r in self.circles] + [abs(y) + r for _, y, r in self.circles])
        if not math.isfinite(reach) or reach > MAX_COORDINATE:
            raise FloorplanError(f"{source}: the drawing reaches {reach:.3g} m from 0 (more than {MAX_COORDINATE:.0e} m): "
                                 "a wrong unit, or a stray coordinate")

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
def _dxf_units(doc, path: Path, scale: float | None) -> float:
    import ezdxf.units

    if scale is not None:
        return scale
    raw = doc.header.get("$INSUNITS", 0)
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


def _read_dxf(path: Path, scale, layers, skip_layers) -> VectorGeometry:
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
    factor = _dxf_units(doc, path, scale)
    wanted = None if not layers else {name.lower() for name in layers}
    skipped = {name.lower() for name in skip_layers or ()}
    known = {layer.dxf.name.lower() for layer in doc.layers}
    missing = sorted((wanted or set()) - known)
    if missing:
        raise FloorplanError(f"{path}: no layer(s) {', '.join(missing)} (layers: {', '.join(sorted(layer.dxf.name for layer in doc.layers))})")
    geometry = VectorGeometry()
    chord = ARC_CHORD / factor

    def visit(entities, depth: int = 0):
        for e in entities:
            layer = e.dxf.get("layer", "0").lower()
            kind = e.dxftype()
            what = f"{path}: DXF {kind} (handle {e.dxf.get('handle', '?')})"
            try:
                if kind == "INSERT" and depth < 8:  # a block reference: its entities, placed
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
    geometry = geometry.scaled(factor)
    geometry.check_reach(path)
    return geometry


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


def _read_svg(path: Path, scale) -> VectorGeometry:
    import svgelements as se

    if scale is None:
        raise FloorplanError(f"{path}: an SVG floorplan has no real-world unit: pass --scale METRES_PER_UNIT (e.g. 0.01 when 1 unit = 1 cm)")
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
            if isinstance(element, se.Circle) or (isinstance(element, se.Ellipse) and abs(element.rx - element.ry) < 1e-9 * max(element.rx, 1)):
                geometry.add_circle(element.cx, element.cy, element.rx, what)
            elif isinstance(element, se.Shape):
                for sub in se.Path(element).as_subpaths():
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


def _read_geojson(path: Path, scale) -> VectorGeometry:
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


# --- primitives from the vectors ----------------------------------------------------------------
def _ring_circle(ring: np.ndarray, max_radius: float) -> tuple[float, float, float] | None:
    """(cx, cy, r) when a closed ring's vertices lie on a circle no larger than a pillar."""
    if len(ring) < MIN_CIRCLE_VERTICES:
        return None
    c = ring.mean(axis=0)
    radii = np.linalg.norm(ring - c, axis=1)
    r = float(radii.mean())
    if r <= 0 or r > max_radius or radii.std() > CIRCLE_FIT_TOLERANCE * r:
        return None
    return float(c[0]), float(c[1]), r


def _joins(a: np.ndarray, b: np.ndarray, cos_tol: float, offset: float, gap: float) -> np.ndarray:
    """(K,) bool, pairwise over broadcast (K, 2, 2) stacks: does segment b join segment a
    (parallel within the angle, both ends within offset of a's line, extents along it
    touching up to gap)."""
    a, b = np.broadcast_arrays(a, b)
    d = (a[:, 1] - a[:, 0]) / np.linalg.norm(a[:, 1] - a[:, 0], axis=1)[:, None]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    db = (b[:, 1] - b[:, 0]) / np.linalg.norm(b[:, 1] - b[:, 0], axis=1)[:, None]
    rel_b, rel_a = b - a[:, :1], a - a[:, :1]
    tb = np.einsum("kpi,ki->kp", rel_b, d)  # positions along a's line
    ta = np.einsum("kpi,ki->kp", rel_a, d)
    return ((np.abs(np.einsum("ki,ki->k", d, db)) >= cos_tol) & (np.abs(np.einsum("kpi,ki->kp", rel_b, n)).max(axis=1) <= offset)
            & ~(tb.min(axis=1) > ta.max(axis=1) + gap) & ~(ta.min(axis=1) > tb.max(axis=1) + gap))


def _joined(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a extended along its own line over b's extent."""
    d = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
    ta, tb = sorted(((a - a[0]) @ d).tolist()), sorted(((b - a[0]) @ d).tolist())
    return np.array([a[0] + min(ta[0], tb[0]) * d, a[0] + max(ta[1], tb[1]) * d])


def _merge_in_order(segs: np.ndarray, cos_tol: float, offset: float, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """The merge rule applied in index order: repeatedly the first segment (lowest index)
    that joins a later one absorbs the first such one. Each row's later partners are found
    in one vectorised test; after a merge only the survivor's pairs have changed, so the
    scan resumes at the earliest row that now joins it instead of at row 0 (the same merges
    as restarting the scan, without the cubic rescans). Returns the survivors and their rows."""
    segs = segs.copy()
    alive = np.ones(len(segs), dtype=bool)
    i = 0
    while i < len(segs):
        if not alive[i]:
            i += 1
            continue
        later = np.flatnonzero(alive[i + 1:]) + i + 1
        hit = later[_joins(segs[i:i + 1], segs[later], cos_tol, offset, gap)] if len(later) else later
        if not len(hit):
            i += 1
            continue
        segs[i] = _joined(segs[i], segs[hit[0]])
        alive[hit[0]] = False
        while True:  # an earlier row (which joined nothing before) may join the grown one now
            earlier = np.flatnonzero(alive[:i])
            back = earlier[_joins(segs[earlier], segs[i:i + 1], cos_tol, offset, gap)] if len(earlier) else earlier
            if not len(back):
                break
            segs[back[0]] = _joined(segs[back[0]], segs[i])
            alive[i] = False
            i = int(back[0])
    return segs[alive], np.flatnonzero(alive)


def _collinear_groups(segs: np.ndarray, angle_deg: float, offset: float, gap: float) -> np.ndarray:
    """Component label per segment: segments near each other and nearly parallel. A chain of
    merges keeps every member within offset of the first one's line and within angle_deg of
    its direction, and a grown segment reaches at most gap past a member's extent, so two
    segments that can end up in one merged line lie within `reach` of each other and within
    twice the angle: components of that (loose) graph never split a merge."""
    lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    reach = math.hypot(gap, offset) + gap + 2 * offset
    spacing = max(reach, 1e-6 * float(lengths.max()))
    # points every `spacing` along each segment (ends included): two segments within reach
    # have sample points within reach + spacing of each other
    count = np.ceil(lengths / spacing).astype(np.int64) + 1
    owner = np.repeat(np.arange(len(segs)), count)
    frac = (np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)) / np.repeat(count - 1, count)
    points = segs[owner, 0] + frac[:, None] * (segs[owner, 1] - segs[owner, 0])
    pairs = cKDTree(points).query_pairs(reach + spacing, output_type="ndarray")
    i, j = owner[pairs[:, 0]], owner[pairs[:, 1]]
    keep = i != j
    i, j = i[keep], j[keep]
    d = (segs[:, 1] - segs[:, 0]) / lengths[:, None]
    near = np.abs(np.einsum("ij,ij->i", d[i], d[j])) >= math.cos(math.radians(min(2 * angle_deg, 90.0)))
    graph = coo_matrix((np.ones(int(near.sum()), dtype=np.int8), (i[near], j[near])), shape=(len(segs), len(segs)))
    return connected_components(graph, directed=False)[1]


def merge_collinear(segments: np.ndarray, angle_deg: float, offset: float, gap: float) -> np.ndarray:
    """Join segments lying on one line whose extents touch or overlap (up to gap apart):
    a wall drawn in pieces is one line, as it is when extracted from pixels.

    Rule: in index order, the first segment that joins a later one (parallel within
    angle_deg, both ends within offset of its line, extents up to gap apart) absorbs it,
    extended along its own line; until nothing joins. Near-linear in the number of
    segments: only segments of one group (near each other and nearly parallel, found with
    a k-d tree) can merge, and the rule runs inside each group. Survivors keep the order
    of their first member."""
    segs = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    segs = segs[np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > 1e-9]
    if len(segs) < 2:
        return segs.copy()
    cos_tol = math.cos(math.radians(angle_deg))
    label = _collinear_groups(segs, angle_deg, offset, gap)
    order = np.argsort(label, kind="stable")  # each group's members in index order
    bounds = np.flatnonzero(np.diff(label[order])) + 1
    out, first = [], []
    for members in np.split(order, bounds):
        if len(members) == 1:
            out.append(segs[members])
            first.append(members[:1])
            continue
        merged, rows = _merge_in_order(segs[members], cos_tol, offset, gap)
        out.append(merged)
        first.append(members[rows])  # a survivor keeps its first member's place
    rows = np.concatenate(first)
    return np.concatenate(out)[np.argsort(rows, kind="stable")].reshape(-1, 2, 2)


@dataclass
class _Primitives:
    segments: np.ndarray  # (N, 2, 2) every wall piece: the lines come from these
    outlines: np.ndarray  # (K, 2, 2) the pieces drawn as thick lines (centrelines, room outlines)
    solids: list[np.ndarray]  # closed rings drawn filled (wall footprints, square columns)
    circles: np.ndarray  # (M, 3) round pillars


def _segments(polylines) -> np.ndarray:
    return np.concatenate([np.stack([p[:-1], p[1:]], axis=1) for p in polylines]) if polylines else np.zeros((0, 2, 2))


def _ring_width(ring: np.ndarray) -> float:
    """2 area / perimeter: the thickness of a long thin shape (a wall), half the side of a square."""
    x, y = ring[:, 0], ring[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    perimeter = np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1).sum()
    return 2.0 * area / max(perimeter, 1e-12)


def _thin_rectangle_axis(ring: np.ndarray, thin: float) -> np.ndarray | None:
    """The long axis (2, 2) of a rectangle no thicker than thin, else None. A thin wall's
    two faces are one line to the line extractor (faces closer than dedup_offset merge), so
    the vector plan gives that wall its centre line too."""
    if len(ring) != 4:
        return None
    edges = np.roll(ring, -1, axis=0) - ring
    lengths = np.linalg.norm(edges, axis=1)
    if min(lengths) <= 0 or abs(edges[0] @ edges[1]) > 1e-6 * lengths[0] * lengths[1] or not np.allclose(edges[0], -edges[2], atol=1e-9 + 1e-6 * lengths.max()):
        return None
    k = 0 if lengths[0] >= lengths[1] else 1  # edge k runs along the long side
    if lengths[1 - k] > thin:
        return None
    half = 0.5 * edges[1 - k]
    return np.array([ring[k] + half, ring[k + 1] + half])


def _primitives(geometry: VectorGeometry, settings: Settings) -> _Primitives:
    max_r = settings.primitives.circles.max_radius
    solid_width = settings.datasets.vector_floorplan.solid_max_width
    circles, outlines, solids = [], list(geometry.polylines), []
    for x, y, r in geometry.circles:  # radii are finite and > 0 (VectorGeometry.add_circle)
        if r <= max_r:
            circles.append((x, y, r))
        elif r > max_r:  # a round room or a curved wall: its outline is wall
            n = max(int(math.ceil(math.pi / math.acos(max(1 - ARC_CHORD / r, -1.0)))), 16)
            a = np.linspace(0, 2 * math.pi, n + 1)
            outlines.append(np.column_stack([x + r * np.cos(a), y + r * np.sin(a)]))
    for ring in geometry.rings:
        circle = _ring_circle(ring, max_r)
        if circle is not None:
            circles.append(circle)
        elif _ring_width(ring) <= solid_width:
            solids.append(ring)
        else:
            outlines.append(np.vstack([ring, ring[:1]]))
    # thin as the raster sees it: face cells half a cell inside each face
    thin = settings.primitives.lines.dedup_offset + settings.datasets.vector_floorplan.resolution
    solid_lines = []
    for ring in solids:
        axis = _thin_rectangle_axis(ring, thin)
        solid_lines.append(axis if axis is not None else np.vstack([ring, ring[:1]]))
    return _Primitives(_segments(outlines + solid_lines), _segments(outlines), solids, np.array(circles, dtype=float).reshape(-1, 3))


def _rasterise(prims: _Primitives, settings: Settings, name: str) -> tuple[np.ndarray, np.ndarray, float]:
    cfg = settings.datasets.vector_floorplan
    res = cfg.resolution
    pts = np.vstack([prims.segments.reshape(-1, 2), prims.circles[:, :2] - prims.circles[:, 2:],
                     prims.circles[:, :2] + prims.circles[:, 2:]])
    lo = np.floor((pts.min(axis=0) - cfg.margin) / res) * res
    hi = np.ceil((pts.max(axis=0) + cfg.margin) / res) * res
    fw, fh = np.round((hi - lo) / res)
    if not (np.isfinite(fw) and np.isfinite(fh)) or fw * fh > cfg.max_cells:
        raise FloorplanError(
            f"{name}: the drawing spans {hi[0] - lo[0]:.0f} x {hi[1] - lo[1]:.0f} m ({fw:.0f}x{fh:.0f} cells at {res} m), "
            f"more than datasets.vector_floorplan.max_cells = {cfg.max_cells:,}: is the unit scale right (--scale)? "
            "(--set datasets.vector_floorplan.max_cells=N raises the limit)"
        )
    w, h = int(fw), int(fh)
    check_plan_budget((h, w), res, settings, name)  # the estimator's grid too, before the raster
    shift = 4  # cv2 sub-pixel bits
    k = float(1 << shift)

    def pix(p):  # metres -> cv2 fixed-point pixel coordinates (pixel centres at integers)
        return np.round(((np.asarray(p) - lo) / res - 0.5) * k).astype(np.int32)

    img = np.zeros((h, w), dtype=np.uint8)  # row index grows with y: the internal convention
    thickness = max(int(round(cfg.wall_thickness / res)), 1)
    for a, b in prims.outlines:
        cv2.line(img, tuple(pix(a)), tuple(pix(b)), 1, thickness=thickness, lineType=cv2.LINE_8, shift=shift)
    for ring in prims.solids:
        cv2.fillPoly(img, [pix(ring)], 1, lineType=cv2.LINE_8, shift=shift)
    for x, y, r in prims.circles:
        cv2.circle(img, tuple(pix((x, y))), int(round(r / res * k)), 1, thickness=-1, lineType=cv2.LINE_8, shift=shift)
    return img.astype(bool), lo, res


# --- the floorplan ------------------------------------------------------------------------------
class VectorFloorplan(Floorplan):
    """A Floorplan whose lines and circles are the drawing's own; the raster is drawn from them."""

    def __init__(self, geometry: VectorGeometry, settings: Settings | None = None, name: str = "",
                 source: tuple[str, bytes] | None = None, options: dict | None = None):
        settings = settings if settings is not None else Settings()
        self.geometry = geometry
        self.primitive_geometry = _primitives(geometry, settings)
        self.source = source  # (file name, bytes) of the drawing, for write_ros
        self.options = dict(options or {})
        if len(self.primitive_geometry.segments) == 0 and len(self.primitive_geometry.circles) == 0:
            raise FloorplanError(f"floorplan {name!r}: the drawing holds no wall lines or circles")
        occupied, origin, res = _rasterise(self.primitive_geometry, settings, name)
        super().__init__(occupied, res, origin, settings, name)

    @cached_property
    def lines(self) -> LineSet:
        cfg = self.settings.primitives.lines
        segs = merge_collinear(self.primitive_geometry.segments, cfg.dedup_angle_deg, cfg.inlier_distance, cfg.gap)
        segs = segs[np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) >= cfg.min_length]
        return deduplicate_lines(LineSet.from_endpoints(segs), cfg) if len(segs) else LineSet.empty()

    @cached_property
    def circles(self) -> CircleSet:
        c = self.primitive_geometry.circles
        keep = c[:, 2] >= self.settings.primitives.circles.min_radius
        return CircleSet(c[keep, :2].copy(), c[keep, 2].copy())

    def write_ros(self, directory, name: str = "map") -> Path:
        """The raster as a ROS map (name.yaml + name.png) whose YAML also names the drawing
        (copied beside it), so plan_loading.load_floorplan of the YAML rebuilds this vector floorplan."""
        out = super().write_ros(directory, name)
        if self.source is not None:
            suffix = Path(self.source[0]).suffix.lower()
            (Path(directory) / f"{name}{suffix}").write_bytes(self.source[1])
            meta = yaml.safe_load(out.read_text())
            meta["vector"] = f"{name}{suffix}"
            meta.update(self.options)
            out.write_text(yaml.safe_dump(meta, sort_keys=False))
        return out


def _check_scale(scale, path: Path) -> float | None:
    if scale is None:
        return None
    value = real_number(scale)
    if value is None:
        raise FloorplanError(f"{path}: scale must be a number of metres per drawing unit, got {str(scale)[:40]!r}")
    if not (math.isfinite(value) and value > 0):
        raise FloorplanError(f"{path}: scale must be positive and finite (metres per drawing unit), got {str(scale)[:40]}")
    return value


def load_vector_floorplan(path, settings: Settings | None = None, scale: float | None = None,
                          layers=None, skip_layers=None) -> VectorFloorplan:
    """A DXF, SVG or GeoJSON floorplan. scale: metres per drawing unit (DXF: overrides the
    header's units; SVG: required); layers / skip_layers: DXF layer names to keep / drop."""
    path = Path(path)
    if not path.is_file():
        raise FloorplanError(f"floorplan file not found: {path}")
    suffix = path.suffix.lower()
    scale = _check_scale(scale, path)
    if (layers or skip_layers) and suffix != ".dxf":
        raise FloorplanError(f"{path}: layers apply to DXF floorplans only")
    if suffix == ".dxf":
        geometry = _read_dxf(path, scale, layers, skip_layers)
    elif suffix == ".svg":
        geometry = _read_svg(path, scale)
    elif suffix in (".geojson", ".json"):
        geometry = _read_geojson(path, scale)
    else:
        raise FloorplanError(f"{path}: unknown vector floorplan format '{path.suffix}' (expected {', '.join(VECTOR_SUFFIXES)})")
    if geometry.is_empty():
        what = f" on layer(s) {', '.join(layers)}" if layers else ""
        raise FloorplanError(f"{path}: no walls found{what} (no lines, polylines, arcs, polygons or circles)")
    options = {k: v for k, v in (("scale", scale), ("layers", list(layers or [])), ("skip_layers", list(skip_layers or []))) if v}
    try:
        return VectorFloorplan(geometry, settings, path.stem, source=(path.name, path.read_bytes()), options=options)
    except FloorplanError as err:  # messages name the plan by its stem: name the file instead
        raise FloorplanError(f"{path}: {str(err).removeprefix(path.stem + ': ')}") from None


def load_vector_yaml(path: Path, meta: dict, settings: Settings | None) -> VectorFloorplan:
    """A floorplan YAML with a `vector:` key (as write_ros writes for a vector plan)."""
    source = Path(str(meta["vector"]))
    if not source.is_absolute():
        source = path.parent / source
    return load_vector_floorplan(source, settings, scale=meta.get("scale"), layers=meta.get("layers") or None,
                                 skip_layers=meta.get("skip_layers") or None)


__all__ = ["VECTOR_SUFFIXES", "VectorFloorplan", "VectorGeometry", "load_vector_floorplan", "merge_collinear"]
