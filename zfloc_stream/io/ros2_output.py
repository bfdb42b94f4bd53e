"""The estimates as ROS 2 messages (`zfloc-stream run --ros2`): an MCAP file with the ROS 2
profile and CDR messages, written by mcap-ros2-support, which ROS 2 tools (ros2 bag, RViz
through a player, Foxglove) and evo (`evo_ape bag2 ...`, through rosbags) read.

Topics (frames: frame_tree.py, REP 105 `map`, `odom`, `base_link`, as in session.mcap):
- /zfloc/pose          geometry_msgs/PoseWithCovarianceStamped in `map` (as AMCL's
                       /amcl_pose), one per frame with a pose
- /zfloc/groundtruth   geometry_msgs/PoseStamped in `map`, where the frame's truth is known
- /tf                  tf2_msgs/TFMessage `map -> odom` (the localization correction) and
                       `odom -> base_link` (the odometry), with each pose
- /zfloc/floorplan     nav_msgs/OccupancyGrid in `map`, once, with the first frame: 100
                       wall, 0 free, -1 unknown (map_server's values)

The covariance is 6x6 row-major over (x, y, z, roll, pitch, yaw): the estimate's (x, y,
yaw) block where it is known; z, roll and pitch are not estimated and get
UNOBSERVED_VARIANCE (as robot_localization reads an axis it should not fuse; AMCL leaves
them 0, which a filter would take as certainty).

The alignment is a similarity and a tf is rigid: `map -> odom` is exact at each frame's
stamp (frame_tree.py says how a non-unit scale is handled). Stamps are the trajectory.tum
ones (a repeated input stamp moved 1 us on), so evo pairs the topics with the TUM files
and with each other.

The message definitions are the ROS 2 Humble ones (ros2msg text with dependencies).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError
from ..geometry.frame_tree import BASE_LINK, MAP, ODOM, map_to_odom, odom_to_base, yaw_quaternion

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
POSE_WITH_COVARIANCE = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"

MSGDEFS = {
    POSE_STAMPED: msgdef("std_msgs/Header header\ngeometry_msgs/Pose pose\n", HEADER, TIME, POSE, POINT, QUATERNION),
    POSE_WITH_COVARIANCE: msgdef(
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n", HEADER, TIME,
        "MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n", POSE, POINT, QUATERNION),
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
UNOBSERVED_VARIANCE = 1e6  # m^2 / rad^2 of the axes a planar localizer does not estimate
COVARIANCE_AXES = (0, 1, 5)  # x, y, yaw among (x, y, z, roll, pitch, yaw)
FREE, OCCUPIED, UNKNOWN = 0, 100, -1  # OccupancyGrid cell values


def _stamp(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _header(ns: int, frame_id: str) -> dict:
    return {"stamp": _stamp(ns), "frame_id": frame_id}


def _yaw_quaternion(theta: float) -> dict:
    return dict(zip("xyzw", yaw_quaternion(float(theta)), strict=True))


def _pose(x: float, y: float, theta: float) -> dict:
    return {"position": {"x": float(x), "y": float(y), "z": 0.0}, "orientation": _yaw_quaternion(theta)}


def pose_stamped(ns: int, x: float, y: float, theta: float) -> dict:
    return {"header": _header(ns, MAP), "pose": _pose(x, y, theta)}


def covariance_6x6(cov) -> list[float]:
    """The 36 row-major entries over (x, y, z, roll, pitch, yaw) of a planar (x, y, theta)
    covariance, made exactly symmetric (the estimate's is up to rounding); unobserved axes
    (and all three where the estimate has none or a non-finite one) get UNOBSERVED_VARIANCE."""
    out = np.diag(np.full(6, UNOBSERVED_VARIANCE))
    c = None if cov is None else np.asarray(cov, dtype=float)
    if c is not None and c.shape == (3, 3) and np.isfinite(c).all():
        out[np.ix_(COVARIANCE_AXES, COVARIANCE_AXES)] = 0.5 * (c + c.T)
    return out.ravel().tolist()


def pose_with_covariance(ns: int, pose, cov) -> dict:
    return {"header": _header(ns, MAP), "pose": {"pose": _pose(*pose), "covariance": covariance_6x6(cov)}}


def _transform(ns: int, parent: str, child: str, x: float, y: float, yaw: float) -> dict:
    return {"header": _header(ns, parent), "child_frame_id": child,
            "transform": {"translation": {"x": float(x), "y": float(y), "z": 0.0}, "rotation": _yaw_quaternion(yaw)}}


def tf_message(ns: int, pose, alignment) -> dict:
    """map -> odom (the correction) and odom -> base_link (the odometry-plane pose): their
    product is the estimated pose at this stamp."""
    return {"transforms": [_transform(ns, MAP, ODOM, *map_to_odom(pose, alignment)),
                           _transform(ns, ODOM, BASE_LINK, *odom_to_base(pose, alignment))]}


def occupancy_grid(ns: int, floorplan) -> dict:
    """The floorplan's walls (100), free cells (0) and the cells its map marks unknown (-1,
    map_server's grey); row 0 of the grid is its lowest y, as OccupancyGrid wants (origin =
    the lower-left corner of cell (0, 0))."""
    occupied = np.asarray(floorplan.occupied, dtype=bool)
    values = np.where(occupied, OCCUPIED, FREE).astype(np.int8)
    unknown = getattr(floorplan, "unknown", None)
    if unknown is not None:
        values[np.asarray(unknown, dtype=bool) & ~occupied] = UNKNOWN
    h, w = occupied.shape
    x0, y0 = (float(v) for v in floorplan.origin)
    return {
        "header": _header(ns, MAP),
        "info": {"map_load_time": _stamp(ns), "resolution": float(floorplan.resolution), "width": int(w), "height": int(h),
                 "origin": {"position": {"x": x0, "y": y0, "z": 0.0}, "orientation": _yaw_quaternion(0.0)}},
        "data": values.ravel().tolist(),
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
            self._put(TOPIC_POSE, POSE_WITH_COVARIANCE, pose_with_covariance(ns, pose, estimate.covariance), ns)
            self.poses += 1
            if estimate.alignment is not None:
                self._put(TOPIC_TF, TF_MESSAGE, tf_message(ns, pose, estimate.alignment), ns)
        if truth is not None and np.isfinite(truth).all():
            self._put(TOPIC_TRUTH, POSE_STAMPED, pose_stamped(ns, *truth), ns)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
