"""Writes small ROS 2 bags (rosbag2 MCAP, CDR) with mcap-ros2-support's writer, the way a
robot records them: sensor and odometry at their own rates and stamps, /tf_static mounts.

The message definitions are the ROS 2 Humble ones (ros2msg text with dependencies), so the
files decode with any ROS 2 MCAP reader.
"""

from __future__ import annotations

import numpy as np
from mcap_ros2.writer import Writer

from zfloc_stream.geometry.pose_interpolation import interpolate_pose
from zfloc_stream.io.messages import quaternion_from_matrix

# the pieces the package's own ROS 2 output uses (zfloc_stream/io/ros2_output.py)
from zfloc_stream.io.ros2_output import HEADER, POINT, POSE, QUATERNION, TIME, VECTOR3
from zfloc_stream.io.ros2_output import MSGDEFS as OUTPUT_MSGDEFS
from zfloc_stream.io.ros2_output import msgdef as _msgdef

MSGDEFS = {
    "sensor_msgs/msg/LaserScan": _msgdef(
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n"
        "float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n"
        "float32[] ranges\nfloat32[] intensities\n", HEADER, TIME),
    "nav_msgs/msg/Odometry": _msgdef(
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n", HEADER, TIME,
        "MSG: geometry_msgs/PoseWithCovariance\ngeometry_msgs/Pose pose\nfloat64[36] covariance\n",
        POSE, POINT, QUATERNION,
        "MSG: geometry_msgs/TwistWithCovariance\ngeometry_msgs/Twist twist\nfloat64[36] covariance\n",
        "MSG: geometry_msgs/Twist\ngeometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n", VECTOR3),
    "tf2_msgs/msg/TFMessage": OUTPUT_MSGDEFS["tf2_msgs/msg/TFMessage"],
    "sensor_msgs/msg/Image": _msgdef(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring encoding\nuint8 is_bigendian\n"
        "uint32 step\nuint8[] data\n", HEADER, TIME),
    "sensor_msgs/msg/CameraInfo": _msgdef(
        "std_msgs/Header header\nuint32 height\nuint32 width\nstring distortion_model\nfloat64[] d\n"
        "float64[9] k\nfloat64[9] r\nfloat64[12] p\nuint32 binning_x\nuint32 binning_y\n"
        "sensor_msgs/RegionOfInterest roi\n", HEADER, TIME,
        "MSG: sensor_msgs/RegionOfInterest\nuint32 x_offset\nuint32 y_offset\nuint32 height\nuint32 width\nbool do_rectify\n"),
}


def header(ns: int, frame_id: str) -> dict:
    return {"stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}, "frame_id": frame_id}


def _xyz(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


def _quat(R) -> dict:
    x, y, z, w = quaternion_from_matrix(R)
    return {"x": x, "y": y, "z": z, "w": w}


def transform(ns: int, parent: str, child: str, T: np.ndarray) -> dict:
    return {"header": header(ns, parent), "child_frame_id": child,
            "transform": {"translation": _xyz(T[:3, 3]), "rotation": _quat(T[:3, :3])}}


def odometry(ns: int, T: np.ndarray, parent: str = "odom", child: str = "base_link") -> dict:
    zero = {"x": 0.0, "y": 0.0, "z": 0.0}
    return {"header": header(ns, parent), "child_frame_id": child,
            "pose": {"pose": {"position": _xyz(T[:3, 3]), "orientation": _quat(T[:3, :3])}, "covariance": [0.0] * 36},
            "twist": {"twist": {"linear": zero, "angular": zero}, "covariance": [0.0] * 36}}


def mount(x: float, y: float, z: float, yaw: float = 0.0, optical: bool = False) -> np.ndarray:
    """T_base_sensor of a sensor at (x, y, z) turned by yaw; optical: camera axes (z forward,
    x right, y down), as ROS *_optical_frame links are."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    if optical:
        T[:3, :3] = T[:3, :3] @ np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])
    T[:3, 3] = (x, y, z)
    return T


def base_poses_at(stamps_ns, frame_stamps_ns, T_odom_sensor, T_base_sensor) -> list[np.ndarray]:
    """Base poses at odometry stamps, moving between the frames' base poses (held at the ends)."""
    base = [T @ np.linalg.inv(T_base_sensor) for T in T_odom_sensor]
    out = []
    for t in stamps_ns:
        k = int(np.searchsorted(frame_stamps_ns, t, side="right")) - 1
        if k < 0:
            out.append(base[0])
        elif k >= len(base) - 1:
            out.append(base[-1])
        else:
            a = (t - frame_stamps_ns[k]) / (frame_stamps_ns[k + 1] - frame_stamps_ns[k])
            out.append(interpolate_pose(base[k], base[k + 1], a))
    return out


class BagWriter:
    """mcap_ros2 Writer with the schemas above registered on first use."""

    def __init__(self, path):
        self._file = open(path, "wb")
        self.writer = Writer(self._file)
        self.schemas = {}

    def write(self, topic: str, datatype: str, msg: dict, ns: int) -> None:
        if datatype not in self.schemas:
            self.schemas[datatype] = self.writer.register_msgdef(datatype, MSGDEFS[datatype])
        self.writer.write_message(topic, self.schemas[datatype], msg, log_time=ns, publish_time=ns)

    def close(self) -> None:
        self.writer.finish()
        self._file.close()


def write_sensor_bag(path, frames, T_base_sensor, kind: str = "scan", sensor_hz: float = 15.0, odom_hz: float = 50.0,
                     t0: float = 100.0, odom_offset: float = 0.007, swap_odometry: int | None = None,
                     odom_via_tf: bool = False, sensor_frame: str | None = None, depth_mm: bool = True,
                     scan_topic: str = "/scan", depth_scale: float = 1.0, distortion=None) -> list[int]:
    """A bag of the frames (LaserFrame for kind='scan', CameraFrame for 'depth') at sensor_hz,
    odometry of base_link at odom_hz on its own stamps (offset from the sensor's), a
    /tf_static base_link -> sensor mount. swap_odometry=j writes odometry messages j and
    j+1 in swapped order (out of order in the file). depth_scale multiplies the 32FC1 depth
    (1000: millimetres); distortion: CameraInfo's plumb_bob d. Returns the frame stamps (ns)."""
    sensor_frame = sensor_frame or ("laser" if kind == "scan" else "camera_depth_optical_frame")
    n = len(frames)
    frame_ns = np.array([int(round((t0 + k / sensor_hz) * 1e9)) for k in range(n)], dtype=np.int64)
    span = (n - 1) / sensor_hz
    n_odom = int(np.ceil((span + 0.2) * odom_hz)) + 1
    odom_ns = np.array([int(round((t0 - 0.1 + odom_offset + j / odom_hz) * 1e9)) for j in range(n_odom)], dtype=np.int64)
    poses = [f.T_odom_sensor if kind == "scan" else f.T_odom_cam for f in frames]
    base = base_poses_at(odom_ns, frame_ns, poses, T_base_sensor)
    bag = BagWriter(path)
    static = {"transforms": [transform(int(frame_ns[0]), "base_link", sensor_frame, T_base_sensor)]}
    bag.write("/tf_static", "tf2_msgs/msg/TFMessage", static, int(frame_ns[0]) - 10**9)
    if kind == "depth":
        K = frames[0].K
        h, w = frames[0].depth.shape
        info = {"header": header(int(frame_ns[0]), sensor_frame), "height": h, "width": w, "distortion_model": "plumb_bob",
                "d": [0.0] * 5 if distortion is None else [float(v) for v in distortion], "k": K.ravel().tolist(), "r": np.eye(3).ravel().tolist(),
                "p": np.hstack([K, np.zeros((3, 1))]).ravel().tolist(), "binning_x": 0, "binning_y": 0,
                "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False}}
        bag.write("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo", info, int(frame_ns[0]) - 10**9)
    order = list(range(n_odom))
    if swap_odometry is not None:
        order[swap_odometry], order[swap_odometry + 1] = order[swap_odometry + 1], order[swap_odometry]
    events = [(int(odom_ns[j]), "odom", j) for j in range(n_odom)] + [(int(frame_ns[k]), kind, k) for k in range(n)]
    events.sort(key=lambda e: (e[0], e[1]))
    odom_iter = iter(order)
    for ns, what, k in events:
        if what == "odom":
            j = next(odom_iter)  # the swapped pair goes out in swapped order
            if odom_via_tf:
                bag.write("/tf", "tf2_msgs/msg/TFMessage", {"transforms": [transform(int(odom_ns[j]), "odom", "base_link", base[j])]}, ns)
            else:
                bag.write("/odom", "nav_msgs/msg/Odometry", odometry(int(odom_ns[j]), base[j]), ns)
        elif what == "scan":
            f = frames[k]
            r = np.where(np.isfinite(f.ranges), f.ranges, np.inf).astype(np.float32)
            msg = {"header": header(ns, sensor_frame), "angle_min": f.angle_min,
                   "angle_max": f.angle_min + f.angle_increment * (len(r) - 1), "angle_increment": f.angle_increment,
                   "time_increment": 0.0, "scan_time": 1.0 / sensor_hz, "range_min": f.range_min, "range_max": f.range_max,
                   "ranges": r.tolist(), "intensities": []}
            bag.write(scan_topic, "sensor_msgs/msg/LaserScan", msg, ns)
        else:
            d = np.nan_to_num(frames[k].depth, nan=0.0)
            if depth_mm:
                data, enc, item = np.round(d * 1000.0).astype("<u2").tobytes(), "16UC1", 2
            else:
                data, enc, item = (d * depth_scale).astype("<f4").tobytes(), "32FC1", 4
            h, w = d.shape
            msg = {"header": header(ns, sensor_frame), "height": h, "width": w, "encoding": enc, "is_bigendian": 0,
                   "step": w * item, "data": data}
            bag.write("/camera/depth/image_rect_raw", "sensor_msgs/msg/Image", msg, ns)
    bag.close()
    return frame_ns.tolist()
