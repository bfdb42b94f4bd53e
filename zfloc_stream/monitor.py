"""The consistency monitor: does the tracked alignment explain what the sensor sees now?

Rounds come every k frames; a kidnapped robot, a slipped wheel or a wrong mode that won a
round shows up sooner, in the frames' own wall hits. Each fused frame with at least
localizer.monitor_min_points wall hits is judged against an alignment: consistent when at
least monitor_min_consistency of its hits (monitor_max_points of them, evenly
subsampled) lie within monitor_distance metres of a floorplan wall. While the tracker
reports `tracking`, monitor_frames inconsistent frames in a row ask the next round for a
full global search (the scheduler keeps the request until a round started after it lands).

The same per-frame judgement withholds `tracking` from a single frame the alignment does
not explain (tracking.assess_frame): the monitor and the estimate ask about the same frame
and alignment, so the share is computed once.
"""

from __future__ import annotations

import numpy as np

from .estimation.local_refinement import explained_share
from .floorplan import Floorplan
from .settings.localizer import LocalizerSettings
from .sim2 import Sim2


class ConsistencyMonitor:
    def __init__(self, floorplan: Floorplan, settings: LocalizerSettings):
        self.floorplan = floorplan
        self.settings = settings
        self.inconsistent_frames = 0  # consecutive judged frames the tracked alignment did not explain
        self._memo: tuple | None = None  # (alignment, hits, share) of the last judgement

    def frame_consistent(self, alignment: Sim2, hits: np.ndarray) -> bool | None:
        """Does the alignment explain the frame's wall hits (plane frame)? None: too few
        hits to judge."""
        cfg = self.settings
        if len(hits) < cfg.monitor_min_points:
            return None
        memo = self._memo
        if memo is not None and memo[0] is alignment and memo[1] is hits:
            share = memo[2]
        else:
            share = explained_share(self.floorplan, alignment, hits[:: max(1, len(hits) // cfg.monitor_max_points)],
                                    cfg.monitor_distance)
            self._memo = (alignment, hits, share)
        return bool(share >= cfg.monitor_min_consistency)

    def wants_global_search(self, tracking: bool, alignment: Sim2 | None, hits: np.ndarray) -> bool:
        """Judge one fused frame against the tracked alignment (tracking: the tracker's
        status is `tracking`); True when the run of inconsistent frames reaches
        monitor_frames (the run then starts again)."""
        consistent = self.frame_consistent(alignment, hits) if tracking else None
        if consistent is None:
            return False
        self.inconsistent_frames = 0 if consistent else self.inconsistent_frames + 1
        if self.inconsistent_frames >= self.settings.monitor_frames:
            self.inconsistent_frames = 0
            return True
        return False
