"""Message fields that session logs (Foxglove protobuf) and ROS 2 bags (sensor_msgs) share:
image rows that may be padded, the depth encodings, quaternions <-> rotation matrices.

Pure functions of a message's fields (width, height, step, encoding, data; x, y, z, w), so the
session schemas and the ROS 2 bag reader decode them the same way without importing each
other. Errors are SessionLogError naming the field that is wrong.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SessionLogError
from ..frames import MAX_MEDIAN_DEPTH_M, median_above, median_depth

DEPTH_ENCODINGS = ("32FC1", "16UC1")  # 16UC1: millimetres (ROS convention)


def image_rows(msg, dtype: str) -> np.ndarray:
    """HxW array from an image message (RawImage, sensor_msgs/Image) whose rows may be padded (step >= width * bytes)."""
    item = np.dtype(dtype).itemsize
    w, h, step = int(msg.width), int(msg.height), int(msg.step)
    if w <= 0 or h <= 0:
        raise SessionLogError(f"{msg.encoding} image has size {w}x{h}")
    if step < w * item:
        raise SessionLogError(f"{msg.encoding} image step {step} is shorter than a row ({w} x {item} bytes)")
    if len(msg.data) < step * (h - 1) + w * item:
        raise SessionLogError(f"{msg.encoding} image data holds {len(msg.data)} bytes, {w}x{h} with step {step} needs more")
    # a strided view over the (possibly row-padded) buffer, copied into a packed array
    return np.ndarray((h, w), dtype=dtype, buffer=msg.data, strides=(step, item)).copy()


def depth_from_msg(msg) -> np.ndarray:
    """Metres, float32. 32FC1 as is; 16UC1 read as millimetres (0 stays 'no reading')."""
    if msg.encoding == "32FC1":
        return image_rows(msg, "<f4").astype(np.float32)
    if msg.encoding == "16UC1":
        w, h, step = int(msg.width), int(msg.height), int(msg.step)
        if w >= 8 and h > 0 and (step == 4 * w or (step == 2 * w and len(msg.data) == 4 * w * h)):
            raise SessionLogError(f"depth is declared 16UC1 but holds 4 bytes per pixel ({w}x{h}, step {step}, "
                                  f"{len(msg.data)} bytes): float32 data with the wrong encoding? (expected 32FC1)")
        return (image_rows(msg, "<u2").astype(np.float32) / np.float32(1000.0)).astype(np.float32)
    raise SessionLogError(f"depth encoding '{msg.encoding}' is not supported (expected one of {', '.join(DEPTH_ENCODINGS)})")


# Float depth in millimetres (some tools write it so) read as metres puts every wall
# kilometres away and every frame stays 'initializing'. An indoor depth camera's median
# reading is never above MAX_MEDIAN_DEPTH_M (frames.py); millimetres put it at 250-50,000.
MM_MEDIAN_RANGE = (250.0, 50_000.0)
MM_NOTE = "depth holds millimetres"  # the start of the note: a reader warns once per read


def depth_in_metres(msg) -> tuple[np.ndarray, str | None]:
    """depth_from_msg, with 32FC1 depth whose median reading is a plausible indoor distance
    in millimetres (and not in metres) converted to metres; the note says so, else None.
    Depth implausible either way is left for CameraFrame to refuse."""
    d = depth_from_msg(msg)
    if msg.encoding != "32FC1":
        return d, None
    if not median_above(d, MAX_MEDIAN_DEPTH_M):  # (a comparison: the median itself costs ms per frame)
        return d, None
    median = median_depth(d)
    if MM_MEDIAN_RANGE[0] <= median <= MM_MEDIAN_RANGE[1]:
        note = (f"{MM_NOTE}, not metres (median reading {median:.0f} 'm', above the {MAX_MEDIAN_DEPTH_M:.0f} m "
                "an indoor camera sees): converted to metres")
        return (d.astype(np.float64) * 1e-3).astype(np.float32), note
    return d, None


# --- poses --------------------------------------------------------------------------------
def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """(x, y, z, w) with w >= 0, from a rotation matrix (Shepperd's branch choice)."""
    R = np.asarray(R, dtype=float)
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0:
        s = 2.0 * math.sqrt(1.0 + tr)
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s, (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s, (R[0, 2] - R[2, 0]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s, (R[1, 0] - R[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def matrix_from_quaternion(q) -> np.ndarray:
    """Rotation matrix of (x, y, z, w); normalises first (other writers round)."""
    q = np.asarray(q, dtype=float)
    n = float(np.linalg.norm(q))
    if not np.isfinite(q).all() or n < 1e-6:
        raise SessionLogError(f"orientation quaternion {q.tolist()} is not a rotation (zero or not finite)")
    x, y, z, w = q / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
