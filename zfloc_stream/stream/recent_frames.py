"""The recent frames: what each of the last localizer.local_frames fused frames left behind,
one record per frame. The local refinement fits the tracked mode on their wall hits; the
kidnap test and the audit judge places on them; the largest contradiction among them says
whether the sensor was carried off (recovery.py)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RecentFrame:
    hits: np.ndarray  # its wall hits in the odometry plane (RollingBEV.last_wall_hits)
    camera: np.ndarray  # (2,) its sensor position in the odometry plane
    contradiction: float  # how much it contradicted what older frames saw (RollingBEV.last_contradiction)


class RecentFrames:
    def __init__(self, length: int):
        self._frames: deque[RecentFrame] = deque(maxlen=max(1, length))

    def add(self, hits: np.ndarray, camera: np.ndarray, contradiction: float) -> None:
        self._frames.append(RecentFrame(hits, camera, contradiction))

    def clear(self) -> None:
        self._frames.clear()

    @property
    def hits(self) -> list[np.ndarray]:
        """Each frame's wall hits, oldest first."""
        return [f.hits for f in self._frames]

    @property
    def cameras(self) -> list[np.ndarray]:
        """Each frame's sensor position, oldest first."""
        return [f.camera for f in self._frames]

    @property
    def contradiction(self) -> float:
        """The most any of them contradicted what older frames saw (0 without frames)."""
        return max((f.contradiction for f in self._frames), default=0.0)

    def all_hits(self) -> np.ndarray | None:
        """Their wall hits in one array; None when none has any."""
        hits = [f.hits for f in self._frames if len(f.hits)]
        return np.concatenate(hits) if hits else None
