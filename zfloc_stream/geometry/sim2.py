"""2D similarity transforms x' = s R(theta) x + t (BEV / odometry plane -> floorplan)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def wrap_angle(theta):
    """Map angles to [-pi, pi)."""
    return (np.asarray(theta) + np.pi) % (2.0 * np.pi) - np.pi


@dataclass(frozen=True)
class Sim2:
    s: float = 1.0
    theta: float = 0.0
    t: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self):
        object.__setattr__(self, "s", float(self.s))
        object.__setattr__(self, "theta", float(wrap_angle(self.theta)))
        object.__setattr__(self, "t", (float(self.t[0]), float(self.t[1])))

    # --- construction -------------------------------------------------------------
    @classmethod
    def identity(cls) -> Sim2:
        return cls()

    @classmethod
    def from_params(cls, p) -> Sim2:
        """From the parameter vector (tx, ty, theta, log s)."""
        tx, ty, theta, log_s = (float(v) for v in p)
        return cls(np.exp(log_s), theta, (tx, ty))

    @classmethod
    def from_matrix(cls, m) -> Sim2:
        m = np.asarray(m, dtype=float)
        a, b = m[0, 0], m[1, 0]
        return cls(np.hypot(a, b), np.arctan2(b, a), (m[0, 2], m[1, 2]))

    # --- views ----------------------------------------------------------------------
    @property
    def R(self) -> np.ndarray:
        c, s = np.cos(self.theta), np.sin(self.theta)
        return np.array([[c, -s], [s, c]])

    @property
    def translation(self) -> np.ndarray:
        return np.array(self.t)

    def params(self) -> np.ndarray:
        """Parameter vector (tx, ty, theta, log s), the filter state."""
        return np.array([self.t[0], self.t[1], self.theta, np.log(self.s)])

    def matrix(self) -> np.ndarray:
        m = np.eye(3)
        m[:2, :2] = self.s * self.R
        m[:2, 2] = self.t
        return m

    # --- algebra --------------------------------------------------------------------
    def apply(self, points) -> np.ndarray:
        """Transform (N, 2) points (or one (2,) point)."""
        p = np.asarray(points, dtype=float)
        return p @ (self.s * self.R).T + self.translation

    def __matmul__(self, other: Sim2) -> Sim2:
        """Composition: (self @ other).apply(x) == self.apply(other.apply(x))."""
        t = self.s * self.R @ other.translation + self.translation
        return Sim2(self.s * other.s, self.theta + other.theta, t)

    compose = __matmul__

    def inverse(self) -> Sim2:
        inv_s = 1.0 / self.s
        t = -inv_s * self.R.T @ self.translation
        return Sim2(inv_s, -self.theta, t)

    def apply_pose(self, x: float, y: float, yaw: float) -> tuple[float, float, float]:
        """Map a planar pose (position + heading) through the transform."""
        px, py = self.apply(np.array([x, y]))
        return float(px), float(py), float(wrap_angle(yaw + self.theta))

    def is_finite(self) -> bool:
        return bool(np.isfinite([self.s, self.theta, *self.t]).all() and self.s > 0)
