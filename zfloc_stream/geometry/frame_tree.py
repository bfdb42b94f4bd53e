"""The coordinate frames the outputs name (ROS REP 105) and the transforms between them,
shared by the session log (foxglove.FrameTransforms on /tf) and the ROS 2 output
(tf2_msgs/TFMessage on /tf):

    map -> odom -> base_link -> laser | camera

- `map`: the floorplan (metres, x right, y up, origin as map_server's). Logs written
  before this naming called it `floorplan` (LEGACY_MAP); readers take both.
- `odom`: the localizer's odometry plane, the frame the alignment maps from and the BEV
  lives in: the logged odometry levelled to gravity (cameras) and corrected by scan
  matching (lasers), in odometry units.
- `base_link`: the localized sensor's footprint, its planar pose (x, y, heading) in
  `odom`. zfloc localizes the sensor, not a robot body: on a robot whose sensor sits off
  its base this is not the robot's own base_link (merge with care).
- `laser` / `camera`: the sensor, where scans and images are drawn; base_link -> sensor
  is the logged odometry pose's height and tilt (identity for a level 2D laser).

map -> odom is the localization correction. The alignment is a similarity x' = s R x + t
and a transform is rigid, so map -> odom is the rigid transform that puts this frame's
odometry-plane pose exactly on its estimated pose (what AMCL publishes), recomputed every
frame: at s = 1 (lasers) it is the alignment itself and stays put between corrections; at
s != 1 (a camera's free scale) it also slides with the odometry, and a BEV point d metres
from the sensor is drawn |s - 1| d away from where the alignment puts it.
"""

from __future__ import annotations

import math

import numpy as np

MAP, ODOM, BASE_LINK, LASER, CAMERA = "map", "odom", "base_link", "laser", "camera"
LEGACY_MAP = "floorplan"  # the map frame's name in session logs before REP 105 naming
HEADING_COLUMN = {"x": 0, "z": 2}  # the sensor axis that is its heading: laser x, camera optical z


def odom_to_base(pose, alignment) -> tuple[float, float, float]:
    """(x, y, yaw) of base_link in odom: the odometry-plane pose the alignment maps onto
    the estimated pose (the alignment's inverse applied to it)."""
    return tuple(float(v) for v in alignment.inverse().apply_pose(*(float(p) for p in pose)))


def map_to_odom(pose, alignment) -> tuple[float, float, float]:
    """(x, y, yaw) of the rigid map -> odom transform that carries this frame's
    odometry-plane pose onto its estimated pose."""
    x, y, theta = (float(v) for v in pose)
    qx, qy, qth = odom_to_base(pose, alignment)
    yaw = theta - qth
    c, s = math.cos(yaw), math.sin(yaw)
    return x - (c * qx - s * qy), y - (s * qx + c * qy), yaw


def planar_matrix(x: float, y: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:2, 3] = x, y
    return T


def base_to_sensor(T_odom_sensor: np.ndarray, heading_axis: str) -> np.ndarray:
    """base_link -> sensor (4x4) from a logged sensor pose: the pose relative to its own
    level footprint (position on z = 0, heading axis projected on the plane), i.e. its
    height, tilt and roll; the identity for a level 2D laser at z = 0."""
    T = np.asarray(T_odom_sensor, dtype=float)
    h = T[:3, HEADING_COLUMN[heading_axis]]
    yaw = math.atan2(h[1], h[0]) if math.hypot(h[0], h[1]) > 1e-9 else 0.0  # looking straight up/down: any yaw
    return np.linalg.inv(planar_matrix(T[0, 3], T[1, 3], yaw)) @ T


def yaw_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of a rotation by yaw about z."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)
