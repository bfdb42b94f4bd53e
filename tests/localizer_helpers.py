"""Running a Localizer in tests (test_localizer*.py, test_threads.py): frames whose odometry
jumps, a camera carried off, a run with settings overrides, and an estimate as bytes for
bit-for-bit checks."""

from dataclasses import replace

import numpy as np

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.stream.localizer import Localizer


class Kidnapped:
    """Frames whose odometry jumps (a VIO reset) at frame k0 while the camera moves on."""

    def __init__(self, seq, k0, yaw=1.0, shift=(4.0, -3.0)):
        self.seq, self.k0 = seq, k0
        self.jump = odometry_jump(yaw, shift)

    def __iter__(self):
        for k, frame in enumerate(self.seq):
            yield frame if k < self.k0 else replace(frame, T_odom_cam=self.jump @ frame.T_odom_cam)


def carried_off(frames, k0, later, count):
    """frames[:k0], then `count` frames from frames[later] on, their odometry re-anchored so
    that it stands still across the cut: the camera was carried from frame k0 - 1's place
    to frame later's. Camera or laser frames."""
    key = "T_odom_sensor" if hasattr(frames[0], "T_odom_sensor") else "T_odom_cam"
    anchor = getattr(frames[k0 - 1], key) @ np.linalg.inv(getattr(frames[later], key))
    return frames[:k0] + [replace(f, **{key: anchor @ getattr(f, key)}) for f in frames[later:later + count]]


def settings_with(*overrides):
    return load_settings(overrides=list(overrides))


def run_localizer(floorplan, frames, settings):
    with Localizer(floorplan, settings) as loc:
        return [loc.push(f) for f in frames]


def estimate_bits(est):
    """Everything an estimate reports except its timings, as bytes / plain values."""
    def b(a):
        return None if a is None else np.asarray(a, dtype=float).tobytes()

    alts = tuple((b(a.pose), b(a.weight), b(a.score), b(a.alignment.params())) for a in est.alternatives)
    align = None if est.alignment is None else b(est.alignment.params())
    return (est.frame, est.status, b(est.pose), b(est.covariance), align, b(est.score), alts, est.skipped, est.round_skipped)  # bytes: NaN == NaN


def odometry_jump(yaw, shift, about=(0.0, 0.0)) -> np.ndarray:
    """The 4x4 jump of an odometry frame: turned by yaw (rad) about the point `about`, then
    shifted by `shift` (both in the odometry plane)."""
    c, s = np.cos(yaw), np.sin(yaw)
    jump = np.eye(4)
    jump[:2, :2] = [[c, -s], [s, c]]
    about = np.asarray(about, dtype=float)
    jump[:2, 3] = about - jump[:2, :2] @ about + np.asarray(shift, dtype=float)
    return jump


def odometry_jumped(frames, k0, shift=(0.0, 0.0), yaw_deg=0.0):
    """frames with their odometry jumped from frame k0 on (a persistent jump: a VIO reset, a
    slipped wheel): turned by yaw_deg about the sensor's odometry position at k0, then
    shifted by `shift`, while the sensor itself moves on. Camera or laser frames."""
    key = "T_odom_sensor" if hasattr(frames[0], "T_odom_sensor") else "T_odom_cam"
    jump = odometry_jump(np.deg2rad(yaw_deg), shift, about=getattr(frames[k0], key)[:2, 3])
    return [f if k < k0 else replace(f, **{key: jump @ getattr(f, key)}) for k, f in enumerate(frames)]
