"""TUM trajectory files (`timestamp tx ty tz qx qy qz qw`, one pose per line), the format
evo (`evo_traj tum FILE`, `evo_ape tum REF FILE`) and most SLAM tools read.

The estimate is planar: z = 0 and the orientation is the yaw about the floorplan's z
axis. Frames without a pose (before the first hypothesis) are left out, and so is a frame
whose timestamp does not increase (evo needs strictly ordered stamps). Lines are flushed
as they are written, like trajectory.csv. The one comment line starts with '#', which
evo skips; fields are separated by one space with none trailing.
"""

from __future__ import annotations

import math
from pathlib import Path

from .errors import InputError
from .estimate import Estimate

HEADER = "# timestamp tx ty tz qx qy qz qw (zfloc-stream estimate in the floorplan frame; planar: z = 0, yaw only)\n"


def tum_line(timestamp: float, x: float, y: float, theta: float) -> str:
    half = 0.5 * theta
    values = (timestamp, x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half))
    return " ".join(repr(float(v)) for v in values) + "\n"


class TumWriter:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "w")
        except OSError as err:
            raise InputError(f"cannot write TUM file {self.path}: {err.strerror or err}") from None
        self._file.write(HEADER)
        self._last = -math.inf
        self.rows = 0

    def write(self, est: Estimate) -> None:
        if est.pose is None or not all(math.isfinite(float(v)) for v in est.pose) or not math.isfinite(est.timestamp):
            return
        if est.timestamp <= self._last:
            return
        self._last = float(est.timestamp)
        self._file.write(tum_line(est.timestamp, *est.pose))
        self._file.flush()
        self.rows += 1

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def export_session_tum(session_path, tum_path, salvage: bool = False) -> int:
    """The estimates logged in a session file as a TUM file; returns the rows written.
    salvage: a file cut off or damaged is read as far as its intact chunks go."""
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
    return out.rows
