"""The odometry-jump watch: is a frame's step one the sensor could have made?

The tracker carries an alignment odometry -> floorplan; odometry that jumps (a VIO reset,
a wheel slip of metres, a relocalising SLAM front end) moves every later pose by the jump,
and the frames after it are fused into the BEV at the wrong place, on top of the old
ones. The monitor (monitor.py) sees the frames' hits stop fitting the floorplan, but only
once the hits are judged, and a BEV smeared by the jump can then confirm a wrong mode
(without this watch a 1 km jump was reported `tracking` 1 km off at confidence 1.0, a
3 m jump `tracking` 2.4-3 m off for over ten frames).

Each fused frame's step in the plane frame (metres and turn since the last accepted frame)
is compared with the recent motion and with what the BEV says of the frame's wall hits
(policy.odometry_jumped). A frame that fails is suspect: it is not `tracking`,
and the next fused frame decides. Back near the track before it (closer to it than to the
suspect frame): one bad reading, a spike (issue 29), and nothing restarts. Going on from
the suspect frame: the odometry jumped, and the localizer restarts the map and the
hypotheses there (the old map and alignment belong to the old odometry frame).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..tracking import policy
from ..settings.loading import Settings
from ..geometry.sim2 import wrap_angle

SUSPECT = "suspect"  # the frame is not `tracking`; the next frame decides
JUMPED = "jumped"  # the odometry jumped: restart the map and the hypotheses


class OdometryJumpWatch:
    def __init__(self, settings: Settings):
        self.settings = settings
        self._steps: deque[tuple[float, float]] = deque(maxlen=max(1, settings.tracking.odometry_jump_window))
        self._last: np.ndarray | None = None  # the last accepted fused frame's plane pose
        self._suspect: np.ndarray | None = None  # the suspect frame's plane pose, until the next frame decides

    def restart(self, plane_pose) -> None:
        """The map restarted at this frame (or recent motion is unknown): measured from here."""
        self._steps.clear()
        self._last = np.asarray(plane_pose, dtype=float).copy()
        self._suspect = None

    def judge(self, plane_pose, known_hits: int, contradiction: float, hits: int) -> tuple[str, str] | None:
        """Judge one fused frame (plane pose (x, y, yaw); known_hits and contradiction: its
        wall hits on cells older frames saw, and the share of those contradicting them,
        RollingBEV.last_known_hits / last_contradiction; hits: all its wall hits): None (a step the sensor made),
        (SUSPECT, why) or (JUMPED, why). Judged once odometry_jump_window steps are known;
        a suspect frame's step never enters the recent motion."""
        s = self.settings.tracking
        pose = np.asarray(plane_pose, dtype=float).copy()
        if self._last is None or s.odometry_jump_window == 0:
            self._last = pose
            return None
        if self._suspect is not None:
            suspect, self._suspect = self._suspect, None
            if self._reach(pose, self._last) < self._reach(pose, suspect):
                self._last = pose  # back on the track: the suspect frame was a spike
                return None
            return JUMPED, self._why(suspect, self._last, "map and hypotheses restarted")
        step, turn = _step(pose, self._last)
        if len(self._steps) < self._steps.maxlen:
            self._steps.append((step, turn))
            self._last = pose
            return None
        lc = self.settings.localizer
        explains = (known_hits >= max(lc.monitor_min_points, s.odometry_jump_min_known_share * hits)
                    and contradiction < s.odometry_jump_contradiction)
        recent_step, recent_turn = self._recent()
        if not policy.odometry_jumped(step, turn, recent_step, recent_turn, explains, s):
            self._steps.append((step, turn))
            self._last = pose
            return None
        self._suspect = pose
        return SUSPECT, self._why(pose, self._last, "hits unexplained by the map: not tracking until the next frame")

    def _recent(self) -> tuple[float, float]:
        return max(a for a, _ in self._steps), max(b for _, b in self._steps)

    def _reach(self, pose: np.ndarray, other: np.ndarray) -> float:
        """How far `pose` is from `other` in units of the rule's limits (step and turn)."""
        s = self.settings.tracking
        recent_step, recent_turn = self._recent()
        step, turn = _step(pose, other)
        step_limit = s.odometry_jump_min_step + s.odometry_jump_factor * recent_step
        turn_limit = math.radians(s.odometry_jump_min_turn_deg) + s.odometry_jump_factor * recent_turn
        return step / max(step_limit, 1e-9) + turn / max(turn_limit, 1e-9)

    def _why(self, pose: np.ndarray, last: np.ndarray, then: str) -> str:
        step, turn = _step(pose, last)
        recent_step, recent_turn = self._recent()
        return (f"{policy.PolicyRule.ODOMETRY_JUMP}: {step:.2f} m and {math.degrees(turn):.1f} deg in one frame against at most "
                f"{recent_step:.2f} m and {math.degrees(recent_turn):.1f} deg in the last {len(self._steps)}; {then}")


def _step(pose: np.ndarray, last: np.ndarray) -> tuple[float, float]:
    """(metres, |turn| radians) from `last` to `pose`."""
    return float(np.hypot(pose[0] - last[0], pose[1] - last[1])), abs(float(wrap_angle(pose[2] - last[2])))
