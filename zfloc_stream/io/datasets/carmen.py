"""Carmen laser logs (plain or gzipped): FLASER and ROBOTLASER1 lines.

Field layouts (whitespace separated):

  FLASER n r_1..r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp
  ROBOTLASER1 laser_type start_angle fov angular_res max_range accuracy remission_mode
              n r_1..r_n n_rem rem_1..rem_nrem laser_x laser_y laser_theta
              robot_x robot_y robot_theta tv rv forward_safety side_safety turn_axis
              timestamp host logger_timestamp

FLASER beams: n beams over settings.datasets.carmen.flaser_fov_deg (180) starting at
flaser_start_deg (-90), i.e. an increment of fov / n (1 deg for 180 beams). The logged
laser pose (x y theta) is the ground truth (a corrected log); the localizer never sees
it: frames carry odometry re-chained from its relative motion, with seeded synthetic
drift, from a random origin. Other line types (ODOM, PARAM, NEFF, comments...) are
ignored; malformed laser lines are skipped and counted in one warning. A file without
any laser line is an InputError.
"""

from __future__ import annotations

import gzip
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...settings.loading import CarmenSettings, Settings
from ...errors import InputError
from ...frames import LaserFrame
from .base import Sequence, odometry_rng, planar_pose_matrix, register, synthetic_odometry

GZIP_MAGIC = b"\x1f\x8b"
LASER_TYPES = ("FLASER", "ROBOTLASER1")
CARMEN_WORDS = (b"FLASER", b"ROBOTLASER1", b"ODOM", b"PARAM", b"RLASER", b"TRUEPOS", b"SYNC", b"NEFF", b"RAWLASER")


@dataclass(frozen=True)
class CarmenLog:
    """All laser scans of a log, in file order."""

    path: Path
    ranges: list[np.ndarray]  # per scan (n_i,) metres
    angle_min: np.ndarray  # (N,) rad
    angle_increment: np.ndarray  # (N,) rad
    max_range: np.ndarray  # (N,) m, readings at or beyond are no-returns
    poses: np.ndarray  # (N, 3) logged laser pose (ground truth of a corrected log)
    timestamps: np.ndarray  # (N,)
    skipped: int  # malformed laser lines skipped

    def __len__(self) -> int:
        return len(self.ranges)


def open_text(path: Path):
    """Text handle on a plain or gzipped file (decided by content, not by suffix)."""
    try:
        with open(path, "rb") as f:
            magic = f.read(2)
    except OSError as err:
        raise InputError(f"cannot read {path}: {err.strerror}") from None
    if magic == GZIP_MAGIC:
        return gzip.open(path, "rt", errors="replace")
    return open(path, errors="replace")


def looks_like_carmen(head: bytes) -> bool:
    """True when the first bytes of a (decompressed) file hold Carmen message lines."""
    lines = head.splitlines()
    return any(line.split(b" ", 1)[0] in CARMEN_WORDS for line in lines)


def _floats(tokens: list[str]) -> np.ndarray:
    return np.array([float(t) for t in tokens])


def _parse_flaser(tokens: list[str], cfg) -> tuple:
    n = int(tokens[1])
    if n <= 0 or len(tokens) < 2 + n + 7:
        raise ValueError(f"FLASER with {n} beams needs {2 + n + 7} fields, has {len(tokens)}")
    ranges = _floats(tokens[2 : 2 + n])
    x, y, theta, _, _, _, stamp = _floats(tokens[2 + n : 2 + n + 7])
    fov = np.deg2rad(cfg.flaser_fov_deg)
    return ranges, np.deg2rad(cfg.flaser_start_deg), fov / n, cfg.max_range, (x, y, theta), stamp


def _parse_robotlaser(tokens: list[str], cfg) -> tuple:
    start, _fov, res, max_range = _floats(tokens[2:6])
    n = int(tokens[8])
    if n <= 0 or len(tokens) < 9 + n + 1:
        raise ValueError(f"ROBOTLASER1 with {n} beams is truncated")
    ranges = _floats(tokens[9 : 9 + n])
    n_rem = int(tokens[9 + n])
    tail = 9 + n + 1 + max(n_rem, 0)
    if n_rem < 0 or len(tokens) < tail + 12:
        raise ValueError("ROBOTLASER1 remissions or poses are truncated")
    x, y, theta = _floats(tokens[tail : tail + 3])
    stamp = float(tokens[tail + 11])
    if not (max_range > 0):
        max_range = cfg.max_range
    return ranges, start, res, max_range, (x, y, theta), stamp


def read_carmen(path, settings: Settings | None = None) -> CarmenLog:
    """Parse every FLASER / ROBOTLASER1 line of a Carmen log."""
    path = Path(path)
    cfg = (settings if settings is not None else Settings()).datasets.carmen
    if not path.is_file():
        raise InputError(f"Carmen log not found: {path}")
    ranges, amin, ainc, rmax, poses, stamps = [], [], [], [], [], []
    skipped, first_problem = 0, ""
    with open_text(path) as handle:
        try:
            for line_no, line in enumerate(handle, start=1):
                tokens = line.split()
                if not tokens or tokens[0] not in LASER_TYPES:
                    continue
                try:
                    parse = _parse_flaser if tokens[0] == "FLASER" else _parse_robotlaser
                    r, a0, da, mr, pose, stamp = parse(tokens, cfg)
                    if not (np.isfinite(pose).all() and np.isfinite([a0, da, mr, stamp]).all() and da != 0):
                        raise ValueError("non-finite pose, angles or timestamp")
                except (ValueError, IndexError) as err:
                    skipped += 1
                    first_problem = first_problem or f"line {line_no}: {err}"
                    continue
                ranges.append(r)
                amin.append(a0)
                ainc.append(da)
                rmax.append(mr)
                poses.append(pose)
                stamps.append(stamp)
        except (OSError, EOFError, UnicodeDecodeError) as err:  # truncated / corrupt gzip
            raise InputError(f"cannot read Carmen log {path}: {err}") from None
    if skipped:
        warnings.warn(f"{path}: skipped {skipped} malformed laser line(s) (first: {first_problem})", stacklevel=2)
    if not ranges:
        raise InputError(f"{path}: no FLASER or ROBOTLASER1 scan found (not a Carmen laser log?)")
    return CarmenLog(
        path=path,
        ranges=ranges,
        angle_min=np.array(amin),
        angle_increment=np.array(ainc),
        max_range=np.array(rmax),
        poses=np.array(poses, dtype=float),
        timestamps=np.array(stamps, dtype=float),
        skipped=skipped,
    )


@lru_cache(maxsize=4)
def _cached_log(path: str, mtime: float, cfg: CarmenSettings) -> CarmenLog:
    return read_carmen(path, Settings(datasets={"carmen": cfg}))


def load_log(path, settings: Settings) -> CarmenLog:
    """read_carmen, memoised per process (a study worker parses a log once)."""
    path = Path(path)
    try:
        mtime = path.stat().st_mtime
    except OSError:
        raise InputError(f"Carmen log not found: {path}") from None
    return _cached_log(str(path.resolve()), mtime, settings.datasets.carmen)


def carmen_sequence(path, settings: Settings, floorplan=None, odometry_noise: float | None = None) -> Sequence:
    """A Carmen log as one laser Sequence. Without a floorplan, the map is built from the
    log itself (map-from-log); floorplan_for(start, stop) then leaves that window out
    (+- datasets.carmen.heldout_margin scans), so a study never localizes a window against
    walls drawn from its own scans."""
    from ...plans.map_from_log import map_from_log

    log = load_log(path, settings)
    name = Path(path).name
    odom = synthetic_odometry(log.poses, settings.datasets.odometry, odometry_rng(settings, name), noise=odometry_noise)
    cfg = settings.datasets.carmen

    def frames(start: int, stop: int):
        for i in range(start, stop):
            yield LaserFrame(
                ranges=log.ranges[i],
                angle_min=float(log.angle_min[i]),
                angle_increment=float(log.angle_increment[i]),
                range_min=cfg.min_range,
                range_max=float(log.max_range[i]),
                T_odom_sensor=planar_pose_matrix(*odom[i]),
                timestamp=float(log.timestamps[i]),
                ground_truth=log.poses[i].copy(),
            )

    window_floorplan = None
    if floorplan is None:
        margin = cfg.heldout_margin

        @lru_cache(maxsize=8)  # the seeds of one window share its map
        def window_floorplan(start: int, stop: int):
            return map_from_log(log, [(start - margin, stop + margin)], settings)

        floorplan = lambda: map_from_log(log, [], settings)  # noqa: E731 (lazy factory)
    return Sequence(
        name=name,
        frame_source=frames,
        n_frames=len(log),
        ground_truth=log.poses,
        floorplan=floorplan,
        settings_overrides={"estimator": {"scale_mode": "fixed"}},  # a laser measures metres
        window_floorplan=window_floorplan,
        source=f"carmen:{path}",
    )


CARMEN_SUFFIXES = (".log", ".log.gz", ".clf", ".clf.gz")


def _carmen_paths(arg: str) -> list[Path]:
    """A log, or every Carmen log in a directory (sorted, so a study's cells are stable)."""
    path = Path(arg)
    if not path.is_dir():
        return [path]
    logs = sorted(p for p in path.iterdir() if p.is_file() and p.name.endswith(CARMEN_SUFFIXES))
    if not logs:
        raise InputError(f"{path}: no Carmen log ({', '.join(CARMEN_SUFFIXES)}) in this directory")
    return logs


@register("carmen")
def load_carmen(args: str, settings: Settings) -> list[Sequence]:
    """carmen:/path/log[.gz] (several separated by commas), or carmen:DIR for every log in
    DIR: `carmen:../shared/data/carmen` is the real-building benchmark's five buildings."""
    return [carmen_sequence(p, settings) for a in args.split(",") if a for p in _carmen_paths(a)]
