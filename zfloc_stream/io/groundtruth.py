"""Ground truth from a file, for any input (`zfloc-stream run --groundtruth FILE`).

Two formats, told apart by content:
- TUM (`timestamp tx ty tz qx qy qz qw`, e.g. evo's or our own groundtruth.tum): looked up
  at each frame's stamp, interpolated between rows like odometry (pose_interpolation; no
  answer outside the rows' span or across a gap longer than datasets.ros2.max_odometry_gap).
  The stamps a frame is looked up at are those trajectory.tum uses (tum.TumStamps: a
  repeated stamp moved 1 us on), so a groundtruth.tum written by a run fits the next run.
- CSV with a header holding x, y, theta (radians): with a `frame` column, row per input
  frame number; with a `timestamp` column, looked up like TUM; with neither, row i is
  input frame i (the layout of `gt.csv` beside the shared sessions).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .datasets.base import planar_pose_matrix
from ..errors import InputError
from ..geometry.pose_interpolation import PoseTrack
from .tum import read_tum


class GroundTruth:
    """at(frame_index, stamp) -> (x, y, theta) or None (unknown for that frame)."""

    def __init__(self, path: Path, by_frame: dict[int, np.ndarray] | None = None, track: PoseTrack | None = None,
                 stamps: tuple[float, float] | None = None):
        self.path = path
        self._by_frame = by_frame
        self._track = track
        self._stamps = stamps  # first and last stamp of a track's rows

    def coverage_note(self, frames: int, matched: int, kept: int, first_index: int, stamps: tuple[float, float]) -> str | None:
        """What a run whose `frames` frames (input numbers from first_index, stamps the first
        and last) got from this file: None when it gave a pose for each; else one line for
        a `warning:` (matched: frames it gave a pose for; kept: others that kept their own)."""
        if matched == frames or not frames:
            return None
        if self._by_frame is not None:
            rows = sorted(self._by_frame)
            its = f"its rows cover frames {rows[0]}-{rows[-1]}" if rows else "it holds no complete row"
            yours = f"the input's frames {first_index}-{first_index + frames - 1}"
        else:
            its = f"its stamps span {self._stamps[0]:.3f}-{self._stamps[1]:.3f} s" if self._stamps else "it holds no row"
            yours = f"the input's {stamps[0]:.3f}-{stamps[1]:.3f} s"
        own = f"; the input's own ground truth kept on {kept} other frames" if kept else ""
        if matched == 0:
            return (f"ground truth {self.path.name}: no pose for any of the {frames} frames ({its}, {yours})"
                    + (f"; not used: the input's own ground truth kept ({kept} frames)" if kept else "; no position errors"))
        return (f"ground truth {self.path.name}: a pose for {matched} of the {frames} frames ({its}, {yours}){own}"
                + ("; the errors and success figures cover only frames with ground truth" if matched + kept < frames else ""))

    def at(self, index: int, stamp: float) -> np.ndarray | None:
        if self._by_frame is not None:
            return self._by_frame.get(int(index))
        T, _reason = self._track.at(int(round(stamp * 1e9)))
        if T is None:
            return None
        return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def _track(path: Path, stamps, poses, max_gap: float | None) -> GroundTruth:
    track = PoseTrack(f"ground truth {path.name}", max_gap)
    for t, (x, y, th) in zip(stamps, poses):
        track.add(int(round(float(t) * 1e9)), planar_pose_matrix(x, y, th))
    span = (float(min(stamps)), float(max(stamps))) if len(stamps) else None
    return GroundTruth(path, track=track, stamps=span)


def _looks_like_tum(text: str) -> bool:
    for line in text.splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            try:
                return len([float(v) for v in line.split()]) == 8
            except ValueError:
                return False
    return False


def load_groundtruth(path: str | Path, max_gap: float | None = None) -> GroundTruth:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise InputError(f"cannot read ground truth {path}: {err.strerror or err}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: ground truth must be a TUM or CSV text file") from None
    if _looks_like_tum(text):
        stamps, poses = read_tum(path)
        return _track(path, stamps, poses, max_gap)
    rows = list(csv.DictReader(line for line in text.splitlines() if line.strip() and not line.startswith("#")))
    columns = {c.strip().lower(): c for c in (rows[0].keys() if rows else [])}
    missing = [c for c in ("x", "y", "theta") if c not in columns]
    if not rows or missing:
        raise InputError(f"{path}: ground truth must be a TUM file (timestamp tx ty tz qx qy qz qw) or a CSV with a "
                         f"header naming x, y, theta (+ optional frame or timestamp column)"
                         + (f"; missing {', '.join(missing)}" if rows and missing else ""))
    def number(text) -> float:  # an empty cell (no truth for that frame) reads as NaN
        return float(text) if text is not None and text.strip() else float("nan")

    try:
        poses = np.array([[number(r[columns[c]]) for c in ("x", "y", "theta")] for r in rows])
        if "frame" in columns:
            frames = [int(float(r[columns["frame"]])) for r in rows]
        elif "timestamp" in columns:
            stamps = [float(r[columns["timestamp"]]) for r in rows]
            return _track(path, stamps, poses, max_gap)
        else:
            frames = list(range(len(rows)))
    except (TypeError, ValueError):
        raise InputError(f"{path}: a ground-truth CSV row holds a value that is not a number") from None
    return GroundTruth(path, by_frame={f: p for f, p in zip(frames, poses) if np.isfinite(p).all()})
