"""Small deterministic camera and laser frames (random depth, labels, poses) for the session
tests and the session benchmarks: no scene, no engine."""

from __future__ import annotations

import numpy as np

from zfloc_stream.frames import CameraFrame, LaserFrame


def rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    x, y, z, w = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def pose(rng: np.random.Generator) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = rotation(rng)
    T[:3, 3] = rng.normal(scale=5.0, size=3)
    return T


def camera_frames(n: int, seed: int = 0, shape=(24, 32), labels: bool = True, truth: bool = True, t0: float = 0.5):
    rng = np.random.default_rng(seed)
    h, w = shape
    K = np.array([[w / 2, 0, w / 2], [0, w / 2, h / 2], [0, 0, 1.0]])
    out = []
    for i in range(n):
        depth = rng.uniform(0.3, 8.0, shape).astype(np.float32)
        depth[rng.random(shape) < 0.05] = 0.0
        depth[rng.random(shape) < 0.02] = np.nan
        lab = rng.integers(0, 5, shape).astype(np.uint8) if labels else None
        gt = np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-np.pi, np.pi)]) if truth else None
        out.append(CameraFrame(depth, lab, K, pose(rng), t0 + 0.1 * i, ground_truth=gt))
    return out


def laser_frames(n: int, seed: int = 0, beams: int = 90, truth: bool = True):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        r = rng.uniform(0.1, 12.0, beams)
        r[rng.random(beams) < 0.1] = np.inf
        T = np.eye(4)
        c, s = np.cos(0.1 * i), np.sin(0.1 * i)
        T[:2, :2] = [[c, -s], [s, c]]
        T[:2, 3] = [0.2 * i, -0.1 * i]
        gt = np.array([1.0 + i, 2.0, 0.3 * i - 1.0]) if truth else None
        out.append(LaserFrame(r, -np.pi / 2, np.pi / (beams - 1), 0.05, 10.0, T, 3.0 + 0.05 * i, ground_truth=gt))
    return out
