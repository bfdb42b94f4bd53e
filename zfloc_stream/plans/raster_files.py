"""Reading a raster plan's files, with every check made before anything large is
allocated: a ROS map_server YAML (keys, resolution, origin, thresholds) and its image, or a
bare image; the image's size is read from its header and held against
floorplan.max_image_cells before it is decoded (a plan over floorplan.max_cells is then
pooled to coarser cells: coarsening, pooled), a damaged image is named by Pillow before
OpenCV decodes it, and coordinates farther than MAX_COORDINATE from 0 are refused."""

from __future__ import annotations

import contextlib
import os
import threading
from pathlib import Path

import cv2
import numpy as np
import yaml

from ..settings.loading import Settings
from ..settings.documents import DocumentRefused, TooDeep, load_yaml, read_document_text, real_number, yaml_problem
from ..errors import FloorplanError


ROS_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
IMAGE_SUFFIXES = (".png", ".pgm", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
GIBSON_RESOLUTION = 0.01  # m/px of Gibson(t)/F3Loc map.png
# Largest |coordinate| in metres a plan may place anything at: farther than any projected
# CRS on Earth reaches (UTM northings stay below 1e7 m), and float64 still resolves 1e-8 m
# there; beyond it a coordinate is a mistake (1e308 would make every cell the same point).
MAX_COORDINATE = 1e8
_PIL_LOCK = threading.Lock()


@contextlib.contextmanager
def pillow():
    """Pillow's Image with its decompression-bomb guard off (our own budget applies,
    floorplan.max_image_cells), for one caller at a time (the guard is a module global)."""
    from PIL import Image

    with _PIL_LOCK:
        guard, Image.MAX_IMAGE_PIXELS = Image.MAX_IMAGE_PIXELS, None
        try:
            yield Image
        finally:
            Image.MAX_IMAGE_PIXELS = guard


def image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from the image file's header without decoding it (None when
    Pillow does not know the format; cv2 then reads it whole)."""
    with pillow() as Image:
        try:
            with Image.open(path) as im:
                return im.size
        except Exception:  # noqa: BLE001 - unknown format or damaged header: cv2 decides
            return None


def _decodes(path: Path) -> str | None:
    """Why Pillow cannot decode the image (None when it can, or does not know the format):
    checked before cv2 reads it, since libpng prints its own errors on stderr."""
    from PIL import UnidentifiedImageError

    with pillow() as Image:
        try:
            with Image.open(path) as im:
                im.load()
        except UnidentifiedImageError:
            return None
        except Exception as err:  # noqa: BLE001 - any decoder fault on damaged bytes
            return f"{type(err).__name__}: {err}"
    return None


def read_gray(path: Path, settings: Settings | None = None) -> np.ndarray:
    if not path.is_file():
        raise FloorplanError(f"floorplan image not found: {path}")
    size = image_size(path)
    if size is not None:  # the budget before the pixels are decoded
        check_cells(size[1], size[0], settings if settings is not None else Settings(), str(path))
        broken = _decodes(path)
        if broken is not None:
            raise FloorplanError(f"cannot read floorplan image {path}: damaged ({broken})")
    with _quiet_stderr():  # libpng prints its own messages for damaged files; ours follows
        img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if img is None or img.size == 0:
        raise FloorplanError(f"cannot read floorplan image (not a readable image file): {path}")
    return img


@contextlib.contextmanager
def _quiet_stderr():
    """File descriptor 2 to /dev/null for the block (C libraries' own messages)."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def check_cells(h: int, w: int, settings: Settings, source: str) -> None:
    """Refuse a raster of more cells than floorplan.max_image_cells (what is read whole
    before it is pooled to floorplan.max_cells)."""
    limit = settings.floorplan.max_image_cells
    if h * w > limit:
        raise FloorplanError(
            f"{source}: the plan is {w}x{h} cells ({h * w:,}), more than floorplan.max_image_cells = {limit:,} "
            f"(raise it with --set floorplan.max_image_cells=N where the machine has ~3 bytes per cell to read it)"
        )


def check_plan_budget(shape: tuple[int, int], resolution: float, settings: Settings, source: str) -> None:
    """Refuse a plan whose raster exceeds floorplan.max_image_cells, or whose estimator
    search grid (correlative.cell over the plan's extent) exceeds floorplan.max_cells,
    before either is allocated."""
    h, w = shape
    check_cells(h, w, settings, source)
    cell = settings.estimator.correlative.cell
    with np.errstate(over="ignore"):
        grid = (w * resolution / cell) * (h * resolution / cell)
    if not np.isfinite(grid) or grid > settings.floorplan.max_cells:
        raise FloorplanError(
            f"{source}: the plan spans {w * resolution:.4g} x {h * resolution:.4g} m ({w}x{h} cells at {resolution:.4g} m): "
            f"the estimator's search grid over it ({cell} m cells) would hold {grid:.3g} cells, more than "
            f"floorplan.max_cells = {settings.floorplan.max_cells:,}; is the resolution right? "
            f"(--set floorplan.max_cells=N raises the limit)"
        )


def coarsening(shape: tuple[int, int], settings: Settings) -> int:
    """The smallest whole factor k whose k x k pooling of a raster of this shape keeps at
    most floorplan.max_cells cells (1: the plan fits as it is)."""
    h, w = shape
    k = 1
    while -(-h // k) * -(-w // k) > settings.floorplan.max_cells:
        k += 1
    return k


def coarsening_warning(source: str, shape: tuple[int, int], resolution: float, k: int, settings: Settings) -> str:
    """The one line said when a plan of this shape (cells at resolution) is localized on
    k times coarser cells to fit floorplan.max_cells."""
    h, w = shape
    return (f"{source}: {w}x{h} cells at {resolution:g} m is more than floorplan.max_cells = "
            f"{settings.floorplan.max_cells:,}: localizing on {k * resolution:g} m cells "
            f"({-(-w // k)}x{-(-h // k)}); --set floorplan.max_cells={h * w} keeps every cell "
            f"(~60 bytes each while the plan is built)")


def pooled(occupied: np.ndarray, k: int) -> np.ndarray:
    """occupied pooled k x k from cell (0, 0) (the origin stays): a coarse cell is wall
    where any of its cells is, so thin walls stay closed; the last row / column of coarse
    cells may reach past the raster (free there)."""
    h, w = occupied.shape
    rows, cols = -(-h // k), -(-w // k)
    padded = np.zeros((rows * k, cols * k), dtype=bool)
    padded[:h, :w] = occupied
    return padded.reshape(rows, k, cols, k).any(axis=(1, 3))


def check_resolution(value, source: str) -> float:
    res = real_number(value)
    if res is None:
        raise FloorplanError(f"{source}: resolution must be a number of metres per pixel, got {value!r}")
    if not (np.isfinite(res) and res > 0):
        raise FloorplanError(f"{source}: resolution must be positive and finite, got {value!r}")
    return res


def check_origin(value, source: str) -> np.ndarray:
    items = list(value) if isinstance(value, (list, tuple, np.ndarray)) else None
    numbers = None if items is None else [real_number(v) for v in np.asarray(items, dtype=object).reshape(-1)]
    if numbers is None or any(v is None for v in numbers):
        raise FloorplanError(f"{source}: origin must be [x, y] or [x, y, yaw] of numbers, got {short_repr(value)}")
    o = np.array(numbers, dtype=float)
    if o.size not in (2, 3) or not np.isfinite(o).all():
        raise FloorplanError(f"{source}: origin must be [x, y] or [x, y, yaw] of finite numbers, got {short_repr(value)}")
    if np.abs(o[:2]).max() > MAX_COORDINATE:
        raise FloorplanError(f"{source}: origin {short_repr(value)} lies more than {MAX_COORDINATE:.0e} m from 0: not a place on Earth")
    if o.size == 3 and abs(o[2]) > 1e-9:
        raise FloorplanError(f"{source}: rotated map origins (yaw != 0) are not supported")
    return o[:2].copy()


def short_repr(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def check_fraction(meta: dict, key: str, source: str) -> float:
    v = real_number(meta[key])
    if v is None or not (0.0 <= v <= 1.0):
        raise FloorplanError(f"{source}: {key} must be a number in [0, 1], got {short_repr(meta[key])}")
    return v


def built_naming_file(path: Path, cls, *args):
    """cls(*args), its FloorplanError naming the file the plan came from."""
    try:
        return cls(*args)
    except FloorplanError as err:
        raise FloorplanError(f"{path}: {err}") from None


MAP_YAML_SUFFIXES = (".yaml", ".yml")


def read_map_yaml(path: Path):
    """The parsed map YAML (a ROS map, or a vector plan's `vector:` YAML), or a one-line
    FloorplanError."""
    if not path.exists():
        raise FloorplanError(f"floorplan YAML not found: {path}")
    try:
        return load_yaml(read_document_text(path))
    except TooDeep as err:
        raise FloorplanError(f"{path}: {err} (a map YAML is a flat mapping)") from None
    except DocumentRefused as err:
        raise FloorplanError(f"floorplan YAML {path} {err}" if str(err).startswith("is ") else f"floorplan YAML {path}: {err}") from None
    except OSError as err:
        raise FloorplanError(f"cannot read floorplan YAML {path}: {err.strerror or type(err).__name__}") from None
    except yaml.YAMLError as err:
        raise FloorplanError(f"cannot parse floorplan YAML {path}: {yaml_problem(err)}") from None
