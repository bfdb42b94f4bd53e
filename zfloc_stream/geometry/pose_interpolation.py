"""Poses of a sensor stream at any time: odometry published at its own rate, looked up at
each scan's or depth image's timestamp.

    track = PoseTrack(max_gap=0.5)
    track.add(stamp_ns, T_odom_base)          # any order; a duplicate stamp keeps the first
    T, reason = track.at(frame_stamp_ns)      # (4x4, None), or (None, why it cannot be known)

Between two messages the pose is interpolated on SE(3) the usual way: position linearly,
rotation by slerp (constant angular rate). A stamp equal to a message's returns that
message's pose bit for bit, so sessions whose frames and odometry share stamps replay
exactly. Outside the span of the messages, or inside a gap longer than max_gap, there is
no honest answer: the reason says which, and the caller skips the frame.
"""

from __future__ import annotations

import bisect

import numpy as np


def _seconds(ns: int) -> str:
    return f"t={ns / 1e9:.6f}"


def interpolate_pose(T0: np.ndarray, T1: np.ndarray, a: float) -> np.ndarray:
    """The SE(3) pose a of the way from T0 to T1 (0 <= a <= 1): linear position, slerp rotation."""
    from scipy.spatial.transform import Rotation  # here: ~0.6 s that a CLI error must not pay

    R0 = Rotation.from_matrix(T0[:3, :3])
    delta = (R0.inv() * Rotation.from_matrix(T1[:3, :3])).as_rotvec()
    T = np.eye(4)
    T[:3, :3] = (R0 * Rotation.from_rotvec(a * delta)).as_matrix()
    T[:3, 3] = (1.0 - a) * T0[:3, 3] + a * T1[:3, 3]
    return T


class PoseTrack:
    """Timestamped 4x4 poses of one frame (e.g. odom -> base_link) at their own rate.

    max_gap: seconds; a stamp between two messages further apart than this is not
    interpolated (the odometry dropped out there). None: no limit."""

    def __init__(self, name: str = "odometry", max_gap: float | None = None):
        self.name = name
        self.max_gap_ns = None if max_gap is None else int(round(max_gap * 1e9))
        self._stamps: list[int] = []  # kept sorted: out-of-order messages are inserted in place
        self._poses: list[np.ndarray] = []
        self.duplicates = 0

    def __len__(self) -> int:
        return len(self._stamps)

    def add(self, stamp_ns: int, T: np.ndarray) -> None:
        stamp_ns = int(stamp_ns)
        i = bisect.bisect_left(self._stamps, stamp_ns)
        if i < len(self._stamps) and self._stamps[i] == stamp_ns:
            self.duplicates += 1  # the same stamp twice: keep the first (a republished message)
            return
        self._stamps.insert(i, stamp_ns)
        self._poses.insert(i, np.asarray(T, dtype=float))

    @property
    def span(self) -> tuple[int, int] | None:
        return (self._stamps[0], self._stamps[-1]) if self._stamps else None

    def drop_before(self, stamp_ns: int) -> None:
        """Forget messages no later lookup at or after stamp_ns can need (keeps one before)."""
        i = bisect.bisect_right(self._stamps, int(stamp_ns)) - 1
        if i > 0:
            del self._stamps[:i], self._poses[:i]

    def at(self, stamp_ns: int) -> tuple[np.ndarray | None, str | None]:
        """(pose, None) at the stamp, or (None, reason) when it cannot be known."""
        stamp_ns = int(stamp_ns)
        if not self._stamps:
            return None, f"no {self.name} message at all"
        i = bisect.bisect_left(self._stamps, stamp_ns)
        if i < len(self._stamps) and self._stamps[i] == stamp_ns:
            return self._poses[i].copy(), None
        if i == 0 or i == len(self._stamps):
            first, last = self.span
            return None, f"{_seconds(stamp_ns)} is outside the {self.name} time span [{first / 1e9:.6f}, {last / 1e9:.6f}] s"
        t0, t1 = self._stamps[i - 1], self._stamps[i]
        if self.max_gap_ns is not None and t1 - t0 > self.max_gap_ns:
            return None, f"{_seconds(stamp_ns)} falls in a {(t1 - t0) / 1e9:.3f} s gap of {self.name} (more than {self.max_gap_ns / 1e9:g} s)"
        return interpolate_pose(self._poses[i - 1], self._poses[i], (stamp_ns - t0) / (t1 - t0)), None
