"""A tiny box-world depth + label renderer for the front-end tests and
benchmarks/bench_fusion.py (independent of sim/).

World frame: z up. A scene is a list of axis-aligned boxes, each with one label for all
its faces. Camera poses follow OpenCV axes; `odom_from_world` re-expresses them in an
arbitrary (tilted) odometry frame so gravity has to be estimated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from zfloc_stream.frames import CEILING, FLOOR, OTHER, WALL, CameraFrame  # noqa: F401 (re-exported for tests)


@dataclass(frozen=True)
class Box:
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    label: int
    true_wall: bool = False  # part of the building (counts as a true wall in metrics)


def room_scene(furniture_as_wall: bool = True) -> list[Box]:
    """An 8 x 6 m room (height 2.6 m) with a 1 m door in the wall x = 8 (y 2.5..3.5,
    up to 2.1 m) opening onto a second room whose far wall is x = 12. Inside: a cabinet and
    a shelf labelled WALL (segmentation errors) and a table labelled OTHER."""
    t, H = 0.1, 2.6
    fur = WALL if furniture_as_wall else OTHER
    return [
        Box((-1, -1, -0.1), (13, 7, 0.0), FLOOR),
        Box((-1, -1, H), (13, 7, H + 0.1), CEILING),
        Box((-t, -t, 0), (0, 6 + t, H), WALL, True),  # x = 0
        Box((-t, -t, 0), (12 + t, 0, H), WALL, True),  # y = 0 (both rooms)
        Box((-t, 6, 0), (12 + t, 6 + t, H), WALL, True),  # y = 6 (both rooms)
        Box((8, 0, 0), (8 + t, 2.5, H), WALL, True),  # x = 8, below the door
        Box((8, 3.5, 0), (8 + t, 6, H), WALL, True),  # x = 8, above the door
        Box((8, 2.5, 2.1), (8 + t, 3.5, H), WALL, True),  # lintel over the door
        Box((12, -t, 0), (12 + t, 6 + t, H), WALL, True),  # far wall of the second room
        Box((3.0, 4.0, 0), (4.0, 4.6, 1.2), fur),  # cabinet, free standing
        Box((5.5, 1.2, 0), (6.3, 1.6, 1.6), fur),  # shelf
        Box((2.0, 1.5, 0), (3.2, 2.3, 0.75), OTHER),  # table
    ]


TRUE_WALL_SEGMENTS = np.array(  # 2D wall faces of room_scene (x0, y0, x1, y1), for metrics
    [
        [0, 0, 0, 6],
        [0, 0, 12, 0],
        [0, 6, 12, 6],
        [8, 0, 8, 2.5],
        [8, 3.5, 8, 6],
        [8.1, 0, 8.1, 2.5],
        [8.1, 3.5, 8.1, 6],
        [12, 0, 12, 6],
    ],
    dtype=float,
)


def distance_to_true_walls(points: np.ndarray) -> np.ndarray:
    p = np.asarray(points, dtype=float)[:, None, :]
    a, b = TRUE_WALL_SEGMENTS[None, :, :2], TRUE_WALL_SEGMENTS[None, :, 2:]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    return np.linalg.norm(p - (a + t[..., None] * ab), axis=-1).min(axis=1)


def intrinsics(width: int, height: int, hfov_deg: float = 90.0) -> np.ndarray:
    f = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2)
    return np.array([[f, 0, width / 2 - 0.5], [0, f, height / 2 - 0.5], [0, 0, 1.0]])


def rotation_axis_angle(axis, angle) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def camera_pose(x, y, z, yaw, tilt_axis=(1, 0, 0), tilt=0.0) -> np.ndarray:
    """T_world_cam: an upright camera looking along world heading `yaw`, then rotated by
    `tilt` radians about `tilt_axis` (camera coordinates)."""
    upright = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)  # columns: cam x, y, z in world
    T = np.eye(4)
    T[:3, :3] = rotation_axis_angle([0, 0, 1], yaw) @ upright @ rotation_axis_angle(tilt_axis, tilt)
    T[:3, 3] = [x, y, z]
    return T


def render(scene: list[Box], T_world_cam: np.ndarray, K: np.ndarray, width: int, height: int, noise=0.0, rng=None):
    """(depth, labels) of the scene: depth along the optical axis, 0 where nothing is hit.
    noise: depth noise std at 1 m (grows with depth squared, like stereo / ToF)."""
    v, u = np.mgrid[0:height, 0:width]
    rays = np.linalg.inv(K) @ np.stack([u.ravel(), v.ravel(), np.ones(u.size)])  # z = 1
    d = T_world_cam[:3, :3] @ rays  # world direction per unit depth
    o = T_world_cam[:3, 3]
    best = np.full(u.size, np.inf)
    labels = np.zeros(u.size, dtype=np.uint8)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        for box in scene:
            t1 = (np.array(box.lo)[:, None] - o[:, None]) * inv
            t2 = (np.array(box.hi)[:, None] - o[:, None]) * inv
            t_near = np.nanmax(np.minimum(t1, t2), axis=0)
            t_far = np.nanmin(np.maximum(t1, t2), axis=0)
            hit = (t_near <= t_far) & (t_near > 1e-6) & (t_near < best)
            best[hit] = t_near[hit]
            labels[hit] = box.label
    depth = np.where(np.isfinite(best), best, 0.0)
    if noise:
        depth = depth + rng.normal(0.0, noise, depth.shape) * depth**2
    depth = depth.astype(np.float32)
    return depth.reshape(height, width), labels.reshape(height, width)


def random_odom_from_world(rng: np.random.Generator, max_tilt_deg: float = 30.0) -> np.ndarray:
    """T_odom_world with a random heading, offset and a tilted z axis (gravity unknown)."""
    T = np.eye(4)
    tilt = rotation_axis_angle(rng.normal(size=3), np.deg2rad(rng.uniform(0, max_tilt_deg)))
    T[:3, :3] = tilt @ rotation_axis_angle([0, 0, 1], rng.uniform(-np.pi, np.pi))
    T[:3, 3] = rng.uniform(-20, 20, 3)
    return T


def camera_sequence(
    rng, n_frames, max_tilt_deg=20.0, width=160, height=120, scene=None, odom_tilt_deg=30.0, labels=True, noise=0.005
):
    """CameraFrames along a wandering path inside the first room (and the world->odom map)."""
    scene = room_scene() if scene is None else scene
    K = intrinsics(width, height)
    T_odom_world = random_odom_from_world(rng, odom_tilt_deg)
    frames = []
    for i in range(n_frames):
        x = 1.5 + 5.0 * (0.5 + 0.5 * np.sin(0.35 * i))
        y = 1.5 + 3.0 * (0.5 + 0.5 * np.cos(0.23 * i))
        yaw = 0.4 * i
        axis = rng.normal(size=3)
        tilt = np.deg2rad(rng.uniform(0, max_tilt_deg))
        T_wc = camera_pose(x, y, 1.4 + 0.1 * np.sin(i), yaw, axis, tilt)
        depth, lab = render(scene, T_wc, K, width, height, noise, rng)
        frames.append(
            CameraFrame(
                depth, lab if labels else None, K, T_odom_world @ T_wc, float(i), ground_truth=np.array([x, y, yaw])
            )
        )
    return frames, T_odom_world


def plane_to_world(bev, T_odom_world: np.ndarray):
    """2D map plane xy -> world xy for a BEV whose gravity is known (z dependence ignored:
    the plane is horizontal up to the gravity error)."""
    M = bev.gravity.R_plane_odom @ T_odom_world[:3, :3]  # world -> plane rotation
    b = bev.gravity.R_plane_odom @ T_odom_world[:3, 3]
    A_inv = np.linalg.inv(M[:2, :2])

    def apply(xy):
        return (np.asarray(xy, dtype=float) - b[:2]) @ A_inv.T

    return apply


def world_to_plane(bev, T_odom_world: np.ndarray):
    """2D map world xy (on the floor) -> BEV plane xy."""
    M = bev.gravity.R_plane_odom @ T_odom_world[:3, :3]
    b = bev.gravity.R_plane_odom @ T_odom_world[:3, 3]

    def apply(xy):
        xy = np.asarray(xy, dtype=float)
        return xy @ M[:2, :2].T + b[:2]

    return apply


def world_points(depth: np.ndarray, K: np.ndarray, T_world_cam: np.ndarray) -> np.ndarray:
    """(H, W, 3) world coordinates of every pixel of a depth image."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w]
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T
    return (rays * depth[..., None]) @ T_world_cam[:3, :3].T + T_world_cam[:3, 3]
