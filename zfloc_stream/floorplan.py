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
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import cv2
import numpy as np
import yaml

from .config import Settings
from .errors import FloorplanError, InputError
from .geometry import CircleSet, LineSet, as_points, grid_subsample
from .rng import make_rng

ROS_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
IMAGE_SUFFIXES = (".png", ".pgm", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
GIBSON_RESOLUTION = 0.01  # m/px of Gibson(t)/F3Loc map.png


def _read_gray(path: Path) -> np.ndarray:
    if not path.is_file():
        raise FloorplanError(f"floorplan image not found: {path}")
    img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None or img.size == 0:
        raise FloorplanError(f"cannot read floorplan image (not a readable image file): {path}")
    return img


def _check_resolution(value, source: str) -> float:
    try:
        res = float(value)
    except (TypeError, ValueError):
        raise FloorplanError(f"{source}: resolution must be a number, got {value!r}") from None
    if not (np.isfinite(res) and res > 0):
        raise FloorplanError(f"{source}: resolution must be positive and finite, got {value!r}")
    return res


def _check_origin(value, source: str) -> np.ndarray:
    try:
        o = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise FloorplanError(f"{source}: origin must be [x, y] or [x, y, yaw], got {value!r}") from None
    if o.size not in (2, 3) or not np.isfinite(o).all():
        raise FloorplanError(f"{source}: origin must be [x, y] or [x, y, yaw] of finite numbers, got {value!r}")
    if o.size == 3 and abs(o[2]) > 1e-9:
        raise FloorplanError(f"{source}: rotated map origins (yaw != 0) are not supported")
    return o[:2].copy()


def _segment_distances(a0: np.ndarray, a1: np.ndarray, b0: np.ndarray, b1: np.ndarray) -> np.ndarray:
    """(N, M) minimum distance between segments a (N) and b (M); 0 where they cross."""

    def point_to_segment(p, s0, s1):  # p (N,1,2) or (1,M,2) broadcast with s (.., .., 2)
        d = s1 - s0
        t = np.clip(np.sum((p - s0) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-18), 0.0, 1.0)
        return np.linalg.norm(p - (s0 + t[..., None] * d), axis=-1)

    A0, A1 = a0[:, None, :], a1[:, None, :]
    B0, B1 = b0[None, :, :], b1[None, :, :]
    dist = np.minimum.reduce(
        [point_to_segment(A0, B0, B1), point_to_segment(A1, B0, B1), point_to_segment(B0, A0, A1), point_to_segment(B1, A0, A1)]
    )

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    da, db = A1 - A0, B1 - B0
    c1, c2 = cross(da, B0 - A0), cross(da, B1 - A0)
    c3, c4 = cross(db, A0 - B0), cross(db, A1 - B0)
    crossing = (c1 * c2 < 0) & (c3 * c4 < 0)
    return np.where(crossing, 0.0, dist)


class Floorplan:
    """Walls of one building in metres; build with from_occupancy / load / from_gibson_map."""

    def __init__(self, occupied, resolution: float, origin, settings: Settings | None = None, name: str = ""):
        occ = np.asarray(occupied)
        if occ.ndim != 2 or occ.shape[0] < 2 or occ.shape[1] < 2:
            raise FloorplanError(f"floorplan {name!r}: occupancy must be a 2D grid of at least 2x2 cells, got shape {occ.shape}")
        self.occupied = occ.astype(bool)
        self.occupied.setflags(write=False)
        self.resolution = _check_resolution(resolution, f"floorplan {name!r}")
        self.origin = _check_origin(origin, f"floorplan {name!r}")
        self.settings = settings if settings is not None else Settings()
        self.name = name
        if not self.occupied.any():
            raise FloorplanError(f"floorplan {name!r} has no wall cells (nothing is occupied)")
        rows, cols = np.nonzero(self.occupied)
        self.wall_points = self.cell_to_world(rows, cols)
        # Wall faces: wall cells next to a non-wall cell. The BEV sees wall surfaces, so the
        # floorplan's lines and circles are extracted from faces, not thick wall interiors.
        from scipy import ndimage  # here: ~0.25 s that a CLI error must not pay

        interior = ndimage.binary_erosion(self.occupied, border_value=1)
        frows, fcols = np.nonzero(self.occupied & ~interior)
        self.face_points = self.cell_to_world(frows, fcols)
        # f^c: exact Euclidean distance from every cell centre to the nearest wall cell centre.
        self.distance_field = ndimage.distance_transform_edt(~self.occupied, sampling=self.resolution)
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
        if suffix in (".dxf", ".svg", ".geojson", ".json"):  # vector drawings (vector_floorplan.py)
            from .vector_floorplan import load_vector_floorplan

            return load_vector_floorplan(path, settings)
        if suffix in (".yaml", ".yml"):
            if resolution is not None or origin is not None:
                raise FloorplanError(f"{path}: resolution and origin come from the YAML file; do not pass them")
            return cls._load_ros(path, settings)
        if suffix in IMAGE_SUFFIXES:
            missing = [k for k, v in (("resolution", resolution), ("origin", origin)) if v is None]
            if missing:
                raise FloorplanError(f"{path}: an image floorplan needs {' and '.join(missing)} (e.g. --resolution 0.05 --origin X,Y)")
            img = _read_gray(path)
            cfg = settings if settings is not None else Settings()
            occ = (255.0 - img) / 255.0 > cfg.floorplan.image_wall_threshold
            if flip_y:
                occ = occ[::-1]
            return cls(occ, resolution, origin, cfg, path.stem)
        raise FloorplanError(f"{path}: unknown floorplan format '{path.suffix}' (expected .yaml/.yml or an image: {', '.join(IMAGE_SUFFIXES)})")

    @classmethod
    def _load_ros(cls, path: Path, settings: Settings | None) -> Floorplan:
        if not path.is_file():
            raise FloorplanError(f"floorplan YAML not found: {path}")
        try:
            meta = yaml.safe_load(path.read_text())
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
            raise FloorplanError(f"cannot parse floorplan YAML {path}: {str(err).splitlines()[0]}") from None
        if isinstance(meta, dict) and "vector" in meta:  # a vector plan (as written into sessions)
            from .vector_floorplan import load_vector_yaml

            return load_vector_yaml(path, meta, settings)
        if not isinstance(meta, dict):
            raise FloorplanError(f"{path}: a ROS map YAML must be a mapping with keys {', '.join(ROS_KEYS)}")
        missing = [k for k in ROS_KEYS if k not in meta]
        if missing:
            raise FloorplanError(f"{path}: missing key(s) {', '.join(missing)}")
        resolution = _check_resolution(meta["resolution"], str(path))
        origin = _check_origin(meta["origin"], str(path))
        try:
            negate = bool(int(meta["negate"]))
            occ_thresh, free_thresh = float(meta["occupied_thresh"]), float(meta["free_thresh"])
        except (TypeError, ValueError):
            raise FloorplanError(f"{path}: negate must be 0/1 and occupied_thresh/free_thresh numbers") from None
        if not (0.0 <= free_thresh <= occ_thresh <= 1.0):
            raise FloorplanError(f"{path}: need 0 <= free_thresh <= occupied_thresh <= 1, got {free_thresh}, {occ_thresh}")
        image = Path(str(meta["image"]))
        if not image.is_absolute():
            image = path.parent / image
        img = _read_gray(image).astype(float)
        p = img / 255.0 if negate else (255.0 - img) / 255.0
        occ = (p > occ_thresh)[::-1]  # image row 0 = largest y
        return cls(occ, resolution, origin, settings, path.stem)

    @classmethod
    def from_gibson_map(cls, path, settings: Settings | None = None) -> Floorplan:
        """Gibson(t)/F3Loc map.png: dark walls, 0.01 m/px, point (x, y) at column
        x/0.01 + W/2 and row y/0.01 + H/2 (rows grow with y: no flip)."""
        path = Path(path)
        img = _read_gray(path)
        cfg = settings if settings is not None else Settings()
        occ = (255.0 - img) / 255.0 > cfg.floorplan.image_wall_threshold
        h, w = occ.shape
        origin = (-w / 2 * GIBSON_RESOLUTION, -h / 2 * GIBSON_RESOLUTION)
        return cls(occ, GIBSON_RESOLUTION, origin, cfg, path.parent.name or path.stem)

    def write_ros(self, directory, name: str = "map") -> Path:
        """Write name.yaml + name.png (map_server convention); returns the YAML path."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        img = np.where(self.occupied[::-1], 0, 254).astype(np.uint8)
        png = directory / f"{name}.png"
        if not cv2.imwrite(str(png), img):
            raise FloorplanError(f"cannot write floorplan image {png}")
        meta = {
            "image": png.name,
            "resolution": float(self.resolution),
            "origin": [float(self.origin[0]), float(self.origin[1]), 0.0],
            "negate": 0,
            "occupied_thresh": 0.65,
            "free_thresh": 0.196,
        }
        out = directory / f"{name}.yaml"
        out.write_text(yaml.safe_dump(meta, sort_keys=False))
        return out

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
        p = (as_points(points) - self.origin) / self.resolution
        return np.floor(p[:, 1]).astype(np.int64), np.floor(p[:, 0]).astype(np.int64)

    def cell_to_world(self, rows, cols) -> np.ndarray:
        """(N, 2) metric centres of cells."""
        rows, cols = np.asarray(rows, dtype=float), np.asarray(cols, dtype=float)
        return np.stack([self.origin[0] + (cols + 0.5) * self.resolution, self.origin[1] + (rows + 0.5) * self.resolution], axis=-1)

    def contains(self, points) -> np.ndarray:
        row, col = self.world_to_cell(points)
        h, w = self.shape
        return (row >= 0) & (row < h) & (col >= 0) & (col < w)

    # ----------------------------------------------------------------------------------
    # f^c lookup
    # ----------------------------------------------------------------------------------
    def distance(self, points) -> np.ndarray:
        """f^c at (N, 2) metric points: bilinear between cell centres. Outside the grid: the
        value at the nearest grid point plus the distance to it (finite, grows outward)."""
        p = np.asarray(points, dtype=float)
        if p.ndim != 2 or p.shape[-1] != 2:
            p = as_points(p)
        if not np.isfinite(p).all():
            raise InputError("points passed to Floorplan.distance contain NaN or inf")
        h, w = self.shape
        u = (p[:, 0] - self.origin[0]) / self.resolution - 0.5
        v = (p[:, 1] - self.origin[1]) / self.resolution - 0.5
        uc = np.clip(u, 0.0, w - 1.0)
        vc = np.clip(v, 0.0, h - 1.0)
        c0 = np.minimum(uc.astype(np.int64), w - 2)
        r0 = np.minimum(vc.astype(np.int64), h - 2)
        fu, fv = uc - c0, vc - r0
        i = r0 * w + c0
        f = self._flat_field
        top = f[i] * (1.0 - fu) + f[i + 1] * fu
        bottom = f[i + w] * (1.0 - fu) + f[i + w + 1] * fu
        value = top * (1.0 - fv) + bottom * fv
        outside = np.hypot(u - uc, v - vc) * self.resolution
        return value + outside

    # ----------------------------------------------------------------------------------
    # primitives
    # ----------------------------------------------------------------------------------
    @cached_property
    def lines(self) -> LineSet:
        cfg = self.settings
        from .primitives import deduplicate_lines, extract_lines  # compiled (numba): imported when first needed

        pts = grid_subsample(self.face_points, cfg.floorplan.line_point_spacing)
        raw = extract_lines(pts, cfg.primitives.lines, make_rng(cfg.seed, "floorplan-lines"))
        return deduplicate_lines(raw, cfg.primitives.lines)

    @cached_property
    def circles(self) -> CircleSet:
        from scipy import ndimage

        from .primitives import extract_circles  # compiled (numba): imported when first needed

        cfg = self.settings
        # Only isolated wall blobs (no wider than a pillar) can be pillars in a floorplan.
        labels, count = ndimage.label(self.occupied, structure=np.ones((3, 3), dtype=bool))
        if count == 0:
            return CircleSet.empty()
        limit = 2 * cfg.primitives.circles.max_radius / self.resolution + 2
        small = np.zeros(count + 1, dtype=bool)
        for k, sl in enumerate(ndimage.find_objects(labels), start=1):
            small[k] = sl is not None and max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start) <= limit
        rows, cols = self.world_to_cell(self.face_points)
        blob = small[labels[rows, cols]]
        if not blob.any():
            return CircleSet.empty()
        return extract_circles(self.face_points[blob], cfg.primitives.circles, make_rng(cfg.seed, "floorplan-circles"))

    @cached_property
    def line_neighbour_matrix(self) -> np.ndarray:
        """(N, N) bool: segment-to-segment distance < neighbour_distance (diagonal False)."""
        e = self.lines.endpoints
        n = len(e)
        near = np.zeros((n, n), dtype=bool)
        block = 256  # rows per block: bounds the (block, N, 2) temporaries on big floorplans
        for i in range(0, n, block):
            d = _segment_distances(e[i : i + block, 0], e[i : i + block, 1], e[:, 0], e[:, 1])
            near[i : i + block] = d < self.settings.floorplan.neighbour_distance
        np.fill_diagonal(near, False)
        return near

    @cached_property
    def line_neighbours(self) -> list[np.ndarray]:
        """For each line, indices of the lines within neighbour_distance of it."""
        return [np.flatnonzero(row) for row in self.line_neighbour_matrix]

    def sample_wall_points(self, spacing: float | None = None, faces_only: bool = True) -> np.ndarray:
        """Wall points thinned to about one per spacing x spacing (default
        floorplan.wall_sample_spacing); faces only by default, since thick-wall interiors add
        nothing a face does not already say."""
        spacing = self.settings.floorplan.wall_sample_spacing if spacing is None else float(spacing)
        return grid_subsample(self.face_points if faces_only else self.wall_points, spacing)

    def __repr__(self) -> str:
        h, w = self.shape
        return f"Floorplan({self.name!r}, {w}x{h} cells at {self.resolution} m, origin={tuple(self.origin)})"
