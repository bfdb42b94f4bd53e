"""What every loader returns (a Sequence), the tiny registry behind `open_dataset`, and the
synthetic odometry shared by the loaders whose logged poses are ground truth.

A Sequence is cheap to make: frames are produced lazily by `frames(start, stop)` (a fresh
iterator each call) and the floorplan is built on first use, so a study worker that needs
frames 200-235 of one sequence pays only for those.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING

import numpy as np

from ...settings.loading import OdometrySettings, Settings
from ...errors import InputError
from ...runtime.rng import make_rng
from ...geometry.sim2 import wrap_angle

if TYPE_CHECKING:
    from ...plans.floorplan import Floorplan
    from ...frames import Frame

FrameSource = Callable[[int, int], Iterator["Frame"]]


class Sequence:
    """One trajectory with its floorplan and per-frame ground truth.

    name: unique within its dataset. frames(start, stop): fresh iterator over frames
    [start, stop), each carrying ground_truth. n_frames: length. ground_truth: (n, 3)
    x, y, theta in the floorplan frame (NaN rows where unknown), given as an array or a
    factory (built on first use). floorplan: a Floorplan or a factory (built on first
    use). window_floorplan: optional factory (start, stop) -> Floorplan for loaders whose
    map is built from the same log and must leave a window out (Carmen held-out maps).
    settings_overrides: what this source needs on top of the defaults (e.g. a laser:
    fixed scale); user settings still win over it. needs_depth_network: its camera
    frames are RGB only (a depth network must fill in depth).
    """

    def __init__(
        self,
        name: str,
        frame_source: FrameSource,
        n_frames: int,
        ground_truth: np.ndarray | Callable[[], np.ndarray],
        floorplan: Floorplan | Callable[[], Floorplan] | None,
        settings_overrides: dict | None = None,
        window_floorplan: Callable[[int, int], Floorplan] | None = None,
        source: str = "",
        needs_depth_network: bool = False,
    ):
        self.name = name
        self._frame_source = frame_source
        self.n_frames = int(n_frames)
        self._ground_truth = ground_truth
        self._floorplan = floorplan
        self.settings_overrides = dict(settings_overrides or {})
        self._window_floorplan = window_floorplan
        self.source = source
        self.needs_depth_network = needs_depth_network
        self.topics: dict[str, str] = {}  # role -> topic read, for the sources that have topics
        self.floorplan_source: str | None = None  # where a floorplan nobody named comes from, said by `run`

    @property
    def ground_truth(self) -> np.ndarray:
        if callable(self._ground_truth):
            self._ground_truth = self._ground_truth()
        return np.asarray(self._ground_truth, dtype=float).reshape(-1, 3)

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[Frame]:
        stop = self.n_frames if stop is None else stop
        if not 0 <= start <= stop <= self.n_frames:
            raise InputError(f"sequence {self.name!r}: frame range [{start}, {stop}) outside [0, {self.n_frames})")
        return self._frame_source(start, stop)

    @property
    def floorplan(self) -> Floorplan:
        if self._floorplan is None:
            raise InputError(f"sequence {self.name!r} ({self.source}) has no floorplan: pass one (--floorplan)")
        if callable(self._floorplan):
            self._floorplan = self._floorplan()
        return self._floorplan

    def floorplan_for(self, start: int, stop: int) -> Floorplan:
        """The floorplan to localize frames [start, stop) against."""
        if self._window_floorplan is not None:
            return self._window_floorplan(start, stop)
        return self.floorplan

    def __repr__(self) -> str:
        return f"Sequence({self.name!r}, {self.n_frames} frames, source={self.source!r})"


# ---------------------------------------------------------------------------------------
# registry
# ---------------------------------------------------------------------------------------
Loader = Callable[[str, Settings], list[Sequence]]
_LOADERS: dict[str, Loader] = {}


def register(kind: str) -> Callable[[Loader], Loader]:
    """Decorator: `@register("gibson")` makes `open_dataset("gibson:...")` call the loader
    with the text after the colon and the settings."""

    def wrap(loader: Loader) -> Loader:
        _LOADERS[kind] = loader
        return loader

    return wrap


def known_kinds() -> list[str]:
    return sorted(_LOADERS)


def open_dataset(spec: str, settings: Settings | None = None) -> list[Sequence]:
    """Sequences named by a spec 'KIND:ARGS', e.g. 'sim:apartment,office',
    'gibson:/data/gibson_t:test', 'carmen:/data/intel.log.gz', 'mcap:/runs/session.mcap'."""
    kind, sep, rest = str(spec).partition(":")
    if not sep or not rest:
        raise InputError(f"dataset spec '{spec}' must look like KIND:ARGS (kinds: {', '.join(known_kinds())})")
    if kind not in _LOADERS:
        raise InputError(f"unknown dataset kind '{kind}' in '{spec}' (kinds: {', '.join(known_kinds())})")
    sequences = _LOADERS[kind](rest, settings if settings is not None else Settings())
    if not sequences:
        raise InputError(f"dataset '{spec}' holds no sequence")
    return sequences


# ---------------------------------------------------------------------------------------
# poses and synthetic odometry
# ---------------------------------------------------------------------------------------
def planar_pose_matrix(x: float, y: float, theta: float, z: float = 0.0) -> np.ndarray:
    """4x4 pose of a body with x forward, y left, z up at (x, y, z), heading theta."""
    c, s = np.cos(theta), np.sin(theta)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = (x, y, z)
    return T


def upright_camera_matrix(x: float, y: float, theta: float, height: float) -> np.ndarray:
    """4x4 pose of an upright OpenCV camera (x right, y down, z forward) looking along
    heading theta, `height` above the z = 0 floor."""
    c, s = np.cos(theta), np.sin(theta)
    T = np.eye(4)
    T[:3, 0] = (s, -c, 0.0)  # image right = heading - 90 deg
    T[:3, 1] = (0.0, 0.0, -1.0)  # image down = gravity
    T[:3, 2] = (c, s, 0.0)  # optical axis = heading
    T[:3, 3] = (x, y, height)
    return T


def synthetic_odometry(truth: np.ndarray, cfg: OdometrySettings, rng: np.random.Generator, noise: float | None = None) -> np.ndarray:
    """(n, 3) odometry poses from (n, 3) ground-truth poses.

    Only the relative motion of the truth survives: each step's body-frame motion gets
    Gaussian drift (translation std = noise * step length + translation_floor per axis,
    heading std = noise * (|turn| + heading_noise_per_m * step length) + heading_floor_deg;
    the floors only when noise > 0) and the chain starts from a
    random origin and heading, so no absolute pose leaks to the localizer.
    """
    truth = np.asarray(truth, dtype=float).reshape(-1, 3)
    noise = cfg.noise if noise is None else float(noise)
    if not np.isfinite(noise) or noise < 0:
        raise InputError(f"odometry noise must be a non-negative number, got {noise}")
    n = len(truth)
    origin = np.array([*rng.uniform(-cfg.origin_extent, cfg.origin_extent, 2), rng.uniform(-np.pi, np.pi)])
    if n == 0:
        return np.zeros((0, 3))
    # body-frame steps of the truth
    dp = np.diff(truth[:, :2], axis=0)
    c, s = np.cos(truth[:-1, 2]), np.sin(truth[:-1, 2])
    step = np.stack([c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1]], axis=1)
    turn = wrap_angle(np.diff(truth[:, 2]))
    length = np.linalg.norm(step, axis=1)
    # draws happen even at noise 0 so the origin does not depend on the noise level
    floor_xy = cfg.translation_floor if noise > 0 else 0.0
    floor_turn = np.deg2rad(cfg.heading_floor_deg) if noise > 0 else 0.0
    step = step + rng.standard_normal(step.shape) * (noise * length + floor_xy)[:, None]
    turn = turn + rng.standard_normal(turn.shape) * (noise * (np.abs(turn) + cfg.heading_noise_per_m * length) + floor_turn)
    # chain the noisy steps from the random origin
    heading = origin[2] + np.concatenate([[0.0], np.cumsum(turn)])
    c, s = np.cos(heading[:-1]), np.sin(heading[:-1])
    world_step = np.stack([c * step[:, 0] - s * step[:, 1], s * step[:, 0] + c * step[:, 1]], axis=1)
    xy = origin[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(world_step, axis=0)])
    return np.column_stack([xy, wrap_angle(heading)])


def odometry_rng(settings: Settings, source: str) -> np.random.Generator:
    """The odometry draws of one source depend on the settings seed and its name only."""
    return make_rng(settings.seed, "odometry", source)
