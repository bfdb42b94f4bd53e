"""Message <-> numpy conversions of the session topics."""

import json

import numpy as np
import pytest
from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
from benchmarks.inputs.session_frames import rotation
from session_helpers import fake_estimate

from zfloc_stream.errors import SessionLogError
from zfloc_stream.io.session import schemas as S


def test_time_conversions_round_trip():
    for ns in (0, 1, 999_999_999, 1_234_430_000_000, 1_700_000_000_123_456_789):
        assert S.from_stamp(S.to_stamp(ns)) == ns
    assert S.seconds_to_ns(1.25) == 1_250_000_000
    assert S.seconds_to_ns(S.ns_to_seconds(123_456_789)) == 123_456_789
    with pytest.raises(SessionLogError, match="non-negative"):
        S.seconds_to_ns(-1.0)
    with pytest.raises(SessionLogError):
        S.seconds_to_ns(float("nan"))


def test_depth_is_lossless_including_nan_and_zero():
    rng = np.random.default_rng(0)
    d = rng.uniform(0, 10, (7, 5)).astype(np.float32)
    d[0, 0], d[1, 1] = 0.0, np.nan
    msg = S.depth_to_msg(d, 5)
    assert (msg.encoding, msg.step, msg.width, msg.height) == ("32FC1", 20, 5, 7)
    back = S.depth_from_msg(RawImage.FromString(msg.SerializeToString()))
    assert back.dtype == np.float32 and np.array_equal(back, d, equal_nan=True)


def test_padded_rows_and_16uc1_millimetres():
    d = np.arange(12, dtype="<u2").reshape(3, 4) * 250
    rows = b"".join(r.tobytes() + b"\xff" * 3 for r in d)  # step = 8 + 3 padding bytes
    msg = RawImage(width=4, height=3, encoding="16UC1", step=11, data=rows[:-3])  # last row unpadded
    out = S.depth_from_msg(msg)
    assert out.dtype == np.float32 and np.allclose(out, d / 1000.0)
    lab = RawImage(width=2, height=2, encoding="mono8", step=3, data=bytes([1, 2, 9, 3, 4]))
    assert S.labels_from_msg(lab).tolist() == [[1, 2], [3, 4]]


@pytest.mark.parametrize(
    "msg, what",
    [
        (RawImage(width=4, height=3, encoding="32FC1", step=16, data=b"\0" * 40), "needs more"),
        (RawImage(width=4, height=3, encoding="32FC1", step=8, data=b"\0" * 48), "shorter than a row"),
        (RawImage(width=0, height=3, encoding="32FC1", step=0, data=b""), "size"),
        (RawImage(width=2, height=2, encoding="rgb8", step=6, data=b"\0" * 12), "not supported"),
    ],
)
def test_bad_images_name_the_fault(msg, what):
    with pytest.raises(SessionLogError, match=what):
        S.depth_from_msg(msg)


def test_pose_round_trip_and_quaternion_sign():
    rng = np.random.default_rng(1)
    for _ in range(200):
        T = np.eye(4)
        T[:3, :3] = rotation(rng)
        T[:3, 3] = rng.normal(size=3)
        msg = S.pose_to_msg(T, 1, "odom")
        assert msg.pose.orientation.w >= 0
        assert np.abs(S.matrix_from_pose(msg.pose) - T).max() < 1e-12
    # the branches of the matrix -> quaternion conversion (trace <= 0 cases)
    for R in (np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])):
        q = S.quaternion_from_matrix(R)
        assert np.abs(S.matrix_from_quaternion(q) - R).max() < 1e-12
    with pytest.raises(SessionLogError, match="not a rotation"):
        S.matrix_from_quaternion([0, 0, 0, 0])


@pytest.mark.parametrize("axis", ["x", "z"])
def test_planar_pose_heading_axis(axis):
    for theta in np.linspace(-3.1, 3.1, 13):
        pose = S.planar_pose_to_pose((1.5, -2.0, theta), axis)
        x, y, th = S.planar_pose_from_pose(pose, axis)
        assert (x, y) == (1.5, -2.0) and abs(th - theta) < 1e-12
    # camera convention: the optical (z) axis is the heading, image y points down
    R = S.matrix_from_pose(S.planar_pose_to_pose((0, 0, 0.0), "z"))[:3, :3]
    assert np.allclose(R[:, 2], [1, 0, 0]) and np.allclose(R[:, 1], [0, 0, -1])


def test_scan_and_grid_round_trip():
    r = np.array([1.0, np.inf, 2.5, np.nan, 0.3])
    msg = S.scan_to_msg(r, -1.0, 0.5, 7)
    ranges, amin, inc = S.scan_from_msg(msg)
    assert np.array_equal(ranges, r, equal_nan=True) and amin == -1.0 and abs(inc - 0.5) < 1e-15
    msg.pose.position.x = 0.2
    with pytest.raises(SessionLogError, match="identity"):
        S.scan_from_msg(msg)
    grid = S.BevGrid(np.arange(6, dtype=np.float32).reshape(2, 3), np.array([-1.0, 2.0]), 0.05)
    back = S.grid_from_msg(S.grid_to_msg(grid, 3))
    assert np.array_equal(back.values, grid.values) and np.array_equal(back.origin, grid.origin) and back.resolution == 0.05


def test_status_json_exact_and_nan_as_null():
    for i in range(4):
        est = fake_estimate(i, 0.1 * i)
        status = S.status_to_json(est)
        text = S.encode_status(status)
        assert b"NaN" not in text
        back = S.decode_status(text)
        assert back == json.loads(text)
        again = S.estimate_from_status(back)
        assert again.status == est.status and again.frame == est.frame and again.skipped == est.skipped
        if est.pose is None:
            assert again.pose is None and np.isnan(again.score)
        else:
            assert np.array_equal(again.pose, est.pose)  # floats survive the JSON exactly
            assert np.array_equal(again.covariance, est.covariance)
            assert again.alignment.s == est.alignment.s and len(again.alternatives) == 2
        assert again.timings == est.timings
    schema = json.loads(S.STATUS_JSON_SCHEMA_BYTES)
    assert schema["properties"]["status"]["enum"] == ["initializing", "tracking", "ambiguous", "lost"]


@pytest.mark.parametrize(
    "payload",
    [b"{", b"[]", b'{"frame": 1}', b'{"frame": 1, "timestamp": NaN, "status": "lost"}',
     b'{"frame": "x", "timestamp": 1, "status": "lost"}', b'{"frame": 1, "timestamp": 1, "status": "asleep"}', b"\xff\xfe"],
)
def test_bad_status_payloads(payload):
    with pytest.raises(SessionLogError):
        S.decode_status(payload)
