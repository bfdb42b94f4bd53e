"""Vector floorplans: DXF (ezdxf), SVG (svgelements), GeoJSON (shapely), as architects and
facilities offices hand them out.

    plan = load_vector_floorplan("plan.dxf", settings, layers=["WALLS"])   # or plans.loading.load_floorplan

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

File reading is readers/'s, the collinear merge segment_merging.py's; this module
turns the geometry into a Floorplan.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..settings.loading import Settings
from ..settings.documents import real_number
from ..errors import FloorplanError
from .floorplan import Floorplan
from .raster_files import check_plan_budget, coarsening, coarsening_warning
from ..geometry.shapes import CircleSet, LineSet
from .readers import ARC_CHORD, CIRCLE_FIT_TOLERANCE, MIN_CIRCLE_VERTICES, VECTOR_SUFFIXES, VectorGeometry, read_dxf, read_geojson, read_svg
from .segment_merging import merge_collinear
from ..geometry.segment_pairs import deduplicate_lines

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




@dataclass
class _Primitives:
    segments: np.ndarray  # (N, 2, 2) every wall piece: the lines come from these
    outlines: np.ndarray  # (K, 2, 2) the pieces drawn as thick lines (centrelines, room outlines)
    solids: list[np.ndarray]  # closed rings drawn filled (wall footprints, square columns)
    circles: np.ndarray  # (M, 3) round pillars


def _segments(polylines) -> np.ndarray:
    """(N, 2, 2) consecutive point pairs of every polyline, in order: one concatenation,
    not an array per polyline (100,000 LINEs)."""
    if not polylines:
        return np.zeros((0, 2, 2))
    points = np.concatenate(polylines)
    last = np.cumsum([len(p) for p in polylines]) - 1  # each polyline's last point
    pair = np.ones(max(len(points) - 1, 0), dtype=bool)  # a pair starts at every point but a polyline's last
    pair[last[:-1]] = False
    starts = np.flatnonzero(pair)
    return np.stack([points[starts], points[starts + 1]], axis=1)


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
    factor = coarsening((h, w), settings)
    if factor > 1:  # a large building: drawn on coarser cells at once (the lines stay the drawing's own)
        warnings.warn(coarsening_warning(f"floorplan {name!r}", (h, w), res, factor, settings), stacklevel=3)
        res = res * factor
        w, h = -(-w // factor), -(-h // factor)
    shift = 4  # cv2 sub-pixel bits
    k = float(1 << shift)

    def pix(p):  # metres -> cv2 fixed-point pixel coordinates (pixel centres at integers)
        return np.round(((np.asarray(p) - lo) / res - 0.5) * k).astype(np.int32)

    img = np.zeros((h, w), dtype=np.uint8)  # row index grows with y: the internal convention
    thickness = max(int(round(cfg.wall_thickness / res)), 1)
    if len(prims.outlines):  # every segment a 2-point polyline, drawn in one call (100,000s of them: no Python loop)
        cv2.polylines(img, list(pix(prims.outlines.reshape(-1, 2)).reshape(-1, 2, 2)), False, 1, thickness=thickness,
                      lineType=cv2.LINE_8, shift=shift)
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
        if len(self.lines) == 0 and len(self.circles) == 0:  # all pieces shorter than a line, all dots smaller than a pillar
            lines, circles = settings.primitives.lines, settings.primitives.circles
            raise FloorplanError(f"{name}: no wall line of {lines.min_length} m (primitives.lines.min_length) or pillar of "
                                 f"radius {circles.min_radius} m or more: nothing to localize against")

    @cached_property
    def lines(self) -> LineSet:
        from ..primitives.line_growing import INLIER_DISTANCE  # compiled (numba): imported when first needed

        cfg = self.settings.primitives.lines
        segs = merge_collinear(self.primitive_geometry.segments, cfg.dedup_angle_deg, INLIER_DISTANCE, cfg.gap)
        segs = segs[np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) >= cfg.min_length]
        return deduplicate_lines(LineSet.from_endpoints(segs), cfg) if len(segs) else LineSet.empty()

    @cached_property
    def circles(self) -> CircleSet:
        c = self.primitive_geometry.circles
        keep = c[:, 2] >= self.settings.primitives.circles.min_radius
        return CircleSet(c[keep, :2].copy(), c[keep, 2].copy())

    def write_ros(self, directory, name: str = "map") -> Path:
        """The raster as a ROS map (name.yaml + name.png) whose YAML also names the drawing
        (copied beside it), so loading.load_floorplan of the YAML rebuilds this vector floorplan."""
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
    settings = settings if settings is not None else Settings()
    max_entities = settings.datasets.vector_floorplan.max_entities
    if suffix == ".dxf":
        geometry = read_dxf(path, scale, layers, skip_layers, max_entities)
    elif suffix == ".svg":
        geometry = read_svg(path, scale, max_entities)
    elif suffix in (".geojson", ".json"):
        geometry = read_geojson(path, scale)
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
