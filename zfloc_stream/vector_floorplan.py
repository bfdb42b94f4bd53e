"""Vector floorplans: DXF (ezdxf), SVG (svgelements), GeoJSON (shapely), as architects and
facilities offices hand them out.

    plan = load_vector_floorplan("plan.dxf", settings, layers=["WALLS"])   # or via Floorplan.load

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

from .config import Settings
from .errors import FloorplanError
from .floorplan import Floorplan
from .geometry import CircleSet, LineSet, deduplicate_lines

VECTOR_SUFFIXES = (".dxf", ".svg", ".geojson", ".json")
ARC_CHORD = 0.05  # m, arcs and curves are flattened to chords deviating at most this much
CIRCLE_FIT_TOLERANCE = 0.02  # relative spread of a ring's vertex radii for it to be a circle
MIN_CIRCLE_VERTICES = 8


@dataclass
class VectorGeometry:
    """Drawing contents in metres: open polylines, closed rings, circles (cx, cy, r)."""

    polylines: list[np.ndarray] = field(default_factory=list)
    rings: list[np.ndarray] = field(default_factory=list)
    circles: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, points, closed: bool) -> None:
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        if closed and len(p) > 1 and np.allclose(p[0], p[-1]):
            p = p[:-1]
        if len(p) >= 3 and closed:
            self.rings.append(p)
        elif len(p) >= 2:
            self.polylines.append(np.vstack([p, p[:1]]) if closed else p)

    def scaled(self, factor: float, flip_y: bool = False) -> VectorGeometry:
        s = np.array([factor, -factor if flip_y else factor])
        return VectorGeometry([p * s for p in self.polylines], [r * s for r in self.rings],
                              [(x * s[0], y * s[1], r * factor) for x, y, r in self.circles])

    def is_empty(self) -> bool:
        return not (self.polylines or self.rings or self.circles)


# --- readers ------------------------------------------------------------------------------------
def _dxf_units(doc, path: Path, scale: float | None) -> float:
    import ezdxf.units

    if scale is not None:
        return scale
    code = int(doc.header.get("$INSUNITS", 0))
    if code == 0:
        warnings.warn(f"{path}: the DXF header gives no units ($INSUNITS = 0): taking drawing units as metres (--scale to change)", stacklevel=3)
        return 1.0
    try:
        return float(ezdxf.units.conversion_factor(code, ezdxf.units.M))
    except (KeyError, ValueError, IndexError):
        raise FloorplanError(f"{path}: DXF header $INSUNITS = {code} is not a length unit: pass --scale") from None


def _read_dxf(path: Path, scale, layers, skip_layers) -> VectorGeometry:
    import ezdxf
    from ezdxf import path as ezpath

    try:
        doc = ezdxf.readfile(path)
    except OSError as err:
        raise FloorplanError(f"cannot read DXF floorplan {path}: {err.strerror or err}") from None
    except ezdxf.DXFError as err:
        raise FloorplanError(f"{path}: not a valid DXF file ({err})") from None
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
            if kind == "INSERT" and depth < 8:  # a block reference: its entities, placed
                visit(e.virtual_entities(), depth + 1)
                continue
            if (wanted is not None and layer not in wanted) or layer in skipped:
                continue
            if kind == "CIRCLE":
                c = e.dxf.center
                geometry.circles.append((float(c.x), float(c.y), float(e.dxf.radius)))
            elif kind in ("LINE", "LWPOLYLINE", "POLYLINE", "ARC"):
                p = ezpath.make_path(e)
                points = [(v.x, v.y) for v in p.flattening(distance=chord)]
                geometry.add(points, closed=kind in ("LWPOLYLINE", "POLYLINE") and bool(e.is_closed))

    visit(doc.modelspace())
    return geometry.scaled(factor)


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
    geometry = VectorGeometry()
    for element in svg.elements():
        if isinstance(element, se.Circle) or (isinstance(element, se.Ellipse) and abs(element.rx - element.ry) < 1e-9 * max(element.rx, 1)):
            geometry.circles.append((float(element.cx), float(element.cy), float(element.rx)))
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
                        n = max(int(math.ceil(seg.length() * scale / (4 * ARC_CHORD))), 2)
                        points += [(q.x, q.y) for q in (seg.point(t) for t in np.linspace(0, 1, n + 1)[1:])]
                geometry.add(points, closed)
    return geometry.scaled(scale, flip_y=True)


def _read_geojson(path: Path, scale) -> VectorGeometry:
    from shapely.geometry import shape
    from shapely.errors import GeometryTypeError

    try:
        data = json.loads(path.read_text())
    except OSError as err:
        raise FloorplanError(f"cannot read GeoJSON floorplan {path}: {err.strerror or err}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise FloorplanError(f"{path}: not valid JSON ({err})") from None
    if not isinstance(data, dict) or "type" not in data:
        raise FloorplanError(f"{path}: not GeoJSON (expected an object with a 'type')")
    features = data.get("features") if data["type"] == "FeatureCollection" else [data if data["type"] == "Feature" else {"geometry": data}]
    geometry = VectorGeometry()

    def visit(geom, props):
        kind = geom.geom_type
        if kind in ("MultiLineString", "MultiPolygon", "GeometryCollection", "MultiPoint"):
            for part in geom.geoms:
                visit(part, props)
        elif kind == "LineString":
            geometry.add(np.asarray(geom.coords)[:, :2], closed=geom.is_ring)
        elif kind == "LinearRing":
            geometry.add(np.asarray(geom.coords)[:, :2], closed=True)
        elif kind == "Polygon":
            for ring in [geom.exterior, *geom.interiors]:
                geometry.add(np.asarray(ring.coords)[:, :2], closed=True)
        elif kind == "Point" and props.get("radius") is not None:
            geometry.circles.append((geom.x, geom.y, float(props["radius"])))

    for k, feature in enumerate(features or []):
        if not isinstance(feature, dict) or feature.get("geometry") is None:
            continue
        try:
            geom = shape(feature["geometry"])
        except (GeometryTypeError, ValueError, TypeError, KeyError, AttributeError) as err:
            raise FloorplanError(f"{path}: feature {k} has an invalid geometry ({type(err).__name__}: {err})") from None
        visit(geom, feature.get("properties") or {})
    geometry = geometry.scaled(1.0 if scale is None else scale)
    points = np.vstack([*geometry.polylines, *geometry.rings, np.zeros((0, 2))])
    if scale is None and len(points) and np.abs(points).max() <= 180 and np.ptp(points, axis=0).max() < 0.05:
        raise FloorplanError(f"{path}: coordinates look like longitude/latitude; a floorplan needs metres (project it to a metric CRS, or pass --scale)")
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


def merge_collinear(segments: np.ndarray, angle_deg: float, offset: float, gap: float) -> np.ndarray:
    """Join segments lying on one line whose extents touch or overlap (up to gap apart):
    a wall drawn in pieces is one line, as it is when extracted from pixels."""
    segs = [s for s in np.asarray(segments, dtype=float).reshape(-1, 2, 2) if np.linalg.norm(s[1] - s[0]) > 1e-9]
    cos_tol = math.cos(math.radians(angle_deg))
    merged = True
    while merged:
        merged = False
        for i in range(len(segs)):
            a = segs[i]
            d = (a[1] - a[0]) / np.linalg.norm(a[1] - a[0])
            n = np.array([-d[1], d[0]])
            for j in range(i + 1, len(segs)):
                b = segs[j]
                db = (b[1] - b[0]) / np.linalg.norm(b[1] - b[0])
                if abs(d @ db) < cos_tol or np.abs((b - a[0]) @ n).max() > offset:
                    continue
                ta, tb = sorted(((a - a[0]) @ d).tolist()), sorted(((b - a[0]) @ d).tolist())
                if tb[0] > ta[1] + gap or ta[0] > tb[1] + gap:
                    continue
                lo, hi = min(ta[0], tb[0]), max(ta[1], tb[1])
                segs[i] = np.array([a[0] + lo * d, a[0] + hi * d])
                del segs[j]
                merged = True
                break
            if merged:
                break
    return np.array(segs).reshape(-1, 2, 2)


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
    for x, y, r in geometry.circles:
        if 0 < r <= max_r:
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
    w, h = (int(v) for v in np.round((hi - lo) / res))
    if w * h > cfg.max_cells:
        raise FloorplanError(
            f"{name}: the drawing spans {hi[0] - lo[0]:.0f} x {hi[1] - lo[1]:.0f} m ({w}x{h} cells at {res} m): "
            "too large for one floor; is the unit scale right (--scale)?"
        )
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
        (copied beside it), so Floorplan.load of the YAML rebuilds this vector floorplan."""
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
    try:
        value = float(scale)
    except (TypeError, ValueError):
        raise FloorplanError(f"{path}: scale must be a number of metres per drawing unit, got {scale!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise FloorplanError(f"{path}: scale must be positive (metres per drawing unit), got {scale!r}")
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
    except FloorplanError as err:
        raise FloorplanError(f"{path}: {err}") from None


def load_vector_yaml(path: Path, meta: dict, settings: Settings | None) -> VectorFloorplan:
    """A floorplan YAML with a `vector:` key (as write_ros writes for a vector plan)."""
    source = Path(str(meta["vector"]))
    if not source.is_absolute():
        source = path.parent / source
    return load_vector_floorplan(source, settings, scale=meta.get("scale"), layers=meta.get("layers") or None,
                                 skip_layers=meta.get("skip_layers") or None)


__all__ = ["VECTOR_SUFFIXES", "VectorFloorplan", "VectorGeometry", "load_vector_floorplan", "merge_collinear"]
