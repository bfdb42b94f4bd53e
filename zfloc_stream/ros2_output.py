"""The estimates as ROS 2 messages (`zfloc-stream run --ros2`): an MCAP file with the ROS 2
profile and CDR messages, written by mcap-ros2-support, which ROS 2 tools (ros2 bag, RViz
through a player, Foxglove) and evo (`evo_ape bag2 ...`, through rosbags) read.

Topics (frame ids: `map` = the floorplan, `odom` = the odometry plane):
- /zfloc/pose          geometry_msgs/PoseStamped in `map`, one per frame with a pose
- /zfloc/groundtruth   geometry_msgs/PoseStamped in `map`, where the frame's truth is known
- /tf                  tf2_msgs/TFMessage `map -> odom`, like a ROS localizer publishes it
- /zfloc/floorplan     nav_msgs/OccupancyGrid in `map`, once, with the first frame

The alignment the localizer estimates is a similarity (it may scale odometry); a tf is
rigid, so `map -> odom` is the rigid transform that puts this frame's odometry-plane pose
on its estimated pose (what AMCL publishes): exact at each frame's stamp. Stamps are the
trajectory.tum ones (a repeated input stamp moved 1 us on), so evo pairs the topics with
the TUM files and with each other.

The message definitions are the ROS 2 Humble ones (ros2msg text with dependencies).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .errors import InputError

SEP = "=" * 80 + "\n"
TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
POINT = "MSG: geometry_msgs/Point\nfloat64 x\nfloat64 y\nfloat64 z\n"
QUATERNION = "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
POSE = "MSG: geometry_msgs/Pose\ngeometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"


def msgdef(main: str, *deps: str) -> str:
    """A ros2msg schema: the type's own fields, then each dependency after a separator."""
    return main + "".join(SEP + d for d in deps)


POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"

MSGDEFS = {
    POSE_STAMPED: msgdef("std_msgs/Header header\ngeometry_msgs/Pose pose\n", HEADER, TIME, POSE, POINT, QUATERNION),
    TF_MESSAGE: msgdef(
        "geometry_msgs/TransformStamped[] transforms\n",
        "MSG: geometry_msgs/TransformStamped\nstd_msgs/Header header\nstring child_frame_id\n"
        "geometry_msgs/Transform transform\n", HEADER, TIME,
        "MSG: geometry_msgs/Transform\ngeometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
        VECTOR3, QUATERNION),
    OCCUPANCY_GRID: msgdef(
        "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n", HEADER, TIME,
        "MSG: nav_msgs/MapMetaData\nbuiltin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\n"
        "uint32 height\ngeometry_msgs/Pose origin\n", POSE, POINT, QUATERNION),
}

TOPIC_POSE = "/zfloc/pose"
TOPIC_TRUTH = "/zfloc/groundtruth"
TOPIC_TF = "/tf"
TOPIC_FLOORPLAN = "/zfloc/floorplan"
FRAME_MAP, FRAME_ODOM = "map", "odom"


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _header(ns: int, frame_id: str) -> dict:
    return {"stamp": _stamp(ns), "frame_id": frame_id}


def _yaw_quaternion(theta: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(0.5 * theta), "w": math.cos(0.5 * theta)}


def pose_stamped(ns: int, x: float, y: float, theta: float) -> dict:
    return {"header": _header(ns, FRAME_MAP),
            "pose": {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": _yaw_quaternion(float(theta))}}


def map_to_odom(pose, alignment) -> tuple[float, float, float]:
    """(x, y, yaw) of the rigid `map -> odom` transform that maps this frame's odometry-plane
    pose (the alignment's inverse applied to the estimate) onto the estimated pose."""
    x, y, theta = (float(v) for v in pose)
    qx, qy, qth = alignment.inverse().apply_pose(x, y, theta)
    yaw = theta - qth
    c, s = math.cos(yaw), math.sin(yaw)
    return x - (c * qx - s * qy), y - (s * qx + c * qy), yaw


def tf_message(ns: int, x: float, y: float, yaw: float) -> dict:
    return {"transforms": [{
        "header": _header(ns, FRAME_MAP), "child_frame_id": FRAME_ODOM,
        "transform": {"translation": {"x": x, "y": y, "z": 0.0}, "rotation": _yaw_quaternion(yaw)},
    }]}


def occupancy_grid(ns: int, floorplan) -> dict:
    """The floorplan's walls (100) and the rest (0); row 0 of the grid is its lowest y, as
    OccupancyGrid wants (origin = the lower-left corner of cell (0, 0))."""
    occupied = np.asarray(floorplan.occupied, dtype=bool)
    h, w = occupied.shape
    x0, y0 = (float(v) for v in floorplan.origin)
    return {
        "header": _header(ns, FRAME_MAP),
        "info": {"map_load_time": _stamp(ns), "resolution": float(floorplan.resolution), "width": int(w), "height": int(h),
                 "origin": {"position": {"x": x0, "y": y0, "z": 0.0}, "orientation": _yaw_quaternion(0.0)}},
        "data": np.where(occupied, 100, 0).astype(np.int8).ravel().tolist(),
    }


class Ros2Writer:
    """write(stamp, estimate, truth) once per frame (stamp: the trajectory.tum stamp)."""

    def __init__(self, path: str | Path, floorplan):
        from mcap_ros2.writer import Writer

        self.path = Path(path)
        try:
            self._file = open(self.path, "wb")  # noqa: SIM115 - owned until close()
        except OSError as err:
            raise InputError(f"cannot write ROS 2 output {self.path}: {err.strerror or err}") from None
        self._writer = Writer(self._file)
        self._schemas = {name: self._writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        self._floorplan = floorplan
        self.poses = 0

    def _put(self, topic: str, datatype: str, message: dict, ns: int) -> None:
        self._writer.write_message(topic, self._schemas[datatype], message, log_time=ns, publish_time=ns)

    def write(self, stamp: float, estimate, truth=None) -> None:
        ns = int(round(stamp * 1e9))
        if self._floorplan is not None:
            self._put(TOPIC_FLOORPLAN, OCCUPANCY_GRID, occupancy_grid(ns, self._floorplan), ns)
            self._floorplan = None
        pose = estimate.pose
        if pose is not None and np.isfinite(pose).all():
            self._put(TOPIC_POSE, POSE_STAMPED, pose_stamped(ns, *pose), ns)
            self.poses += 1
            if estimate.alignment is not None:
                self._put(TOPIC_TF, TF_MESSAGE, tf_message(ns, *map_to_odom(pose, estimate.alignment)), ns)
        if truth is not None and np.isfinite(truth).all():
            self._put(TOPIC_TRUTH, POSE_STAMPED, pose_stamped(ns, *truth), ns)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
