"""TUM trajectory files (`timestamp tx ty tz qx qy qz qw`, one pose per line), the format
evo (`evo_traj tum FILE`, `evo_ape tum REF FILE`) and most SLAM tools read; and reading
them back (`read_tum`, for `run --groundtruth`).

The estimate is planar: z = 0 and the orientation is the yaw about the floorplan's z
axis. Frames without a pose (before the first hypothesis) are left out. evo needs strictly
increasing stamps, but real logs repeat them (Carmen logs print few digits; a session may
carry one stamp for every frame): such a frame is kept, written STEP seconds after the
row before it, and counted (`moved`), so no pose is lost and the caller can say how many
were moved. Every frame advances the stamps, posed or not, so two writers fed the same
frames (estimate and ground truth) give the same stamps and evo pairs them exactly.
Lines are flushed as they are written, like trajectory.csv. The comment lines start with
'#', which evo skips; fields are separated by one space with none trailing.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..estimate import Estimate

HEADER = (
    "# timestamp tx ty tz qx qy qz qw (zfloc-stream estimate in the floorplan frame; planar: z = 0, yaw only)\n"
    "# a frame whose input stamp does not increase is written 1 us after the row before it (evo needs increasing stamps)\n"
)
STEP = 1e-6  # s between frames that arrived with the same stamp: far below any sensor period


class TumStamps:
    """Strictly increasing output stamps from input stamps that may repeat or go back."""

    def __init__(self):
        self.last = -math.inf
        self.moved = 0

    def next(self, timestamp: float) -> float:
        t = float(timestamp)
        if t <= self.last:
            t = self.last + STEP
            if t <= self.last:  # at huge stamps STEP is below one ulp
                t = math.nextafter(self.last, math.inf)
            self.moved += 1
        self.last = t
        return t

def tum_line(timestamp: float, x: float, y: float, theta: float) -> str:
    half = 0.5 * theta
    values = (timestamp, x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half))
    return " ".join(repr(float(v)) for v in values) + "\n"


class TumWriter:
    """One TUM file. write(est) for estimates; write_pose(stamp, pose) for any planar pose
    (ground truth). Feed every frame, posed or not: the stamps advance per frame."""

    def __init__(self, path: str | Path, header: str = HEADER):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w")
        except OSError as err:
            raise InputError(f"cannot write TUM file {self.path}: {err.strerror or err}") from None
        self._file.write(header)
        self._stamps = TumStamps()
        self.rows = 0
        self.moved = 0  # rows written at a moved stamp (their input stamp did not increase)

    def write(self, est: Estimate) -> None:
        self.write_pose(est.timestamp, est.pose)

    def write_pose(self, timestamp: float, pose) -> None:
        if not math.isfinite(timestamp):
            return
        moved_before = self._stamps.moved
        stamp = self._stamps.next(timestamp)
        if pose is None or not all(math.isfinite(float(v)) for v in pose):
            return
        self._file.write(tum_line(stamp, *pose))
        self._file.flush()
        self.rows += 1
        self.moved += self._stamps.moved - moved_before

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def moved_note(path, moved: int, rows: int) -> str | None:
    """The one line that says how many rows sit at a moved stamp (None when none)."""
    if not moved:
        return None
    return (f"{path}: {moved} of {rows} rows had a timestamp that did not increase (repeated in the input); "
            f"kept, each {STEP * 1e6:g} us after the row before it")


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(stamps (n,), planar poses (n, 3) x, y, yaw) from a TUM file; yaw is taken about z
    from the quaternion (the heading of a planar pose)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise InputError(f"cannot read ground truth {path}: {err.strerror or err}") from None
    rows = []
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.replace(",", " ").split()
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise InputError(f"{path}:{number}: a TUM row is 8 numbers (timestamp tx ty tz qx qy qz qw)") from None
        if len(values) != 8:
            raise InputError(f"{path}:{number}: a TUM row is 8 numbers (timestamp tx ty tz qx qy qz qw), got {len(values)}")
        rows.append(values)
    if not rows:
        raise InputError(f"{path}: no TUM row (timestamp tx ty tz qx qy qz qw)")
    m = np.array(rows, dtype=float)
    qx, qy, qz, qw = m[:, 4], m[:, 5], m[:, 6], m[:, 7]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return m[:, 0], np.column_stack([m[:, 1], m[:, 2], yaw])


def export_session_tum(session_path, tum_path, salvage: bool = False) -> TumWriter:
    """The estimates logged in a session file as a TUM file; returns the closed writer
    (rows written, rows at a moved stamp). The stamps follow the same rule as a live run's
    trajectory.tum, so both files are equal. salvage: a file cut off or damaged is read as far
    as its intact chunks go."""
    from .session import read_session

    session = read_session(session_path, salvage=salvage)
    seen = 0
    with TumWriter(tum_path) as out:
        for record in session.records():
            est = record.outputs.estimate
            if est is not None:
                seen += 1
                out.write(est)
    if seen == 0:
        Path(tum_path).unlink(missing_ok=True)
        raise InputError(f"{session_path}: the session holds no logged estimates (/zfloc/status): localize it first with zfloc-stream run")
    return out
