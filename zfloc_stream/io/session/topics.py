"""The session file's public names (docs/inputs.md table): topics, frame ids, channel
metadata keys, metadata records and the floorplan attachment, the encodings read; and its
time stamps, int64 nanoseconds."""

from __future__ import annotations

import math
import zlib

from google.protobuf.timestamp_pb2 import Timestamp

from ...errors import SessionLogError
from ...geometry import frame_tree


# --- topics and frame ids (public contract) ---------------------------------------------
TOPIC_DEPTH = "/camera/depth"
TOPIC_LABELS = "/camera/labels"
TOPIC_CALIBRATION = "/camera/calibration"
TOPIC_IMAGE = "/camera/image"  # colour image: RawImage rgb8/bgr8 or CompressedImage jpeg/png
TOPIC_SCAN = "/scan"
TOPIC_ODOMETRY = "/odometry"
TOPIC_GROUND_TRUTH = "/groundtruth/pose"
TOPIC_POSE = "/zfloc/pose"
TOPIC_HYPOTHESES = "/zfloc/hypotheses"
TOPIC_BEV = "/zfloc/bev"
TOPIC_STATUS = "/zfloc/status"
TOPIC_FLOORPLAN = "/zfloc/floorplan"  # Grid, once, for display (the attachment is the source of truth)
TOPIC_TF = "/tf"  # FrameTransforms map -> odom -> base_link -> sensor with each pose (display; not read back)
INPUT_TOPICS = (TOPIC_CALIBRATION, TOPIC_IMAGE, TOPIC_DEPTH, TOPIC_LABELS, TOPIC_SCAN, TOPIC_ODOMETRY, TOPIC_GROUND_TRUTH)
OUTPUT_TOPICS = (TOPIC_POSE, TOPIC_HYPOTHESES, TOPIC_BEV, TOPIC_STATUS)

# REP 105 names (frame_tree.py); logs before them named the map frame `floorplan` (LEGACY_MAP)
FRAME_ODOM = frame_tree.ODOM
FRAME_FLOORPLAN = FRAME_MAP = frame_tree.MAP
FRAME_CAMERA = frame_tree.CAMERA
FRAME_LASER = frame_tree.LASER

HEADING_AXIS_KEY = "heading_axis"  # channel metadata: which sensor axis is the heading
RANGE_MIN_KEY = "range_min"  # /scan channel metadata (foxglove.LaserScan has no such field)
RANGE_MAX_KEY = "range_max"

# Metadata record names and attachment prefix inside a session file
METADATA_SETTINGS = "zfloc/settings"  # {"yaml": dump_settings(...)}
METADATA_SESSION = "zfloc/session"  # {"format": ..., "sensor": ..., user keys}
METADATA_FLOORPLAN_SETTINGS = "zfloc/floorplan_settings"  # {"yaml", "crc32"} where they differ
METADATA_CHECKSUMS = "zfloc/checksums"  # {attachment name: crc32 hex}
METADATA_ENVIRONMENT = "zfloc/environment"  # where it was recorded: versions, BLAS, SIMD, CPU (environment.py)
CRC_KEY = "crc32"  # in METADATA_SETTINGS: crc32 hex of the YAML text
ATTACHMENT_FLOORPLAN_PREFIX = "floorplan/"
SESSION_FORMAT = "zfloc-session/1"

LABEL_ENCODINGS = ("mono8", "8UC1")
COLOR_ENCODINGS = ("rgb8", "bgr8")  # RawImage on /camera/image
COMPRESSED_FORMATS = ("jpeg", "jpg", "png")  # CompressedImage on /camera/image


def crc32_hex(data: bytes) -> str:
    return f"{zlib.crc32(data):08x}"


# --- time -----------------------------------------------------------------------------------
MAX_NS = 1 << 63  # stamps are int64 ns (numpy arrays, the year 2262); MCAP's own log times go to 2^64


def seconds_to_ns(t: float) -> int:
    if not math.isfinite(t) or t < 0 or t * 1e9 >= MAX_NS:
        raise SessionLogError(f"timestamp {t} cannot be logged: session times are finite, non-negative and before 2^63 ns (the year 2262)")
    return int(round(t * 1e9))


def ns_to_seconds(ns: int) -> float:
    """The one ns -> seconds conversion: live runs and replays both see this value."""
    return ns / 1e9


def to_stamp(ns: int) -> Timestamp:
    return Timestamp(seconds=ns // 1_000_000_000, nanos=ns % 1_000_000_000)


def from_stamp(ts: Timestamp) -> int:
    return int(ts.seconds) * 1_000_000_000 + int(ts.nanos)
