"""The consistency monitor: does the tracked alignment explain what the sensor sees now?

Rounds come every k frames; a kidnapped robot, a slipped wheel or a wrong mode that won a
round shows up sooner, in the frames' own wall hits. Each fused frame with at least
localizer.monitor_min_points wall hits is judged against an alignment: consistent when at
least monitor_min_consistency of its hits (monitor_max_points of them, evenly
subsampled) lie within monitor_distance metres of a floorplan wall. While the tracker
reports `tracking`, monitor_frames inconsistent frames in a row ask the next round for a
full global search (the scheduler keeps the request until a round started after it lands).

The same per-frame judgement withholds `tracking` from a single frame the alignment does
not explain (FRAME_UNEXPLAINED, tracking/status.py): the monitor and the estimate ask about the same frame
and alignment, so the share is computed once.

What a right alignment explains depends on the map: a plan of walls only explains a
frame's wall hits but not the furniture, a dense map made from other passes explains
nearly all of them, and a wrong alignment on such a map still explains 10-60% (the Carmen
self-maps after a kidnap). So a frame is also judged against the tracked mode's own usual
share, the median over its last monitor_reference_frames consistent frames: below
monitor_relative_share of it, the frame is inconsistent too. Once a frame is inconsistent,
the next ones are reported consistent (may be `tracking`) only from monitor_recovery_share
of the usual share: a sensor turned or carried off in a dense building (rooms off a
corridor) still has half its hits near some wall, and a frame at 0.58 of the usual share
after one at 0.43 is the same wrong place, not a recovered one (the built-in `rooms` walk
after a 30 deg odometry jump: four `tracking` frames 1.4-1.8 m off at 0.57-0.66). The run
that starts a kidnap test counts at the normal bar: the doubt changes what is reported,
not what is searched (with it there too, a camera window of the shared buildings failed).
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..estimation.local_refinement import explained_share
from ..plans.floorplan import Floorplan
from ..settings.localizer import LocalizerSettings
from ..geometry.sim2 import Sim2


# a usual share needs this many consistent frames of the mode: a median of fewer is one
# frame's accident
REFERENCE_MIN_FRAMES = 5


class ConsistencyMonitor:
    def __init__(self, floorplan: Floorplan, settings: LocalizerSettings):
        self.floorplan = floorplan
        self.settings = settings
        self.inconsistent_frames = 0  # consecutive judged frames the tracked alignment did not explain
        self._memo: tuple | None = None  # (alignment, hits, share) of the last judgement
        self._usual: deque[float] = deque(maxlen=settings.monitor_reference_frames)  # shares of the tracked mode's consistent frames
        self._usual_mode: int | None = None  # the mode they belong to
        self._doubting = False  # the last judged frame of the tracked mode was inconsistent: the higher bar holds

    def share(self, alignment: Sim2, hits: np.ndarray) -> float | None:
        """The share of the frame's wall hits (plane frame) the alignment explains; None:
        too few hits to judge."""
        cfg = self.settings
        if len(hits) < cfg.monitor_min_points:
            return None
        memo = self._memo
        if memo is None or memo[0] is not alignment or memo[1] is not hits:
            share = explained_share(self.floorplan, alignment, hits[:: max(1, len(hits) // cfg.monitor_max_points)],
                                    cfg.monitor_distance)
            self._memo = memo = (alignment, hits, share)
        return memo[2]

    def usual_share(self, mode_id: int | None) -> float | None:
        """The mode's usual share (median over its recent consistent frames); None while it
        has fewer than REFERENCE_MIN_FRAMES of them."""
        if mode_id is None or mode_id != self._usual_mode or len(self._usual) < REFERENCE_MIN_FRAMES:
            return None
        return float(np.median(self._usual))

    def frame_consistent(self, alignment: Sim2, hits: np.ndarray, mode_id: int | None = None) -> bool | None:
        """Does the alignment (of the mode mode_id, if known) explain the frame's wall hits
        (plane frame)? None: too few hits to judge."""
        share = self.share(alignment, hits)
        if share is None:
            return None
        # after an inconsistent frame of the tracked mode, the higher bar (what is reported only)
        bar = self.settings.monitor_recovery_share if self._doubting else None
        return self.explains(share, self.usual_share(mode_id), bar)

    def explains(self, share: float, usual: float | None, bar: float | None = None) -> bool:
        """The monitor's test: a share at least monitor_min_consistency and at least `bar`
        (default monitor_relative_share) of the usual share (when one is known)."""
        bar = self.settings.monitor_relative_share if bar is None else bar
        relative = usual is None or share >= bar * usual
        return bool(share >= self.settings.monitor_min_consistency and relative)

    def wants_global_search(self, tracked_mode_id: int | None, alignment: Sim2 | None, hits: np.ndarray) -> bool:
        """Judge one fused frame against the tracked mode's alignment (None: nothing is
        tracked); True when the run of inconsistent frames reaches monitor_frames (the run
        then starts again). A consistent frame adds to the mode's usual share."""
        if tracked_mode_id != self._usual_mode:
            self._usual.clear()
            self._usual_mode = tracked_mode_id
            self._doubting = False
        share = None if tracked_mode_id is None else self.share(alignment, hits)
        if share is None:
            return False
        usual = self.usual_share(tracked_mode_id)
        # the run and the usual share count frames at the normal bar (what starts a kidnap
        # test is unchanged); the doubt only withholds `tracking` (frame_consistent)
        consistent = self.explains(share, usual)
        self._doubting = not self.explains(share, usual, self.settings.monitor_recovery_share) if self._doubting else not consistent
        if consistent:
            self._usual.append(share)
        self.inconsistent_frames = 0 if consistent else self.inconsistent_frames + 1
        if self.inconsistent_frames >= self.settings.monitor_frames:
            self.inconsistent_frames = 0
            return True
        return False
