"""The localizer's outputs as session messages: the /zfloc/status JSON (its schema,
encoding and decoding back to an Estimate) and the pose and hypotheses messages."""

from __future__ import annotations

import json
import math

import numpy as np
from foxglove_schemas_protobuf.PoseInFrame_pb2 import PoseInFrame
from foxglove_schemas_protobuf.PosesInFrame_pb2 import PosesInFrame

from ...errors import SessionLogError
from ...estimate import STATUSES, Alternative, Estimate
from ...geometry.sim2 import Sim2
from .sensor_messages import planar_pose_to_pose
from .topics import FRAME_MAP, to_stamp


# --- status (JSON) ----------------------------------------------------------------------------
STATUS_SCHEMA_NAME = "zfloc.Status"
_NUM = {"type": ["number", "null"]}
_POSE = {"type": ["array", "null"], "items": {"type": "number"}, "minItems": 3, "maxItems": 3}
_ALIGNMENT = {
    "type": ["object", "null"],
    "properties": {"s": {"type": "number"}, "theta": {"type": "number"}, "tx": {"type": "number"}, "ty": {"type": "number"}},
}
STATUS_JSON_SCHEMA = {
    "$schema": "http://json-schema.org/draft-07/schema#",
    "title": STATUS_SCHEMA_NAME,
    "description": "Per-frame localizer state. Floats are exact (repr); NaN is written as null.",
    "type": "object",
    "properties": {
        "frame": {"type": "integer"},
        "timestamp": {"type": "number"},
        "status": {"type": "string", "enum": list(STATUSES)},
        "score": _NUM,
        "scale": _NUM,
        "pose": _POSE,
        "covariance": {"type": ["array", "null"], "items": _NUM, "minItems": 9, "maxItems": 9},
        "alignment": _ALIGNMENT,
        "weights": {"type": "array", "items": {"type": "number"}},
        "hypotheses": {
            "type": "array",
            "items": {
                "type": "object",
                "properties": {"weight": _NUM, "score": _NUM, "pose": _POSE, "alignment": _ALIGNMENT},
            },
        },
        "skipped": {"type": ["string", "null"]},
        "round_skipped": {"type": "string"},
        "timings": {"type": "object", "additionalProperties": {"type": "number"}},
        "confidence": {**_NUM, "minimum": 0, "maximum": 1},
    },
    "required": ["frame", "timestamp", "status"],
}
STATUS_JSON_SCHEMA_BYTES = json.dumps(STATUS_JSON_SCHEMA).encode()
MEASURED_STATUS_KEYS = ("timings",)  # wall-clock measurements: never compared by --check


def _num(v) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _nums(a) -> list | None:
    return None if a is None else [_num(v) for v in np.asarray(a, dtype=float).ravel()]


def _alignment_json(a: Sim2 | None) -> dict | None:
    return None if a is None else {"s": _num(a.s), "theta": _num(a.theta), "tx": _num(a.t[0]), "ty": _num(a.t[1])}


def status_to_json(est: Estimate) -> dict:
    status = {
        "frame": int(est.frame),
        "timestamp": _num(est.timestamp),
        "status": est.status,
        "score": _num(est.score),
        "scale": _num(est.scale),
        "pose": _nums(est.pose),
        "covariance": _nums(est.covariance),
        "alignment": _alignment_json(est.alignment),
        "weights": [_num(a.weight) for a in est.alternatives],
        "hypotheses": [
            {"weight": _num(a.weight), "score": _num(a.score), "pose": _nums(a.pose), "alignment": _alignment_json(a.alignment)}
            for a in est.alternatives
        ],
        "skipped": est.skipped,
        "timings": {str(k): float(v) for k, v in est.timings.items()},
        "confidence": _num(est.confidence),  # appended (issue 26); older files lack it
    }
    if est.round_skipped is not None:  # only where a due round did not run (older files lack the key)
        status["round_skipped"] = est.round_skipped
    return status


def encode_status(status: dict) -> bytes:
    return json.dumps(status, allow_nan=False, separators=(",", ":")).encode()


def _reject_constant(name: str):
    raise SessionLogError(f"status JSON holds {name}, which JSON does not allow (NaN is written as null)")


def decode_status(data: bytes) -> dict:
    """Parse and validate a /zfloc/status payload (it must describe an Estimate)."""
    try:
        status = json.loads(data, parse_constant=_reject_constant)
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as err:
        raise SessionLogError(f"status is not valid JSON ({type(err).__name__})") from None
    if not isinstance(status, dict) or not {"frame", "timestamp", "status"} <= status.keys():
        raise SessionLogError("status JSON lacks frame, timestamp or status")
    estimate_from_status(status)  # raises on a malformed field
    return status


def _f(v) -> float:
    return float("nan") if v is None else float(v)


def _sim2(d: dict | None) -> Sim2 | None:
    return None if d is None else Sim2(_f(d["s"]), _f(d["theta"]), (_f(d["tx"]), _f(d["ty"])))


def estimate_from_status(status: dict) -> Estimate:
    """The Estimate a status message describes (for consumers of logged sessions)."""
    if status.get("status") not in STATUSES:
        raise SessionLogError(f"status JSON: unknown status {status.get('status')!r}")
    try:
        pose = None if status.get("pose") is None else np.array([_f(v) for v in status["pose"]])
        cov = None if status.get("covariance") is None else np.array([_f(v) for v in status["covariance"]]).reshape(3, 3)
        alts = tuple(
            Alternative(_sim2(h["alignment"]), np.array([_f(v) for v in h["pose"]]), _f(h["weight"]), _f(h["score"]))
            for h in status.get("hypotheses", [])
        )
        return Estimate(
            int(status["frame"]),
            _f(status["timestamp"]),
            str(status["status"]),
            pose,
            cov,
            _sim2(status.get("alignment")),
            _f(status.get("score")),
            alts,
            {str(k): float(v) for k, v in (status.get("timings") or {}).items()},
            status.get("skipped"),
            status.get("round_skipped"),
            _f(status.get("confidence")),
        )
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as err:
        raise SessionLogError(f"status JSON is malformed ({type(err).__name__}: {err})") from None


def hypotheses_to_msg(est: Estimate, ns: int, frame_id: str = FRAME_MAP) -> PosesInFrame:
    msg = PosesInFrame(timestamp=to_stamp(ns), frame_id=frame_id)
    for alt in est.alternatives:
        msg.poses.append(planar_pose_to_pose(alt.pose, "x"))
    return msg


def estimate_pose_to_msg(est: Estimate, ns: int, frame_id: str = FRAME_MAP) -> PoseInFrame:
    return PoseInFrame(timestamp=to_stamp(ns), frame_id=frame_id, pose=planar_pose_to_pose(est.pose, "x"))
