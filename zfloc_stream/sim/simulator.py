"""Frame sequences from a scene: a walk, rendered frames, and the sensor errors of a real
phone/robot pipeline.

Camera (`simulate`): depth + labels from `render`, with proportional depth noise, a global
scale error shared by depth and odometry translations (a monocular reconstruction at the
wrong scale), segmentation errors (some furniture labelled wall, wall pixels dropped) and
drifting odometry (random walk in translation and yaw per step) in an odometry frame with
a random origin and heading, gravity-aligned or arbitrarily tilted.

Laser (`simulate_laser`): a 2D scanner on the floorplan (raycast2d) whose beams are also
stopped by furniture taller than the scanner, with range noise and the same odometry drift
(no scale error: a laser is metric).

Sequence-level draws (walk, scale, odometry origin and drift, which furniture is
mislabelled) are made up front; per-frame noise comes from make_rng(seed, ..., frame), so
frame k is the same whether the sequence is read in order or not.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from scipy.spatial.transform import Rotation

from ..errors import ConfigError, InputError
from ..frames import OTHER, UNKNOWN, WALL, CameraFrame, LaserFrame
from ..runtime.rng import make_rng
from ..geometry.sim2 import Sim2, wrap_angle
from .render import box_distance, camera_pose, intrinsics, render
from .scenes import build_scene
from .scenes import Scene
from .trajectory import WalkSettings, random_walk


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    @classmethod
    def load(cls, data: dict | None = None):
        """From a plain dict (e.g. parsed YAML); bad keys or values raise ConfigError."""
        try:
            return cls.model_validate(data or {})
        except ValidationError as err:
            first = err.errors()[0]
            loc = ".".join(str(p) for p in first["loc"]) or "<root>"
            raise ConfigError(f"{cls.__name__}: '{loc}': {first['msg']}") from None


class MotionSettings(_Model):
    """How the sensor moves and how its odometry drifts."""

    step_min: float = Field(0.3, gt=0)  # m per frame
    step_max: float = Field(0.5, gt=0)
    heading_wiggle_deg: float = Field(4.0, ge=0)  # std of the heading wiggle around the path direction
    frame_interval: float = Field(0.5, gt=0)  # s between frames (timestamps)
    odom_translation_noise: float = Field(0.02, ge=0)  # std per axis and step, fraction of the step length
    odom_yaw_noise_deg: float = Field(0.3, ge=0)  # std of the yaw error added per step
    odom_origin_range: float = Field(20.0, ge=0)  # m, odometry origin uniform in +-range (heading uniform)


class SimSettings(MotionSettings):
    """A camera scenario (scenario parameters, not algorithm hyperparameters)."""

    width: int = Field(160, ge=8)
    height: int = Field(120, ge=8)
    hfov_deg: float = Field(90.0, gt=10, lt=170)  # 48 phone-like, 108 Gibson-like
    max_depth: float = Field(10.0, gt=0)  # m, Euclidean reach; farther pixels read 0 (no depth)
    camera_height: float = Field(1.4, gt=0)  # m above the floor
    camera_height_jitter: float = Field(0.02, ge=0)  # m, std per frame
    max_pitch_deg: float = Field(10.0, ge=0, le=45)  # per frame uniform in +-max
    max_roll_deg: float = Field(10.0, ge=0, le=45)
    depth_noise: float = Field(0.01, ge=0)  # proportional std of depth
    scale_error: float = Field(0.1, ge=0, lt=0.9)  # true scale uniform in [1 - e, 1 + e]
    furniture_as_wall_prob: float = Field(0.1, ge=0, le=1)  # per furniture piece and sequence
    wall_dropout: float = Field(0.05, ge=0, le=1)  # per wall pixel and frame: labelled unknown
    odom_gravity_aligned: bool = True  # False: the odometry frame is arbitrarily rotated in 3D
    use_labels: bool = True  # False: frames carry labels=None (geometric labeller)


class LaserSimSettings(MotionSettings):
    """A 2D laser scenario."""

    fov_deg: float = Field(360.0, gt=0, le=360)  # 360 or 270 typical
    n_beams: int = Field(360, ge=1)
    max_range: float = Field(10.0, gt=0)  # m
    range_noise: float = Field(0.015, ge=0)  # m, std
    outlier_ratio: float = Field(0.0, ge=0, le=1)  # beams reading a uniform short range
    sensor_height: float = Field(0.3, gt=0)  # m; furniture taller than this blocks beams
    furniture_occludes: bool = True


def _walk_settings(s: MotionSettings) -> WalkSettings:
    if s.step_min > s.step_max:
        raise ConfigError(f"step_min {s.step_min} exceeds step_max {s.step_max}")
    return WalkSettings(step_min=s.step_min, step_max=s.step_max, wiggle_deg=s.heading_wiggle_deg)


# --- odometry ----------------------------------------------------------------------------------


def drift_odometry(poses: np.ndarray, scale: float, rng: np.random.Generator, translation_noise: float,
                   yaw_noise: float, origin) -> np.ndarray:
    """Odometry poses (N, 3) in the odometry frame: the true relative motions (translations
    multiplied by `scale`) with Gaussian errors added per step and integrated from `origin`
    (x, y, theta). translation_noise: std per axis as a fraction of the step length;
    yaw_noise: std in radians per step."""
    poses = np.asarray(poses, dtype=float)
    n = len(poses)
    out = np.empty((n, 3))
    out[0] = origin
    if n == 1:
        return out
    d = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1) * scale
    step = np.linalg.norm(local, axis=1, keepdims=True)
    local = local + rng.normal(0.0, 1.0, local.shape) * translation_noise * step
    dyaw = wrap_angle(np.diff(poses[:, 2])) + rng.normal(0.0, yaw_noise, n - 1)
    yaw = origin[2] + np.concatenate([[0.0], np.cumsum(dyaw)])
    cy, sy = np.cos(yaw[:-1]), np.sin(yaw[:-1])
    world = np.stack([cy * local[:, 0] - sy * local[:, 1], sy * local[:, 0] + cy * local[:, 1]], axis=1)
    out[1:, :2] = np.asarray(origin[:2]) + np.cumsum(world, axis=0)
    out[:, 2] = wrap_angle(yaw)
    return out


def true_alignments(poses: np.ndarray, odom: np.ndarray, scale: float) -> list[Sim2]:
    """Per frame, the Sim2 odometry plane -> floorplan that maps the odometry pose onto the
    true pose: scale 1/scale, rotation true yaw - odometry yaw."""
    out = []
    for (x, y, yaw), (ox, oy, oyaw) in zip(poses, odom):
        rot = Sim2(1.0 / scale, yaw - oyaw)
        t = np.array([x, y]) - rot.apply(np.array([ox, oy]))
        out.append(Sim2(1.0 / scale, yaw - oyaw, t))
    return out


def _odom_origin(rng, reach: float) -> np.ndarray:
    return np.array([rng.uniform(-reach, reach), rng.uniform(-reach, reach), rng.uniform(-np.pi, np.pi)])


def _trajectory(scene: Scene, trajectory, rng, n_frames: int, ws: WalkSettings) -> np.ndarray:
    if trajectory is None:
        return random_walk(scene, rng, n_frames, ws=ws)
    poses = np.asarray(trajectory, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) == 0 or not np.isfinite(poses).all():
        raise InputError(f"trajectory must be a finite (N, 3) array of x, y, theta, got shape {poses.shape}")
    return poses if n_frames is None else poses[:n_frames]


def _scene(scene, seed: int) -> Scene:
    return build_scene(scene, seed) if isinstance(scene, str) else scene


# --- camera --------------------------------------------------------------------------------------


@dataclass(eq=False)
class SimSequence:
    """A simulated camera sequence. Frames are rendered on access (index or iteration) and
    are identical whichever order they are read in.

    poses: (N, 3) true x, y, theta (optical-axis heading) in the floorplan.
    odom: (N, 3) drifting odometry-plane poses (before any tilt of the odometry frame).
    scale: true scale; odometry translations and depths are `scale` x the truth.
    alignments: per frame, the true Sim2 odometry plane -> floorplan (scale 1/scale).
    odom_tilt: 4x4 rotation applied to the gravity-aligned odometry frame (identity when
    settings.odom_gravity_aligned).
    """

    scene: Scene
    settings: SimSettings
    seed: int
    poses: np.ndarray
    odom: np.ndarray
    scale: float
    alignments: list[Sim2]
    odom_tilt: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    heights: np.ndarray
    odom_z0: float
    mislabelled_furniture: np.ndarray  # (K,) bool: furniture pieces the "network" calls wall
    K: np.ndarray = field(init=False)

    def __post_init__(self):
        s = self.settings
        self.K = intrinsics(s.width, s.height, s.hfov_deg)

    def __len__(self) -> int:
        return len(self.poses)

    def __iter__(self):
        return (self[k] for k in range(len(self)))

    def __getitem__(self, k: int) -> CameraFrame:
        if not -len(self) <= k < len(self):
            raise IndexError(k)
        return self._frame(k % len(self))

    @property
    def frames(self) -> list[CameraFrame]:
        return list(self)

    @property
    def alignment(self) -> Sim2:
        """The true alignment at the last frame (it drifts with the odometry)."""
        return self.alignments[-1]

    def T_world_cam(self, k: int) -> np.ndarray:
        x, y, yaw = self.poses[k]
        return camera_pose(x, y, yaw, self.heights[k], self.pitch[k], self.roll[k])

    def T_odom_cam(self, k: int) -> np.ndarray:
        x, y, yaw = self.odom[k]
        z = self.odom_z0 + self.scale * self.heights[k]
        return self.odom_tilt @ camera_pose(x, y, yaw, z, self.pitch[k], self.roll[k])

    def _frame(self, k: int) -> CameraFrame:
        s = self.settings
        depth, labels, furniture = render(self.scene, self.T_world_cam(k), self.K, (s.height, s.width),
                                          max_range=s.max_depth, return_furniture_index=True)
        rng = make_rng(self.seed, "sim", "frame", k)
        valid = depth > 0
        noisy = depth * self.scale * (1.0 + s.depth_noise * rng.standard_normal(depth.shape))
        depth = np.where(valid, np.maximum(noisy, 1e-3), 0.0).astype(np.float32)
        if s.use_labels:
            if self.mislabelled_furniture.any():
                wrong = (furniture >= 0) & self.mislabelled_furniture[np.maximum(furniture, 0)]
                labels[wrong] = WALL
            if s.wall_dropout > 0:
                labels[(labels == WALL) & (rng.random(labels.shape) < s.wall_dropout)] = UNKNOWN
        return CameraFrame(depth=depth, labels=labels if s.use_labels else None, K=self.K,
                           T_odom_cam=self.T_odom_cam(k), timestamp=k * s.frame_interval,
                           ground_truth=self.poses[k].copy())


DEFAULT_FRAMES = 100


def _true_poses(scene, settings: MotionSettings, seed: int, n_frames: int | None, trajectory):
    """The scene (built from a name if needed) and the true (N, 3) poses of a sequence:
    a seeded random walk of n_frames (default 100), or the given trajectory (all of it
    unless n_frames is given). Shared by the camera and laser simulators."""
    scene = _scene(scene, seed)
    if trajectory is None:
        n_frames = DEFAULT_FRAMES if n_frames is None else n_frames
    if n_frames is not None and n_frames < 1:
        raise InputError(f"n_frames must be >= 1, got {n_frames}")
    ws = _walk_settings(settings)
    return scene, _trajectory(scene, trajectory, make_rng(seed, "sim", scene.name, "walk"), n_frames, ws)


def simulate(scene: Scene | str, settings: SimSettings | None = None, seed: int = 0, n_frames: int | None = None,
             trajectory=None) -> SimSequence:
    """A camera sequence of n_frames (default 100) along a seeded random walk, or along
    `trajectory` ((N, 3) true x, y, theta, e.g. from trajectory_through; all of it unless
    n_frames is given). `scene` may be a built-in name (built with the same seed)."""
    settings = settings or SimSettings()
    scene, poses = _true_poses(scene, settings, seed, n_frames, trajectory)
    rng = make_rng(seed, "sim", "sequence")
    n = len(poses)
    scale = float(rng.uniform(1.0 - settings.scale_error, 1.0 + settings.scale_error))
    odom = drift_odometry(poses, scale, rng, settings.odom_translation_noise,
                          np.radians(settings.odom_yaw_noise_deg), _odom_origin(rng, settings.odom_origin_range))
    pitch = np.radians(settings.max_pitch_deg) * rng.uniform(-1.0, 1.0, n)
    roll = np.radians(settings.max_roll_deg) * rng.uniform(-1.0, 1.0, n)
    heights = settings.camera_height + settings.camera_height_jitter * rng.standard_normal(n)
    odom_z0 = float(rng.uniform(-1.0, 1.0))
    tilt = np.eye(4)
    if not settings.odom_gravity_aligned:
        tilt[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    mislabelled = rng.random(len(scene.furniture)) < settings.furniture_as_wall_prob
    return SimSequence(scene, settings, int(seed), poses, odom, scale, true_alignments(poses, odom, scale),
                       tilt, pitch, roll, heights, odom_z0, mislabelled)


# --- laser ----------------------------------------------------------------------------------------


@dataclass(eq=False)
class LaserSequence:
    """A simulated 2D laser sequence (frames computed up front: they are small)."""

    scene: Scene
    settings: LaserSimSettings
    seed: int
    poses: np.ndarray
    odom: np.ndarray
    alignments: list[Sim2]
    frames: list[LaserFrame]
    scale: float = 1.0

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self):
        return iter(self.frames)

    def __getitem__(self, k: int) -> LaserFrame:
        return self.frames[k]

    @property
    def alignment(self) -> Sim2:
        return self.alignments[-1]


def _laser_ranges(scene: Scene, pose, s: LaserSimSettings, rng) -> tuple[np.ndarray, np.ndarray]:
    from .raycast2d import beam_angles, trace

    angles = beam_angles(np.radians(s.fov_deg), s.n_beams)
    world = pose[2] + angles
    dirs = np.stack([np.cos(world), np.sin(world)], axis=1)
    ranges = trace(scene.floorplan, pose[:2], dirs, s.max_range)
    tall = scene.furniture[scene.furniture[:, 5] > s.sensor_height] if s.furniture_occludes else scene.furniture[:0]
    if len(tall):
        f = box_distance(np.asarray(pose[:2]), dirs[:, None, :], tall[:, :2], tall[:, 2:4] / 2, tall[:, 4])
        ranges = np.minimum(ranges, f.min(axis=1))
    ranges[ranges > s.max_range] = np.inf
    hit = np.isfinite(ranges)
    if s.range_noise > 0:
        ranges[hit] = np.maximum(ranges[hit] + rng.normal(0.0, s.range_noise, hit.sum()), 1e-3)
    if s.outlier_ratio > 0:
        out = hit & (rng.random(len(ranges)) < s.outlier_ratio)
        ranges[out] = ranges[out] * (1.0 - rng.random(out.sum()))
    return angles, ranges


def simulate_laser(scene: Scene | str, settings: LaserSimSettings | None = None, seed: int = 0,
                   n_frames: int | None = None, trajectory=None) -> LaserSequence:
    """A 2D laser sequence of n_frames (default 100) along a seeded random walk, or along
    `trajectory` (all of it unless n_frames is given)."""
    settings = settings or LaserSimSettings()
    scene, poses = _true_poses(scene, settings, seed, n_frames, trajectory)
    rng = make_rng(seed, "sim", "laser", "sequence")
    odom = drift_odometry(poses, 1.0, rng, settings.odom_translation_noise,
                          np.radians(settings.odom_yaw_noise_deg), _odom_origin(rng, settings.odom_origin_range))
    frames = []
    for k, (pose, odom_pose) in enumerate(zip(poses, odom)):
        angles, ranges = _laser_ranges(scene, pose, settings, make_rng(seed, "sim", "laser", k))
        T = np.eye(4)
        c, s = np.cos(odom_pose[2]), np.sin(odom_pose[2])
        T[:2, :2] = [[c, -s], [s, c]]
        T[:2, 3] = odom_pose[:2]
        increment = float(angles[1] - angles[0]) if len(angles) > 1 else 1.0
        frames.append(LaserFrame(ranges=ranges, angle_min=float(angles[0]), angle_increment=increment,
                                 range_min=0.0, range_max=float(settings.max_range), T_odom_sensor=T,
                                 timestamp=k * settings.frame_interval, ground_truth=pose.copy()))
    return LaserSequence(scene, settings, int(seed), poses, odom, true_alignments(poses, odom, 1.0), frames)
