"""Datasets: one loader per format behind a tiny registry.

    open_dataset("sim:apartment,office")            built-in simulated scenes
    open_dataset("gibson:/data/gibson_t:test")      Gibson(t) (F3Loc release), a split or one scene
    open_dataset("carmen:/data/intel.log.gz")       Carmen laser log(s)
    open_dataset("mcap:/runs/session.mcap")         recorded MCAP session(s)
    open_dataset("ros2:/bags/run1.mcap")            ROS 2 bag(s) (rosbag2 MCAP)

Each returns a list of Sequence (base.py). `detect_source(path)` picks the loader by the
file's content for `zfloc-stream run --input`.
"""

from __future__ import annotations

import gzip
from pathlib import Path

from ...settings.loading import Settings
from ...errors import InputError
from . import carmen, gibson, mcap, ros2, sim  # noqa: F401 (registers the loaders)
from .base import Sequence, known_kinds, open_dataset, register, synthetic_odometry

MCAP_MAGIC = b"\x89MCAP"
HEAD_BYTES = 65536  # enough to get past a long comment header

__all__ = ["Sequence", "detect_source", "known_kinds", "open_dataset", "register", "synthetic_odometry"]


def _head(path: Path) -> bytes:
    """First bytes of a file, decompressed when it is gzipped."""
    try:
        with open(path, "rb") as f:
            head = f.read(HEAD_BYTES)
        if head[:2] == carmen.GZIP_MAGIC:
            with gzip.open(path, "rb") as f:
                head = f.read(HEAD_BYTES)
    except (OSError, EOFError) as err:
        raise InputError(f"cannot read input {path}: {err}") from None
    return head


def detect_source(
    path,
    floorplan=None,
    odometry_noise: float | None = None,
    seed: int | None = None,
    settings: Settings | None = None,
    topics: dict[str, str] | None = None,
    salvage: bool = False,
) -> Sequence:
    """One Sequence from a path, recognised by content: an MCAP session (magic bytes), a
    Gibson(t) scene folder (map.png + poses.txt + depth40.txt), or a Carmen log, plain or
    gzipped (FLASER / ROBOTLASER1 lines). odometry_noise: synthetic drift fraction for
    sources whose poses are ground truth (None: settings.datasets.odometry.noise). An MCAP
    file with ROS 2 (CDR) channels is read as a ROS 2 bag; topics: its role -> topic overrides.
    salvage: an MCAP session cut off or damaged is read as far as its intact chunks go."""
    settings = settings if settings is not None else Settings()
    if seed is not None:
        settings = settings.model_copy(update={"seed": int(seed)})
    path = Path(path)
    if not path.exists():
        raise InputError(f"input not found: {path}")
    if path.is_dir():
        if gibson.is_scene_dir(path):
            return gibson.scene_sequence(path, settings, floorplan=floorplan, odometry_noise=odometry_noise)
        sessions = sorted(path.glob("*.mcap"))
        if sessions:  # a session folder (session.mcap + map.yaml + gt.csv): name the file
            raise InputError(f"{path} is a folder: give the session file itself: --input {sessions[0]}")
        raise InputError(f"{path} is a folder but not a Gibson(t) scene (needs {', '.join(gibson.SCENE_FILES)}) "
                         "and holds no session .mcap")
    head = _head(path)
    if head.startswith(MCAP_MAGIC) and odometry_noise is not None:  # recorded odometry: no synthetic drift to set
        raise InputError(f"--odometry-noise applies to Carmen logs and Gibson(t) scenes, whose odometry is made from "
                         f"ground truth; {path} is an MCAP file with its own odometry")
    if head.startswith(MCAP_MAGIC) and ros2.is_ros2_mcap(path):
        return ros2.bag_sequence(path, settings, floorplan=floorplan, topics=topics)
    if topics:
        raise InputError(f"--topic applies to ROS 2 bags only; {path} is not one")
    if head.startswith(MCAP_MAGIC):
        return mcap.session_sequence(path, settings, floorplan=floorplan, salvage=salvage)
    if carmen.looks_like_carmen(head):
        return carmen.carmen_sequence(path, settings, floorplan=floorplan, odometry_noise=odometry_noise)
    raise InputError(f"unrecognised input {path}: not an MCAP session, a Gibson(t) scene folder or a Carmen log")
