"""Gibson(t) as released with F3Loc.

Layout: ROOT/split.yaml (train / val / test scene lists) and per scene ROOT/SCENE/ with
  map.png     walls dark, 0.01 m/px; (x, y) at column x/0.01 + W/2, row y/0.01 + H/2
  poses.txt   one 'x y theta' per frame (metres, radians, in that map frame)
  depth40.txt one line of 40 depths per frame: z-depth (along the optical axis, not ray
              length) at 40 equally spaced columns, left to right; focal length = 3/8 of
              the image width (~106 deg horizontal fov); upright camera
  rgb/NNNNN.png (not read here)
ROOT may also be a folder holding `gibson_t/` (the F3Loc download).

Each frame becomes a CameraFrame whose depth image is synthesised from the 40 depths:
40 columns x `image_rows` rows, K with fx = fy = focal_fraction * 40 px, principal point
at the centre ((W-1)/2, (H-1)/2 as F3Loc's ray code). The data has no camera or ceiling
height, so two ASSUMPTIONS (settings.datasets.gibson) complete the geometry: the camera
sits `camera_height` above a flat floor and the ceiling is `wall_height` high. For every
pixel the ray meets the floor (below the horizon), the ceiling (above) or the column's
wall at its logged z-depth, whichever comes first; pixels are labelled floor / ceiling /
wall accordingly and get the z-depth of that surface. Walls therefore enter the BEV at
exactly the logged depths; the floor only serves gravity estimation. A column whose depth
is missing (<= 0 or not finite) is left without readings.

The camera pose is upright at `camera_height` (z up, floor at z = 0) with odometry made
from the relative motion of poses.txt (synthetic drift, random origin; see
base.synthetic_odometry): the localizer never receives an absolute pose. Timestamps are
frame indices (Gibson(t) has none).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ...settings.loading import GibsonSettings, Settings
from ...errors import InputError
from ...frames import CEILING, FLOOR, WALL, CameraFrame
from .base import Sequence, odometry_rng, register, synthetic_odometry, upright_camera_matrix

N_COLUMNS = 40
SCENE_FILES = ("map.png", "poses.txt", "depth40.txt")
SPLITS = ("train", "val", "test")


def is_scene_dir(path: Path) -> bool:
    return path.is_dir() and all((path / f).is_file() for f in SCENE_FILES)


def _read_table(path: Path, columns: int) -> np.ndarray:
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"cannot read {path}: {err}") from None
    rows = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            values = [float(v) for v in line.split()]
        except ValueError:
            raise InputError(f"{path}:{number}: expected {columns} numbers, got {line.strip()[:60]!r}") from None
        if len(values) != columns:
            raise InputError(f"{path}:{number}: expected {columns} numbers, got {len(values)}")
        rows.append(values)
    if not rows:
        raise InputError(f"{path} holds no frame")
    return np.array(rows, dtype=float)


def camera_model(cfg: GibsonSettings) -> np.ndarray:
    f = cfg.focal_fraction * N_COLUMNS
    return np.array([[f, 0.0, (N_COLUMNS - 1) / 2], [0.0, f, (cfg.image_rows - 1) / 2], [0.0, 0.0, 1.0]])


def synthesize_image(z_depths: np.ndarray, cfg: GibsonSettings) -> tuple[np.ndarray, np.ndarray]:
    """(depth (R, 40) float32 metres, labels (R, 40) uint8) from one frame's 40 z-depths."""
    K = camera_model(cfg)
    z_wall = np.asarray(z_depths, dtype=float).reshape(1, N_COLUMNS)
    slope = ((np.arange(cfg.image_rows) - K[1, 2]) / K[1, 1]).reshape(-1, 1)  # y/z of each row, + = down
    with np.errstate(divide="ignore"):
        z_floor = np.where(slope > 0, cfg.camera_height / slope, np.inf)
        z_ceiling = np.where(slope < 0, (cfg.wall_height - cfg.camera_height) / -slope, np.inf)
    depth = np.broadcast_to(z_wall, (cfg.image_rows, N_COLUMNS)).copy()
    labels = np.full(depth.shape, WALL, dtype=np.uint8)
    floor = np.broadcast_to(z_floor < z_wall, depth.shape)
    ceiling = np.broadcast_to(z_ceiling < z_wall, depth.shape)
    depth[floor] = np.broadcast_to(z_floor, depth.shape)[floor]
    labels[floor] = FLOOR
    depth[ceiling] = np.broadcast_to(z_ceiling, depth.shape)[ceiling]
    labels[ceiling] = CEILING
    missing = np.broadcast_to(~(np.isfinite(z_wall) & (z_wall > 0)), depth.shape)
    depth[missing] = 0.0
    return depth.astype(np.float32), labels


def scene_sequence(scene_dir, settings: Settings, floorplan=None, odometry_noise: float | None = None) -> Sequence:
    """One Gibson(t) scene folder as a camera Sequence."""
    from ...plans.floorplan import Floorplan

    scene_dir = Path(scene_dir)
    if not is_scene_dir(scene_dir):
        missing = [f for f in SCENE_FILES if not (scene_dir / f).is_file()]
        raise InputError(f"{scene_dir} is not a Gibson(t) scene folder (missing {', '.join(missing)})")
    cfg = settings.datasets.gibson
    truth = _read_table(scene_dir / "poses.txt", 3)
    depths = _read_table(scene_dir / "depth40.txt", N_COLUMNS)
    if len(depths) < len(truth):
        raise InputError(f"{scene_dir}: depth40.txt has {len(depths)} frames but poses.txt {len(truth)}")
    n = len(truth)
    odom = synthetic_odometry(truth, settings.datasets.odometry, odometry_rng(settings, scene_dir.name), noise=odometry_noise)
    K = camera_model(cfg)

    def frames(start: int, stop: int):
        for i in range(start, stop):
            depth, labels = synthesize_image(depths[i], cfg)
            yield CameraFrame(
                depth=depth,
                labels=labels,
                K=K,
                T_odom_cam=upright_camera_matrix(*odom[i], cfg.camera_height),
                timestamp=float(i),
                ground_truth=truth[i].copy(),
            )

    if floorplan is None:
        floorplan = lambda: Floorplan.from_gibson_map(scene_dir / "map.png", settings)  # noqa: E731 (lazy)
    return Sequence(
        name=scene_dir.name,
        frame_source=frames,
        n_frames=n,
        ground_truth=truth,
        floorplan=floorplan,
        # paper: Gibson has linear walls only, so the line solvers; 40 columns: use every pixel
        settings_overrides={"estimator": {"solvers": {"pool": ["3L", "2L"]}}, "frontend": {"pixel_stride": 1}},
        source=f"gibson:{scene_dir}",
    )


def _split_args(args: str, default_split: str) -> tuple[Path, str | None]:
    """'ROOT[:SPLIT]' -> (root, split); a split is recognised only by name."""
    head, sep, tail = args.rpartition(":")
    if sep and tail in SPLITS:
        return Path(head), tail
    return Path(args), None


def scene_dirs(root: Path, split: str | None, default_split: str) -> list[Path]:
    if is_scene_dir(root):
        return [root]
    if not root.is_dir():
        raise InputError(f"Gibson(t) root not found: {root}")
    if not (root / "split.yaml").is_file() and (root / "gibson_t" / "split.yaml").is_file():
        root = root / "gibson_t"
    split_file = root / "split.yaml"
    if not split_file.is_file():
        if split is not None:
            raise InputError(f"{root}: no split.yaml, cannot select split '{split}'")
        scenes = sorted(p for p in root.iterdir() if is_scene_dir(p))
        if not scenes:
            raise InputError(f"{root} holds neither split.yaml nor Gibson(t) scene folders")
        return scenes
    try:
        splits = yaml.safe_load(split_file.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise InputError(f"cannot read {split_file}: {str(err).splitlines()[0]}") from None
    split = split or default_split
    if not isinstance(splits, dict) or split not in splits:
        raise InputError(f"{split_file}: no '{split}' scene list")
    names = splits[split] or []
    if not isinstance(names, list):
        raise InputError(f"{split_file}: '{split}' must be a list of scene names")
    return [root / str(name) for name in names]


@register("gibson")
def load_gibson(args: str, settings: Settings) -> list[Sequence]:
    """gibson:ROOT[:train|val|test] (default split: settings.datasets.gibson.split), or
    gibson:SCENE_DIR for one scene."""
    root, split = _split_args(args, settings.datasets.gibson.split)
    return [scene_sequence(d, settings) for d in scene_dirs(root, split, settings.datasets.gibson.split)]
