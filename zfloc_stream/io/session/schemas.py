"""Message <-> numpy conversion for the session topics (docs/inputs.md table), one namespace
(`from . import schemas as S`) over topics.py (names, stamps), sensor_messages.py (images,
calibration, poses, scans, grids) and status_messages.py (/zfloc/status and the pose outputs).

Every function here is pure: no file, no clock. Decoders validate what they read and
raise SessionLogError naming the field that is wrong; the reader adds the file and topic.

Pose conventions (recorded in channel metadata as `heading_axis`, see HEADING_AXIS_KEY):
- /odometry and /groundtruth/pose hold the *sensor* pose. For a camera that is its OpenCV
  axes (x right, y down, z forward), so its heading is the optical (z) axis projected on
  the plane; for a laser the sensor x axis is the heading. Files from other tools follow
  the same rule (intel-camera-30 does).
- /zfloc/pose and /zfloc/hypotheses are planar poses: a yaw about z, heading = x axis,
  so Foxglove draws their arrows along the heading.
"""

from __future__ import annotations

# the message classes of the session topics (foxglove schemas), named here as S.RawImage ...
from foxglove_schemas_protobuf.CameraCalibration_pb2 import CameraCalibration  # noqa: F401
from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage  # noqa: F401
from foxglove_schemas_protobuf.Grid_pb2 import Grid  # noqa: F401
from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan  # noqa: F401
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField  # noqa: F401
from foxglove_schemas_protobuf.Pose_pb2 import Pose  # noqa: F401
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame  # noqa: F401
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame  # noqa: F401
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage  # noqa: F401
from google.protobuf.timestamp_pb2 import Timestamp  # noqa: F401

# image rows, depth encodings and quaternions: shared with the ROS 2 bag reader (datasets/ros2.py)
from ..messages import DEPTH_ENCODINGS, depth_from_msg, image_rows, matrix_from_quaternion, quaternion_from_matrix  # noqa: F401
from .sensor_messages import (  # noqa: F401
    depth_to_msg, labels_to_msg, labels_from_msg, image_to_msg, image_from_msg, calibration_to_msg, distortion_from_msg,
    calibration_from_msg, pose_to_msg, matrix_from_pose, planar_pose_to_pose, planar_pose_from_pose, scan_to_msg,
    scan_from_msg, BevGrid, grid_to_msg, occupancy_grid_msg, grid_from_msg,
)
from .status_messages import (  # noqa: F401
    STATUS_SCHEMA_NAME, STATUS_JSON_SCHEMA, STATUS_JSON_SCHEMA_BYTES, MEASURED_STATUS_KEYS, status_to_json,
    encode_status, decode_status, estimate_from_status, hypotheses_to_msg, estimate_pose_to_msg,
)
from .topics import (  # noqa: F401
    TOPIC_DEPTH, TOPIC_LABELS, TOPIC_CALIBRATION, TOPIC_IMAGE, TOPIC_SCAN, TOPIC_ODOMETRY, TOPIC_GROUND_TRUTH,
    TOPIC_POSE, TOPIC_HYPOTHESES, TOPIC_BEV, TOPIC_STATUS, TOPIC_FLOORPLAN, TOPIC_TF, INPUT_TOPICS, OUTPUT_TOPICS,
    FRAME_ODOM, FRAME_FLOORPLAN, FRAME_MAP, FRAME_CAMERA, FRAME_LASER, HEADING_AXIS_KEY, RANGE_MIN_KEY, RANGE_MAX_KEY,
    METADATA_SETTINGS, METADATA_SESSION, METADATA_FLOORPLAN_SETTINGS, METADATA_CHECKSUMS, METADATA_ENVIRONMENT, CRC_KEY,
    ATTACHMENT_FLOORPLAN_PREFIX, SESSION_FORMAT, LABEL_ENCODINGS, COLOR_ENCODINGS, COMPRESSED_FORMATS, crc32_hex,
    MAX_NS, seconds_to_ns, ns_to_seconds, to_stamp, from_stamp,
)
