"""One mode of the filter bank: a Kalman filter over the odom -> floorplan alignment,
anchored at the sensor (filter_bank.py explains the parametrisation), and the Jacobians
that carry its state and covariance from one anchor to another."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from filterpy.kalman import KalmanFilter

from ..geometry.sim2 import Sim2


def _perp(v: np.ndarray) -> np.ndarray:
    """v rotated by +90 degrees: d/dtheta of R(theta) v is R(theta) perp(v)."""
    return np.array([-v[1], v[0]])


def anchored_state(alignment: Sim2, anchor: np.ndarray) -> np.ndarray:
    """(qx, qy, theta, log s) of an alignment about the anchor point."""
    qx, qy = alignment.apply(anchor)
    return np.array([qx, qy, alignment.theta, np.log(alignment.s)])


def implied_jacobian(state: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """d/dstate of (q + s R offset, theta, log s): identity plus the lever-arm columns."""
    scaled_r = np.exp(state[3]) * Sim2(1.0, state[2]).R
    jac = np.eye(4)
    jac[:2, 2] = scaled_r @ _perp(offset)
    jac[:2, 3] = scaled_r @ offset
    return jac


@dataclass(eq=False)
class Mode:
    """One live hypothesis. Read its fields; only the tracker changes them."""

    id: int
    kf: KalmanFilter
    anchor: np.ndarray  # (2,) odometry-plane point the state is expressed about
    score: float  # latest fresh score C = Cc - Cv
    running_score: float  # exponentially smoothed score, drives the weight
    weight: float = 0.0  # normalised over modes
    hits: int = 1  # rounds in which it was found near the top (within confirm_score_gap of the round's best)
    collapses: int = 0  # consecutive rounds its score collapsed or it went unseen
    tracked_rounds: int = 0  # consecutive rounds it was the tracked mode
    near_top: bool = True  # found near the top (within confirm_score_gap of the best) in the latest round

    @property
    def state(self) -> np.ndarray:
        """(qx, qy, theta, log s) about `anchor`."""
        return self.kf.x.ravel().copy()

    @property
    def local_covariance(self) -> np.ndarray:
        """4x4 covariance of `state` (anchored parametrisation)."""
        return self.kf.P.copy()

    @property
    def alignment(self) -> Sim2:
        qx, qy, theta, log_s = self.kf.x.ravel()
        s = np.exp(log_s)
        t = np.array([qx, qy]) - s * Sim2(1.0, theta).R @ self.anchor
        return Sim2(s, theta, t)

    @property
    def covariance(self) -> np.ndarray:
        """4x4 covariance of alignment.params() = (tx, ty, theta, log s)."""
        jac = implied_jacobian(self.kf.x.ravel(), -self.anchor)  # t = q + s R (0 - a)
        return jac @ self.kf.P @ jac.T

    def pose(self, sensor_xy, yaw: float) -> np.ndarray:
        """(x, y, theta) of the sensor pose in the floorplan implied by this mode."""
        return np.array(self.alignment.apply_pose(float(sensor_xy[0]), float(sensor_xy[1]), yaw))
