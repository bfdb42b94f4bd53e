"""Odometry at its own rate, looked up at frame stamps: SE(3) interpolation, skip reasons,
out-of-order messages."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zfloc_stream.geometry.pose_interpolation import PoseTrack, interpolate_pose

S = 1_000_000_000


def pose(x, y, z, yaw, pitch=0.0):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("zy", [yaw, pitch]).as_matrix()
    T[:3, 3] = (x, y, z)
    return T


def test_pose_between_two_messages_is_linear_in_position_and_slerp_in_rotation():
    track = PoseTrack(max_gap=1.0)
    track.add(10 * S, pose(0.0, 0.0, 0.0, 0.0))
    track.add(10 * S + S // 2, pose(1.0, 2.0, 0.5, 1.0, pitch=0.2))
    T, reason = track.at(10 * S + S // 8)  # a quarter of the way
    assert reason is None
    np.testing.assert_allclose(T[:3, 3], [0.25, 0.5, 0.125], atol=1e-12)
    # slerp: a quarter of the rotation angle about the same axis
    full = Rotation.from_matrix(pose(0, 0, 0, 1.0, pitch=0.2)[:3, :3]).as_rotvec()
    np.testing.assert_allclose(Rotation.from_matrix(T[:3, :3]).as_rotvec(), full / 4, atol=1e-12)
    np.testing.assert_allclose(T[3], [0, 0, 0, 1])


def test_stamp_on_a_message_returns_its_pose_bit_for_bit():
    track = PoseTrack()
    T1 = pose(0.1234567, -2.0, 0.3, 0.777)
    track.add(5 * S, pose(0, 0, 0, 0))
    track.add(6 * S, T1)
    track.add(7 * S, pose(3, 0, 0, 0))
    T, _ = track.at(6 * S)
    assert np.array_equal(T, T1)


def test_slerp_takes_the_short_way_across_pi():
    T = interpolate_pose(pose(0, 0, 0, np.pi - 0.1), pose(0, 0, 0, -np.pi + 0.1), 0.5)
    yaw = np.arctan2(T[1, 0], T[0, 0])
    assert abs(abs(yaw) - np.pi) < 1e-9  # halfway is pi, not 0


def test_frames_outside_the_span_or_in_a_gap_are_skipped_with_their_reason():
    track = PoseTrack("odometry /odom", max_gap=0.5)
    for k in range(5):
        track.add(10 * S + k * S // 10, pose(k * 0.1, 0, 0, 0))
    track.add(12 * S, pose(1.0, 0, 0, 0))  # a 1.6 s dropout before this one
    T, reason = track.at(9 * S)
    assert T is None and "outside the odometry /odom time span [10.000000, 12.000000]" in reason and "t=9.000000" in reason
    T, reason = track.at(13 * S)
    assert T is None and "outside" in reason
    T, reason = track.at(11 * S)
    assert T is None and "1.600 s gap" in reason
    assert PoseTrack().at(S) == (None, "no odometry message at all")


def test_out_of_order_messages_are_sorted_and_duplicates_keep_the_first():
    stamps = [3, 1, 4, 0, 2]
    track = PoseTrack()
    for k in stamps:
        track.add(k * S, pose(float(k), 0, 0, 0))
    track.add(2 * S, pose(99.0, 0, 0, 0))  # a republished stamp
    assert track.duplicates == 1 and track.span == (0, 4 * S)
    for t in (0.5, 1.5, 2.25, 3.9):
        T, reason = track.at(int(t * S))
        assert reason is None and T[0, 3] == pytest.approx(t)


def test_drop_before_keeps_what_later_lookups_need():
    track = PoseTrack()
    for k in range(10):
        track.add(k * S, pose(float(k), 0, 0, 0))
    track.drop_before(int(5.5 * S))
    assert len(track) == 5 and track.span == (5 * S, 9 * S)
    T, reason = track.at(int(5.5 * S))
    assert reason is None and T[0, 3] == pytest.approx(5.5)
