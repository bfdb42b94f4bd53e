"""The floorplan: an occupancy grid of walls and everything the estimator reads from it.

Grid convention (ARCHITECTURE.md): occupied[row, col]; cell (row, col) covers
x in [origin_x + col*res, +res), y in [origin_y + row*res, +res); row 0 = smallest y.
Images on disk follow their own convention: ROS map_server PNG/PGM row 0 = largest y
(flipped on load and on write); Gibson(t)/F3Loc map.png rows grow with y (no flip).

Derived once at construction: wall points, the distance field f^c (metres to the nearest
wall cell centre, exact Euclidean) with a bilinear lookup, line and circle primitives
extracted by the same code as the BEV, and line neighbourhoods for 3L pruning.

Primitives come from wall *faces* (wall cells next to a non-wall cell), since a BEV sees
wall surfaces, not the inside of thick walls: each face of a thick wall gives its own line,
and faces closer than dedup_offset (thin walls) merge into one. Circles are looked for only
in isolated wall blobs no wider than a pillar.

Reading a raster plan's files and their checks: raster_files.py.
"""

from __future__ import annotations

from functools import cached_property
import warnings
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..settings.loading import Settings
from ..errors import FloorplanError, InputError
from ..geometry.grid import Grid
from ..geometry.shapes import CircleSet, LineSet, as_points, grid_subsample
from .raster_files import (
    GIBSON_RESOLUTION,
    IMAGE_SUFFIXES,
    MAP_YAML_SUFFIXES,
    MAX_COORDINATE,
    ROS_KEYS,
    built_naming_file,
    check_fraction,
    check_origin,
    check_plan_budget,
    check_resolution,
    coarsening,
    coarsening_warning,
    image_size,
    pooled,
    read_gray,
    read_map_yaml,
    short_repr,
)
from ..runtime.rng import make_rng

# m, the floorplan wall points the violation term Cv reads are thinned to one per cell of
# this side: Cv is a ratio (wall points landing in observed free space over those landing
# in observed cells), so 0.2 m measures it about as well as every 0.05 m pixel, with 1/16
# of the points (was the setting floorplan.wall_sample_spacing; every recorded result used 0.2)
WALL_SAMPLE_SPACING = 0.2
# m, wall-face pixels are thinned to one per cell of this side before line growing: finer
# than a usual 0.05 m plan pixel, so such a plan keeps every face pixel, while a finer plan
# does not multiply the points line growing visits (was floorplan.line_point_spacing)
LINE_POINT_SPACING = 0.025


def _distance_field(occupied: np.ndarray, resolution: float) -> np.ndarray:
    """Exact Euclidean distance (metres) from every cell centre to the nearest wall cell
    centre. OpenCV's exact transform (Felzenszwalb) is ~10x faster than scipy's on a large
    map, but float32: its squared cell distances are integers, recovered exactly while they
    stay below 2^22 (float32 relative error 6e-8), and the metres computed in float64 from
    them; maps with larger empty stretches (> 2048 cells) take scipy's float64 transform."""
    free = np.ascontiguousarray(~occupied, dtype=np.uint8)
    cells = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    if float(cells.max()) >= 2048.0:
        from scipy import ndimage  # here: ~0.25 s that a CLI error must not pay

        return ndimage.distance_transform_edt(~occupied, sampling=resolution)
    field = np.square(cells, dtype=np.float64)  # in place from here: a large map's field is ~200 MB
    np.rint(field, out=field)
    np.sqrt(field, out=field)
    field *= resolution
    return field


def blob_spans(occupied: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(labels, span): 8-connected blobs of occupied cells (labels 1..count, 0 = free) and
    each label's bounding-box side in cells (span[0] = 0). All blobs at once: a cluttered
    map has ~10^5 of them, too many for a loop."""
    from scipy import ndimage  # here: ~0.25 s that a CLI error must not pay

    labels, count = ndimage.label(occupied, structure=np.ones((3, 3), dtype=bool))
    span = np.zeros(count + 1, dtype=np.int64)
    if count:
        rows, cols = np.nonzero(occupied)
        blob_of = labels[rows, cols]
        order = np.argsort(blob_of, kind="stable")
        blob_of, rows, cols = blob_of[order], rows[order], cols[order]
        first = np.flatnonzero(np.r_[True, blob_of[1:] != blob_of[:-1]])
        span[blob_of[first]] = np.maximum(np.maximum.reduceat(rows, first) - np.minimum.reduceat(rows, first),
                                          np.maximum.reduceat(cols, first) - np.minimum.reduceat(cols, first)) + 1
    return labels, span


class Floorplan:
    """Walls of one building in metres; build with from_occupancy / load / from_gibson_map."""

    def __init__(self, occupied, resolution: float, origin, settings: Settings | None = None, name: str = "",
                 unknown=None):
        """unknown: optional bool grid of the cells the source marks neither wall nor free
        (a ROS map's grey, between free_thresh and occupied_thresh); only written back out
        (write_ros, the ROS 2 OccupancyGrid's -1), never read by the estimator."""
        occ = np.asarray(occupied)
        if occ.ndim != 2 or occ.shape[0] < 2 or occ.shape[1] < 2:
            raise FloorplanError(f"floorplan {name!r}: occupancy must be a 2D grid of at least 2x2 cells, got shape {occ.shape}")
        self.resolution = check_resolution(resolution, f"floorplan {name!r}")
        self.origin = check_origin(origin, f"floorplan {name!r}")
        self.settings = settings if settings is not None else Settings()
        self.name = name
        check_plan_budget(occ.shape, self.resolution, self.settings, f"floorplan {name!r}")
        unk = None if unknown is None else np.asarray(unknown, dtype=bool)
        if unk is not None and unk.shape != occ.shape:
            raise FloorplanError(f"floorplan {name!r}: unknown-cell mask has shape {unk.shape}, the grid {occ.shape}")
        k = coarsening(occ.shape, self.settings)
        if k > 1:  # a large building: coarser cells keep its memory and load time bounded
            h, w = occ.shape
            occ = pooled(np.asarray(occ, dtype=bool), k)
            unk = None if unk is None else pooled(unk, k)  # pooled with the grid (a wall wins below)
            warnings.warn(coarsening_warning(f"floorplan {name!r}", (h, w), self.resolution, k, self.settings), stacklevel=2)
            self.resolution *= k
        extent = self.origin + np.array(occ.shape[::-1]) * self.resolution
        if np.abs(extent).max() > MAX_COORDINATE:
            raise FloorplanError(f"floorplan {name!r}: the plan reaches {np.abs(extent).max():.3g} m from 0: not a place on Earth")
        self.occupied = occ.astype(bool)
        self.occupied.setflags(write=False)
        self.grid = Grid(self.origin, self.resolution, self.occupied.shape)  # cells, centres, the bilinear f^c
        self.unknown = None  # None: every non-wall cell is free
        if unk is not None:
            if (unk & ~self.occupied).any():
                self.unknown = unk & ~self.occupied
                self.unknown.setflags(write=False)
        if not self.occupied.any():
            raise FloorplanError(f"floorplan {name!r} has no wall cells (nothing is occupied)")
        if self.occupied.all():
            raise FloorplanError(f"floorplan {name!r}: every cell is wall, nothing is free (an all-black image? "
                                 "a map drawn light on dark needs negate: 1)")
        rows, cols = np.nonzero(self.occupied)
        self.wall_points = self.cell_to_world(rows, cols)
        # Wall faces: wall cells next to a non-wall cell. The BEV sees wall surfaces, so the
        # floorplan's lines and circles are extracted from faces, not thick wall interiors.
        from scipy import ndimage  # here: ~0.25 s that a CLI error must not pay

        interior = ndimage.binary_erosion(self.occupied, border_value=1)
        frows, fcols = np.nonzero(self.occupied & ~interior)
        self.face_points = self.cell_to_world(frows, fcols)
        # f^c: exact Euclidean distance from every cell centre to the nearest wall cell centre.
        self.distance_field = _distance_field(self.occupied, self.resolution)
        self._flat_field = np.ascontiguousarray(self.distance_field).ravel()
        # Primitives are computed now, so a floorplan is complete once constructed.
        _ = self.lines, self.circles, self.line_neighbours

    # ----------------------------------------------------------------------------------
    # construction
    # ----------------------------------------------------------------------------------
    @classmethod
    def from_occupancy(cls, occupied, resolution: float, origin, settings: Settings | None = None, name: str = "") -> Floorplan:
        """occupied: bool (H, W) in the internal convention (row 0 = smallest y)."""
        return cls(occupied, resolution, origin, settings, name)

    @classmethod
    def load(
        cls,
        path,
        resolution: float | None = None,
        origin=None,
        settings: Settings | None = None,
        flip_y: bool = True,
        gibson: bool = False,
    ) -> Floorplan:
        """ROS map_server YAML (+ image), a plain image with resolution and origin
        (row 0 = largest y unless flip_y=False; dark pixels are walls), or with gibson=True
        a Gibson(t)/F3Loc map.png."""
        path = Path(path)
        if gibson:
            return cls.from_gibson_map(path, settings)
        suffix = path.suffix.lower()
        if suffix in (".dxf", ".svg", ".geojson", ".json"):  # plans/vector.py reads these, above this module
            raise FloorplanError(f"{path}: a vector drawing; load it with zfloc_stream.plans.loading.load_floorplan (every plan format)")
        if suffix in MAP_YAML_SUFFIXES:
            if resolution is not None or origin is not None:
                raise FloorplanError(f"{path}: resolution and origin come from the YAML file; do not pass them")
            return cls.from_map_yaml(path, settings)
        if suffix in IMAGE_SUFFIXES:
            missing = [k for k, v in (("resolution", resolution), ("origin", origin)) if v is None]
            if missing:
                raise FloorplanError(f"{path}: an image floorplan needs {' and '.join(missing)} (e.g. --resolution 0.05 --origin X Y: metres per pixel, then the metric position of the lower-left corner)")
            cfg = settings if settings is not None else Settings()
            res = check_resolution(resolution, str(path))
            check_origin(origin, str(path))
            size = image_size(path) if path.is_file() else None
            if size is not None:  # the extent budget too, before the pixels are decoded
                check_plan_budget(size[::-1], res, cfg, str(path))
            img = read_gray(path, cfg)
            occ = (255.0 - img) / 255.0 > cfg.floorplan.image_wall_threshold
            if flip_y:
                occ = occ[::-1]
            return built_naming_file(path, cls, occ, resolution, origin, cfg, path.stem)
        raise FloorplanError(f"{path}: unknown floorplan format '{path.suffix}' (expected a ROS map .yaml/.yml, an image ({', '.join(IMAGE_SUFFIXES)}) with --resolution and --origin, or a DXF/SVG/GeoJSON drawing (.dxf, .svg, .geojson/.json))")

    @classmethod
    def from_map_yaml(cls, path, settings: Settings | None = None, meta=None) -> Floorplan:
        """A ROS map_server YAML and its image; meta: the YAML already read (read_map_yaml)."""
        path = Path(path)
        if meta is None:
            meta = read_map_yaml(path)
        if isinstance(meta, dict) and "vector" in meta:  # a vector plan (as written into sessions)
            raise FloorplanError(f"{path}: the YAML of a vector plan; load it with zfloc_stream.plans.loading.load_floorplan (every plan format)")
        if not isinstance(meta, dict):
            raise FloorplanError(f"{path}: a ROS map YAML must be a mapping with keys {', '.join(ROS_KEYS)}")
        missing = [k for k in ROS_KEYS if k not in meta]
        if missing:
            raise FloorplanError(f"{path}: missing key(s) {', '.join(missing)}")
        resolution = check_resolution(meta["resolution"], str(path))
        origin = check_origin(meta["origin"], str(path))
        if meta["negate"] not in (0, 1) or isinstance(meta["negate"], float):
            raise FloorplanError(f"{path}: negate must be 0 or 1, got {short_repr(meta['negate'])}")
        negate = bool(meta["negate"])
        occ_thresh, free_thresh = check_fraction(meta, "occupied_thresh", str(path)), check_fraction(meta, "free_thresh", str(path))
        if not (free_thresh <= occ_thresh):
            raise FloorplanError(f"{path}: need 0 <= free_thresh <= occupied_thresh <= 1, got {free_thresh}, {occ_thresh}")
        if not isinstance(meta["image"], str) or not meta["image"].strip():
            raise FloorplanError(f"{path}: image must be the image's file name, got {short_repr(meta['image'])}")
        image = Path(meta["image"])
        if not image.is_absolute():
            image = path.parent / image
        cfg = settings if settings is not None else Settings()
        if not image.is_file():
            raise FloorplanError(f"{path}: its image {meta['image']!r} is not a file ({image})")
        size = image_size(image)
        if size is not None:  # the extent budget before the pixels are decoded
            check_plan_budget(size[::-1], resolution, cfg, str(path))
        try:
            img = read_gray(image, cfg)  # uint8
        except FloorplanError as err:
            raise FloorplanError(f"{path}: {err}") from None
        # occupancy probability of each grey level (map_server's rule), looked up per pixel:
        # the same test as on a float image, without ~200 MB of floats for a large map
        level = np.arange(256, dtype=float)
        p = level / 255.0 if negate else (255.0 - level) / 255.0
        occ = (p > occ_thresh)[img][::-1]  # image row 0 = largest y
        unknown = ~(p < free_thresh)[img][::-1] & ~occ  # map_server's trinary: neither free nor occupied
        return built_naming_file(path, cls, occ, resolution, origin, settings, path.stem, unknown)

    @classmethod
    def from_gibson_map(cls, path, settings: Settings | None = None) -> Floorplan:
        """Gibson(t)/F3Loc map.png: dark walls, 0.01 m/px, point (x, y) at column
        x/0.01 + W/2 and row y/0.01 + H/2 (rows grow with y: no flip)."""
        path = Path(path)
        cfg = settings if settings is not None else Settings()
        img = read_gray(path, cfg)
        occ = (255.0 - img) / 255.0 > cfg.floorplan.image_wall_threshold
        h, w = occ.shape
        origin = (-w / 2 * GIBSON_RESOLUTION, -h / 2 * GIBSON_RESOLUTION)
        return cls(occ, GIBSON_RESOLUTION, origin, cfg, path.parent.name or path.stem)

    def write_ros(self, directory, name: str = "map") -> Path:
        """Write name.yaml + name.png (map_server convention: 0 wall, 254 free, 205 unknown);
        returns the YAML path."""
        return write_ros_map(directory, name, self.occupied, self.resolution, self.origin, self.unknown)

    # ----------------------------------------------------------------------------------
    # grid geometry
    # ----------------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return self.occupied.shape

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the grid in metres."""
        h, w = self.shape
        x0, y0 = self.origin
        return (float(x0), float(y0), float(x0 + w * self.resolution), float(y0 + h * self.resolution))

    def world_to_cell(self, points) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) integer indices of the cells holding (N, 2) points (may lie outside)."""
        return self.grid.cell_of(as_points(points))

    def cell_to_world(self, rows, cols) -> np.ndarray:
        """(N, 2) metric centres of cells."""
        return np.stack(self.grid.centres(np.asarray(rows, dtype=float), np.asarray(cols, dtype=float)), axis=-1)

    def contains(self, points) -> np.ndarray:
        return self.grid.inside(*self.world_to_cell(points))

    # ----------------------------------------------------------------------------------
    # f^c lookup
    # ----------------------------------------------------------------------------------
    def distance(self, points) -> np.ndarray:
        """f^c at (N, 2) metric points: bilinear between cell centres. Outside the grid: the
        value at the nearest grid point plus the distance to it (finite, grows outward).
        The grid's one compiled lookup (geometry/bilinear.py), as the scores read f^c."""
        p = np.asarray(points, dtype=float)
        if p.ndim != 2 or p.shape[-1] != 2:
            p = as_points(p)
        if not np.isfinite(p).all():
            raise InputError("points passed to Floorplan.distance contain NaN or inf")
        return self.grid.bilinear(self.distance_field, p)

    # ----------------------------------------------------------------------------------
    # primitives
    # ----------------------------------------------------------------------------------
    @cached_property
    def lines(self) -> LineSet:
        cfg = self.settings
        from ..primitives.extract import deduplicate_lines, extract_lines  # compiled (numba): imported when first needed

        pts = grid_subsample(self.face_points, LINE_POINT_SPACING)
        raw = extract_lines(pts, cfg.primitives.lines, make_rng(cfg.seed, "floorplan-lines"))
        return deduplicate_lines(raw, cfg.primitives.lines)

    @cached_property
    def circles(self) -> CircleSet:
        from ..primitives.extract import extract_circles  # compiled (numba): imported when first needed

        cfg = self.settings
        # Only isolated wall blobs (no wider than a pillar) can be pillars in a floorplan.
        labels, span = blob_spans(self.occupied)
        if len(span) == 1:
            return CircleSet.empty()
        small = span <= 2 * cfg.primitives.circles.max_radius / self.resolution + 2
        small[0] = False
        rows, cols = self.world_to_cell(self.face_points)
        blob = small[labels[rows, cols]]
        if not blob.any():
            return CircleSet.empty()
        return extract_circles(self.face_points[blob], cfg.primitives.circles, make_rng(cfg.seed, "floorplan-circles"))

    @cached_property
    def line_neighbours(self) -> list[np.ndarray]:
        """For each line, the ascending indices (int32) of the lines within
        floorplan.neighbour_distance of it (segment distance; 0 where two cross), itself
        excluded. Lists, not an (N, N) matrix: a drawing of 100,000 short lines keeps
        ~58,000 of them (segment_pairs.py)."""
        from ..geometry.segment_pairs import segment_neighbours  # compiled (numba): imported when first needed

        return segment_neighbours(self.lines.endpoints, self.settings.floorplan.neighbour_distance)

    def sample_wall_points(self, spacing: float | None = None, faces_only: bool = True) -> np.ndarray:
        """Wall points thinned to about one per spacing x spacing (default
        WALL_SAMPLE_SPACING); faces only by default, since thick-wall interiors add
        nothing a face does not already say."""
        spacing = WALL_SAMPLE_SPACING if spacing is None else float(spacing)
        return grid_subsample(self.face_points if faces_only else self.wall_points, spacing)

    def __repr__(self) -> str:
        h, w = self.shape
        return f"Floorplan({self.name!r}, {w}x{h} cells at {self.resolution} m, origin={tuple(self.origin)})"


def write_ros_map(directory, name: str, occupied: np.ndarray, resolution: float, origin, unknown: np.ndarray | None = None) -> Path:
    """Write a grid (row index grows with y) as name.yaml + name.png, map_server's
    convention: 0 wall, 254 free, 205 unknown; returns the YAML path. Floorplan.write_ros,
    and a raster written without building a plan (benchmarks)."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    img = np.where(occupied[::-1], 0, 254).astype(np.uint8)
    if unknown is not None:
        img[unknown[::-1]] = 205  # p = 0.196: above free_thresh 0.196, below occupied_thresh
    png = directory / f"{name}.png"
    if not cv2.imwrite(str(png), img):
        raise FloorplanError(f"cannot write floorplan image {png}")
    meta = {
        "image": png.name,
        "resolution": float(resolution),
        "origin": [float(origin[0]), float(origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
    }
    out = directory / f"{name}.yaml"
    out.write_text(yaml.safe_dump(meta, sort_keys=False))
    return out
