"""Sensor messages <-> numpy for the session topics: depth, label and colour images,
calibration, poses (planar and 3D, by heading axis: schemas.py), laser scans, BEV and
floorplan grids. Pure functions: decoders validate what they read and raise
SessionLogError naming the field that is wrong."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration
from foxglove_schemas_protobuf.Grid_pb2 import Grid
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.Pose_pb2 import Pose
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage

from ...errors import SessionLogError
from ..messages import image_rows, matrix_from_quaternion, quaternion_from_matrix
from .topics import COLOR_ENCODINGS, COMPRESSED_FORMATS, FRAME_CAMERA, FRAME_FLOORPLAN, FRAME_LASER, FRAME_ODOM, LABEL_ENCODINGS, to_stamp


# --- images ---------------------------------------------------------------------------------
def depth_to_msg(depth: np.ndarray, ns: int, frame_id: str = FRAME_CAMERA) -> RawImage:
    """32FC1 little-endian, rows packed (step = 4 * width): lossless."""
    d = np.ascontiguousarray(depth, dtype="<f4")
    h, w = d.shape
    return RawImage(timestamp=to_stamp(ns), frame_id=frame_id, width=w, height=h, encoding="32FC1", step=4 * w, data=d.tobytes())


def labels_to_msg(labels: np.ndarray, ns: int, frame_id: str = FRAME_CAMERA) -> RawImage:
    lab = np.ascontiguousarray(labels, dtype=np.uint8)
    h, w = lab.shape
    return RawImage(timestamp=to_stamp(ns), frame_id=frame_id, width=w, height=h, encoding="mono8", step=w, data=lab.tobytes())


def labels_from_msg(msg: RawImage) -> np.ndarray:
    if msg.encoding not in LABEL_ENCODINGS:
        raise SessionLogError(f"labels encoding '{msg.encoding}' is not supported (expected mono8)")
    return image_rows(msg, "u1")


def image_to_msg(rgb: np.ndarray, ns: int, frame_id: str = FRAME_CAMERA) -> RawImage:
    """rgb8, rows packed: lossless, so a replay sees the same pixels."""
    im = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w = im.shape[:2]
    return RawImage(timestamp=to_stamp(ns), frame_id=frame_id, width=w, height=h, encoding="rgb8", step=3 * w, data=im.tobytes())


def image_from_msg(msg) -> np.ndarray:
    """HxWx3 uint8 in RGB order from a RawImage (rgb8, bgr8) or a CompressedImage (jpeg, png)."""
    if msg.DESCRIPTOR.full_name == "foxglove.CompressedImage":  # decoders build their own classes: match by name
        fmt = msg.format.lower().removeprefix("image/")
        if fmt not in COMPRESSED_FORMATS:
            raise SessionLogError(f"compressed image format '{msg.format}' is not supported (expected jpeg or png)")
        import cv2  # only compressed colour images need it

        bgr = cv2.imdecode(np.frombuffer(msg.data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise SessionLogError(f"compressed {fmt} image cannot be decoded")
        return np.ascontiguousarray(bgr[:, :, ::-1])
    if msg.encoding not in COLOR_ENCODINGS:
        raise SessionLogError(f"colour image encoding '{msg.encoding}' is not supported (expected one of {', '.join(COLOR_ENCODINGS)})")
    w = int(msg.width)
    flat = image_rows(RawImage(encoding=msg.encoding, width=3 * w, height=msg.height, step=msg.step, data=msg.data), "u1")
    im = flat.reshape(flat.shape[0], w, 3)
    return np.ascontiguousarray(im[:, :, ::-1]) if msg.encoding == "bgr8" else im


# --- calibration ------------------------------------------------------------------------------
def calibration_to_msg(K: np.ndarray, width: int, height: int, ns: int, frame_id: str = FRAME_CAMERA) -> CameraCalibration:
    K = np.asarray(K, dtype=float)
    P = np.zeros((3, 4))
    P[:, :3] = K
    return CameraCalibration(
        timestamp=to_stamp(ns),
        frame_id=frame_id,
        width=int(width),
        height=int(height),
        distortion_model="plumb_bob",
        D=[0.0] * 5,
        K=K.ravel().tolist(),
        R=np.eye(3).ravel().tolist(),
        P=P.ravel().tolist(),
    )


def distortion_from_msg(msg: CameraCalibration) -> tuple[str, tuple[float, ...]]:
    """(distortion model, D); refused where a coefficient is NaN or inf."""
    D = tuple(float(v) for v in msg.D)
    if not all(math.isfinite(v) for v in D):
        raise SessionLogError(f"calibration D {list(D)} contains NaN or inf")
    return str(msg.distortion_model), D


def calibration_from_msg(msg: CameraCalibration) -> tuple[np.ndarray, int, int]:
    """(K 3x3, width, height). Distortion: distortion_from_msg (removed by assemble.py)."""
    if len(msg.K) != 9:
        raise SessionLogError(f"calibration K has {len(msg.K)} values, expected 9")
    K = np.array(msg.K, dtype=float).reshape(3, 3)
    if not np.isfinite(K).all():
        raise SessionLogError("calibration K contains NaN or inf")
    return K, int(msg.width), int(msg.height)


# --- poses ------------------------------------------------------------------------------------
def _pose(position, quaternion) -> Pose:
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in position)
    (pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w) = (float(v) for v in quaternion)
    return pose


def pose_to_msg(T: np.ndarray, ns: int, frame_id: str) -> PoseInFrame:
    T = np.asarray(T, dtype=float)
    return PoseInFrame(timestamp=to_stamp(ns), frame_id=frame_id, pose=_pose(T[:3, 3], quaternion_from_matrix(T[:3, :3])))


def matrix_from_pose(pose: Pose) -> np.ndarray:
    p, o = pose.position, pose.orientation
    T = np.eye(4)
    T[:3, :3] = matrix_from_quaternion([o.x, o.y, o.z, o.w])
    T[:3, 3] = [p.x, p.y, p.z]
    if not np.isfinite(T).all():
        raise SessionLogError("pose position contains NaN or inf")
    return T


# heading axis of the sensor -> the rotation whose that axis points along theta, level
def _level_rotation(theta: float, heading_axis: str) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    if heading_axis == "x":  # body axes: x forward, y left, z up
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if heading_axis == "z":  # OpenCV camera: x right, y down, z forward
        return np.array([[s, 0.0, c], [-c, 0.0, s], [0.0, -1.0, 0.0]])
    raise SessionLogError(f"heading axis '{heading_axis}' is not one of x, z")


def planar_pose_to_pose(xytheta, heading_axis: str = "x") -> Pose:
    x, y, theta = (float(v) for v in xytheta)
    return _pose((x, y, 0.0), quaternion_from_matrix(_level_rotation(theta, heading_axis)))


def planar_pose_from_pose(pose: Pose, heading_axis: str = "x") -> np.ndarray:
    """(x, y, theta): position and the heading axis projected on the plane."""
    T = matrix_from_pose(pose)
    axis = {"x": 0, "z": 2}.get(heading_axis)
    if axis is None:
        raise SessionLogError(f"heading axis '{heading_axis}' is not one of x, z")
    h = T[:3, axis]
    if math.hypot(h[0], h[1]) < 1e-9:
        raise SessionLogError(f"pose heading axis {heading_axis} is vertical: no planar heading")
    return np.array([T[0, 3], T[1, 3], math.atan2(h[1], h[0])])


# --- laser ------------------------------------------------------------------------------------
def scan_to_msg(ranges: np.ndarray, angle_min: float, angle_increment: float, ns: int, frame_id: str = FRAME_LASER) -> LaserScan:
    r = np.asarray(ranges, dtype=float)
    msg = LaserScan(
        timestamp=to_stamp(ns),
        frame_id=frame_id,
        start_angle=float(angle_min),
        end_angle=float(angle_min + angle_increment * (r.size - 1)),
        ranges=r.tolist(),
    )
    msg.pose.orientation.w = 1.0
    return msg


def scan_from_msg(msg: LaserScan) -> tuple[np.ndarray, float, float]:
    """(ranges, angle_min, angle_increment). A scan origin off the sensor is refused:
    /odometry already is the sensor pose."""
    r = np.array(msg.ranges, dtype=float)
    if r.size < 2:
        raise SessionLogError(f"laser scan has {r.size} ranges, need at least 2")
    p, o = msg.pose.position, msg.pose.orientation
    if msg.HasField("pose") and (abs(p.x) + abs(p.y) + abs(p.z) > 1e-9 or abs(abs(o.w) - 1.0) > 1e-9):
        raise SessionLogError("laser scan pose is not the identity (the scan origin must be the sensor in /odometry)")
    inc = (msg.end_angle - msg.start_angle) / (r.size - 1)
    return r, float(msg.start_angle), float(inc)


# --- grid (BEV) -------------------------------------------------------------------------------
@dataclass(frozen=True)
class BevGrid:
    """A 2D float32 layer in the odometry plane (grid convention of ARCHITECTURE.md:
    row 0 = smallest y), published on /zfloc/bev."""

    values: np.ndarray  # (H, W) float32, e.g. occupancy log-odds
    origin: np.ndarray  # (2,) metres, lower-left corner of cell (0, 0)
    resolution: float  # metres per cell
    name: str = "log_odds"


def grid_to_msg(grid: BevGrid, ns: int, frame_id: str = FRAME_ODOM) -> Grid:
    v = np.ascontiguousarray(grid.values, dtype="<f4")
    h, w = v.shape
    msg = Grid(timestamp=to_stamp(ns), frame_id=frame_id, column_count=w, row_stride=4 * w, cell_stride=4, data=v.tobytes())
    msg.pose.position.x, msg.pose.position.y = (float(c) for c in grid.origin)
    msg.pose.orientation.w = 1.0
    msg.cell_size.x = msg.cell_size.y = float(grid.resolution)
    msg.fields.append(PackedElementField(name=grid.name, offset=0, type=PackedElementField.FLOAT32))
    return msg


def occupancy_grid_msg(occupied: np.ndarray, origin, resolution: float, ns: int, frame_id: str = FRAME_FLOORPLAN) -> Grid:
    """A bool occupancy raster (row 0 = smallest y) as a UINT8 Grid, 100 = wall: the
    floorplan drawn in Foxglove under the poses (display only; replay uses the attachment)."""
    v = np.ascontiguousarray(np.where(occupied, 100, 0), dtype=np.uint8)
    h, w = v.shape
    msg = Grid(timestamp=to_stamp(ns), frame_id=frame_id, column_count=w, row_stride=w, cell_stride=1, data=v.tobytes())
    msg.pose.position.x, msg.pose.position.y = (float(c) for c in origin)
    msg.pose.orientation.w = 1.0
    msg.cell_size.x = msg.cell_size.y = float(resolution)
    msg.fields.append(PackedElementField(name="occupied", offset=0, type=PackedElementField.UINT8))
    return msg


def grid_from_msg(msg: Grid) -> BevGrid:
    if len(msg.fields) < 1 or msg.fields[0].type != PackedElementField.FLOAT32 or msg.cell_stride != 4:
        raise SessionLogError("grid must hold one FLOAT32 field with cell_stride 4")
    w = int(msg.column_count)
    if w <= 0 or msg.row_stride != 4 * w or len(msg.data) % msg.row_stride:
        raise SessionLogError(f"grid data of {len(msg.data)} bytes does not fit {w} columns (row stride {msg.row_stride})")
    values = np.frombuffer(msg.data, dtype="<f4").reshape(-1, w).astype(np.float32)
    origin = np.array([msg.pose.position.x, msg.pose.position.y])
    return BevGrid(values, origin, float(msg.cell_size.x), msg.fields[0].name)
