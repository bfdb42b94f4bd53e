"""Typed, validated input records: one per time step.

A frame is validated on construction, so everything downstream can trust shapes, dtypes
and finiteness. Invalid frames raise FrameError naming what is wrong; the streaming
localizer catches it, logs the reason and skips the frame.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .errors import FrameError

# A pose this far from the odometry origin (a million km) is no robot's: the rolling map's
# integer cells (and float precision) end long before 1e300 (issue 44: an OverflowError)
MAX_POSITION_M = 1e9

# Label codes (docs/inputs.md, /camera/labels mono8)
UNKNOWN, WALL, FLOOR, CEILING, OTHER = 0, 1, 2, 3, 4


def _as_float_array(value, name: str, dtype=float) -> np.ndarray:
    """np.asarray that reports non-numeric input as a FrameError instead of a raw error."""
    try:
        return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError):
        raise FrameError(f"{name} must be a numeric array") from None


def _check_pose(T, name: str) -> np.ndarray:
    T = _as_float_array(T, name)
    if T.shape != (4, 4):
        raise FrameError(f"{name} must be a 4x4 matrix, got shape {T.shape}")
    if not np.isfinite(T).all():
        raise FrameError(f"{name} contains NaN or inf")
    if np.abs(T[:3, 3]).max() > MAX_POSITION_M:
        raise FrameError(f"{name} position {T[:3, 3].tolist()} is beyond {MAX_POSITION_M:g} m of the odometry origin "
                         "(odometry in another unit, or garbage?)")
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-4 or np.linalg.det(R) < 0:
        raise FrameError(f"{name} rotation is not orthonormal (R^T R != I or det < 0)")
    if np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9:
        raise FrameError(f"{name} last row must be [0, 0, 0, 1]")
    return T


def _check_scalar(value, name: str) -> None:
    try:
        ok = np.isfinite(float(value))
    except (TypeError, ValueError):
        raise FrameError(f"{name} must be a number, got {value!r}") from None
    if not ok:
        raise FrameError(f"{name} is not finite")


@dataclass(frozen=True)
class CameraFrame:
    """Depth + per-pixel labels from a pinhole camera (OpenCV axes: x right, y down, z fwd).

    depth: HxW float32, metres along the optical axis; 0 or NaN = no reading. None for a
    plain RGB camera: the depth network (backbones) fills it in.
    labels: HxW uint8 with the codes above, or None when a segmentation network (if one
    is named) or the geometric labeller must label.
    K: 3x3 intrinsics. T_odom_cam: 4x4 camera-to-odometry pose (relative poses only).
    ground_truth: optional (x, y, theta) of the camera in the floorplan frame; never seen
    by the localizer, carried for logging and scoring.
    rgb: optional HxWx3 uint8 colour image (RGB order) of the same pixel grid.
    depth_unit: "m" (default) or "mm": what the depth numbers count. Integer depth (a
    16-bit depth camera's millimetres) must say "mm" (it is converted to float32 metres);
    integer depth said to be metres, boolean and complex depth are refused, and so is
    depth whose median reading is above MAX_MEDIAN_DEPTH_M (float millimetres said to be
    metres: every wall would be kilometres away).
    """

    depth: np.ndarray | None
    labels: np.ndarray | None
    K: np.ndarray
    T_odom_cam: np.ndarray
    timestamp: float
    ground_truth: np.ndarray | None = field(default=None, compare=False)
    rgb: np.ndarray | None = field(default=None, compare=False)
    depth_unit: str = field(default="m", compare=False)

    def __post_init__(self):
        rgb = None if self.rgb is None else _check_rgb(self.rgb)
        object.__setattr__(self, "rgb", rgb)
        if self.depth is None:
            if rgb is None:
                raise FrameError("a camera frame needs depth or an RGB image")
            self._check_rest(rgb.shape[:2])
            return
        d = _depth_in_metres(self.depth, self.depth_unit)
        object.__setattr__(self, "depth_unit", "m")
        if d.ndim != 2 or d.size == 0:
            raise FrameError(f"depth must be a non-empty HxW array, got shape {d.shape}")
        if np.isinf(d).any():
            raise FrameError("depth contains inf")
        valid = np.isfinite(d) & (d != 0)
        if (d[valid] < 0).any():
            raise FrameError("depth contains negative values")
        if not valid.any():
            raise FrameError("depth has no valid reading (all zero or NaN)")
        if median_above(d, MAX_MEDIAN_DEPTH_M, valid):
            raise FrameError(f"depth's median reading is {median_depth(d):.4g} m, implausible for an indoor camera "
                             f"(above {MAX_MEDIAN_DEPTH_M:g} m): millimetres? declare them (depth_unit='mm')")
        object.__setattr__(self, "depth", d)
        if rgb is not None and rgb.shape[:2] != d.shape:
            raise FrameError(f"rgb image is {rgb.shape[1]}x{rgb.shape[0]} but depth is {d.shape[1]}x{d.shape[0]}")
        self._check_rest(d.shape)

    def _check_rest(self, shape: tuple[int, int]) -> None:
        """Labels, K, pose and time (shared by depth and RGB-only frames)."""
        if self.labels is not None:
            lab = np.asarray(self.labels)
            if lab.shape != shape:
                raise FrameError(f"labels shape {lab.shape} does not match image shape {shape}")
            if lab.dtype != np.uint8:
                raise FrameError(f"labels must be uint8, got {lab.dtype}")
            if lab.max() > OTHER:
                raise FrameError(f"labels contain code {int(lab.max())}; valid codes are 0..{OTHER}")
        K = _as_float_array(self.K, "K")
        if K.shape != (3, 3) or not np.isfinite(K).all():
            raise FrameError("K must be a finite 3x3 matrix")
        if abs(np.linalg.det(K)) < 1e-12 or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise FrameError("K is singular (focal lengths must be positive)")
        if np.abs(K[2] - [0, 0, 1]).max() > 1e-9 or abs(K[1, 0]) > 1e-9:
            raise FrameError("K must be upper triangular with last row [0, 0, 1]")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "T_odom_cam", _check_pose(self.T_odom_cam, "T_odom_cam"))
        _check_scalar(self.timestamp, "timestamp")

    @property
    def shape(self) -> tuple[int, int]:
        return self.depth.shape if self.depth is not None else self.rgb.shape[:2]


DEPTH_UNITS = {"m": 1.0, "mm": 1e-3}
# An indoor depth camera reads at most a few tens of metres (structured light ~10 m, stereo
# ~20-40 m): a median reading above this is another unit (millimetres), never metres.
MAX_MEDIAN_DEPTH_M = 50.0


def median_above(d: np.ndarray, limit: float, valid: np.ndarray | None = None) -> bool:
    """Whether more than half the valid readings lie above limit (median > limit, without a sort)."""
    valid = np.isfinite(d) & (d != 0) if valid is None else valid
    with np.errstate(invalid="ignore"):
        return 2 * np.count_nonzero(d > limit) > np.count_nonzero(valid)


def median_depth(d: np.ndarray) -> float:
    """Median of the valid (finite, non-zero) readings; 0 when there is none."""
    v = d[np.isfinite(d) & (d != 0)]
    return float(np.median(v)) if v.size else 0.0


def _depth_in_metres(depth, unit: str) -> np.ndarray:
    """float32 metres from depth in `unit`. Integer depth is millimetres by every camera
    convention, so read as metres it would be 1000x too far: it must be declared."""
    if unit not in DEPTH_UNITS:
        raise FrameError(f"depth_unit must be one of {', '.join(DEPTH_UNITS)}, got {unit!r}")
    raw = np.asarray(depth)
    kind = raw.dtype.kind
    if kind in "bc":
        raise FrameError(f"depth must be real numbers of distance, got {raw.dtype} values")
    if kind in "iu" and unit == "m":
        raise FrameError(f"depth is {raw.dtype}: integer depth is millimetres by camera convention; "
                         "declare it (CameraFrame(..., depth_unit='mm')) or pass float metres")
    d = _as_float_array(raw, "depth", np.float32)
    return d if unit == "m" else (d.astype(np.float64) * DEPTH_UNITS[unit]).astype(np.float32)


def _check_rgb(rgb) -> np.ndarray:
    im = np.asarray(rgb)
    if im.ndim != 3 or im.shape[2] != 3 or im.size == 0:
        raise FrameError(f"rgb must be an HxWx3 image, got shape {im.shape}")
    if im.dtype != np.uint8:
        raise FrameError(f"rgb must be uint8, got {im.dtype}")
    return im


@dataclass(frozen=True)
class LaserFrame:
    """A planar range scan. Sensor axes: x forward, y left, z up; beam i points at
    angle_min + i * angle_increment (counter-clockwise from x). Readings outside
    [range_min, range_max] or non-finite are no-returns. T_odom_sensor: 4x4, the scan
    plane is assumed horizontal (odometry z up)."""

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    T_odom_sensor: np.ndarray
    timestamp: float
    ground_truth: np.ndarray | None = field(default=None, compare=False)

    def __post_init__(self):
        r = _as_float_array(self.ranges, "ranges")
        if r.ndim != 1 or r.size == 0:
            raise FrameError(f"ranges must be a non-empty 1D array, got shape {r.shape}")
        object.__setattr__(self, "ranges", r)
        for name in ("angle_min", "angle_increment", "range_min", "range_max", "timestamp"):
            _check_scalar(getattr(self, name), name)
        if self.angle_increment == 0:
            raise FrameError("angle_increment must be non-zero")
        if not 0 <= self.range_min < self.range_max:
            raise FrameError("need 0 <= range_min < range_max")
        object.__setattr__(self, "T_odom_sensor", _check_pose(self.T_odom_sensor, "T_odom_sensor"))

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(self.ranges.size)

    @property
    def valid(self) -> np.ndarray:
        r = self.ranges
        return np.isfinite(r) & (r >= self.range_min) & (r < self.range_max)


Frame = CameraFrame | LaserFrame
