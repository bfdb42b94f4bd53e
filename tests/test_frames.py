import numpy as np
import pytest

from zfloc_stream.errors import FrameError, ZflocError
from zfloc_stream.frames import FLOOR, WALL, CameraFrame, LaserFrame

K = np.array([[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]])


def camera(**kw):
    args = dict(
        depth=np.full((48, 64), 2.0, dtype=np.float32),
        labels=np.full((48, 64), WALL, dtype=np.uint8),
        K=K,
        T_odom_cam=np.eye(4),
        timestamp=0.0,
    )
    args.update(kw)
    return CameraFrame(**args)


def laser(**kw):
    args = dict(
        ranges=np.full(90, 3.0),
        angle_min=-np.pi / 2,
        angle_increment=np.pi / 90,
        range_min=0.1,
        range_max=30.0,
        T_odom_sensor=np.eye(4),
        timestamp=0.0,
    )
    args.update(kw)
    return LaserFrame(**args)


def test_valid_frames_are_accepted_and_normalised():
    f = camera(depth=np.full((48, 64), 2.0), labels=None)  # float64 depth is converted
    assert f.depth.dtype == np.float32 and f.shape == (48, 64)
    d = np.full((48, 64), 2.0, dtype=np.float32)
    d[0, 0] = np.nan
    d[1, 1] = 0.0  # NaN and 0 are "no reading", not errors
    camera(depth=d)
    scan = laser(ranges=np.r_[np.nan, np.full(89, 3.0)])
    assert not scan.valid[0] and scan.valid[1:].all()


def rotation_with_scale():
    T = np.eye(4)
    T[:3, :3] *= 1.01
    return T


def reflection():
    T = np.eye(4)
    T[0, 0] = -1
    return T


def pose_with_nan():
    T = np.eye(4)
    T[0, 3] = np.nan
    return T


def with_value(value, where=(3, 4)):
    d = np.full((48, 64), 2.0, dtype=np.float32)
    d[where] = value
    return d


@pytest.mark.parametrize(
    "kw, fragment",
    [
        (dict(depth=with_value(np.inf)), "inf"),
        (dict(depth=with_value(-1.0)), "negative"),
        (dict(depth=np.zeros((48, 64))), "no valid reading"),
        (dict(depth=np.full((48, 64), np.nan)), "no valid reading"),
        (dict(depth=np.zeros((48, 64, 3))), "HxW"),
        (dict(depth=np.zeros((0, 64))), "HxW"),
        (dict(depth=[["a", "b"]]), "numeric"),
        (dict(labels=np.zeros((48, 63), dtype=np.uint8)), "labels shape"),
        (dict(labels=np.zeros((48, 64), dtype=np.int32)), "uint8"),
        (dict(labels=np.full((48, 64), 9, dtype=np.uint8)), "code 9"),
        (dict(K=np.zeros((3, 3))), "singular"),
        (dict(K=np.array([[100.0, 0, 32], [0, -100.0, 24], [0, 0, 1]])), "singular"),
        (dict(K=np.array([[100.0, 0, 32], [0, 100.0, 24], [0, 0, 2]])), "last row"),
        (dict(K=np.eye(2)), "3x3"),
        (dict(K=np.full((3, 3), np.nan)), "finite"),
        (dict(T_odom_cam=rotation_with_scale()), "orthonormal"),
        (dict(T_odom_cam=reflection()), "orthonormal"),
        (dict(T_odom_cam=pose_with_nan()), "NaN"),
        (dict(T_odom_cam=np.eye(3)), "4x4"),
        (dict(timestamp=float("nan")), "timestamp"),
        (dict(timestamp="yesterday"), "timestamp"),
    ],
)
def test_bad_camera_frames_raise_frame_error(kw, fragment):
    with pytest.raises(FrameError, match=fragment):
        camera(**kw)


@pytest.mark.parametrize(
    "kw, fragment",
    [
        (dict(ranges=np.zeros((2, 3))), "1D"),
        (dict(ranges=[]), "1D"),
        (dict(ranges=["x"]), "numeric"),
        (dict(angle_increment=0.0), "non-zero"),
        (dict(angle_min=float("inf")), "angle_min"),
        (dict(range_min=5.0, range_max=1.0), "range_min"),
        (dict(range_min=-1.0), "range_min"),
        (dict(T_odom_sensor=reflection()), "orthonormal"),
        (dict(timestamp=None), "timestamp"),
    ],
)
def test_bad_laser_frames_raise_frame_error(kw, fragment):
    with pytest.raises(FrameError, match=fragment):
        laser(**kw)


def test_frame_error_is_a_zfloc_error():
    with pytest.raises(ZflocError):
        camera(labels=np.full((48, 64), FLOOR, dtype=np.uint8), K=np.zeros((3, 3)))
