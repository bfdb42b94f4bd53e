"""What the localizer reports for every pushed frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from .geometry.sim2 import Sim2

class Status(StrEnum):
    """The status of a frame (tracking/status.py decides it). A str: it compares equal to,
    prints and serialises as its value, the word logs, CSV and users already read."""

    INITIALIZING = "initializing"
    TRACKING = "tracking"
    AMBIGUOUS = "ambiguous"
    LOST = "lost"


STATUSES: tuple[str, ...] = tuple(s.value for s in Status)


@dataclass(frozen=True)
class Alternative:
    """One live mode: an odom-plane -> floorplan alignment and the pose it implies."""

    alignment: Sim2
    pose: np.ndarray  # (3,) x, y, theta of the sensor in the floorplan frame
    weight: float  # normalised over modes
    score: float  # latest C = Cc - Cv


@dataclass(frozen=True)
class Estimate:
    """What `Localizer.push` returns for one frame.

    frame: the frame's push number (0 for the first frame pushed).
    timestamp: the frame's own stamp, seconds.
    status: initializing (no mode confirmed yet), tracking (one confirmed mode clearly
        ahead), ambiguous (confirmed rivals at other places), lost (the tracked mode
        collapsed; a global search runs again). docs/status.md gives the rules.
    pose: (x, y, theta) of the sensor in the floorplan frame (metres, radians); the best
        mode's alignment applied to the frame's odometry pose. None before any hypothesis.
    covariance: (3, 3) of pose (x, y, theta): the best mode's filter covariance carried to
        the pose (tracking.HypothesisTracker.pose_covariance); None without a pose.
    alignment: the best mode's odometry-plane -> floorplan similarity (Sim2: s, R, t).
    score: the best mode's latest score C = Cc - Cv in [-1, 1]: the share of the seen wall
        points that lie on a plan wall (Cc) minus the share of plan walls crossing floor
        seen free (Cv). 1 is a perfect match, 0 or less no support; on a real building a
        correct place scores well below 1 (furniture, clutter, walls the plan lacks). It
        ranks the places of one run; it is no probability (see confidence). nan: none.
    alternatives: every live mode (the reported one first) with its pose, weight and score.
    timings: seconds per stage spent in this push (bev, round, ...).
    skipped: why the frame was refused and not fused (None: fused).
    round_skipped: why the round due at this frame did not run (None: it ran, or none due).
    confidence: see the field's comment.
    scale: the alignment's scale (metres of floorplan per odometry unit; nan without).
    n_hypotheses: the number of live modes.
    prior: the caller's pose prior (prior.py): None without one, else pending, active,
        released or contradicted.
    """

    frame: int
    timestamp: float
    status: Status
    pose: np.ndarray | None  # (3,) best x, y, theta in the floorplan; None before any hypothesis
    covariance: np.ndarray | None  # (3, 3) of pose
    alignment: Sim2 | None  # best odom-plane -> floorplan alignment
    score: float  # best mode's latest score (nan when none)
    alternatives: tuple[Alternative, ...] = ()
    timings: dict[str, float] = field(default_factory=dict)  # seconds per stage for this push
    skipped: str | None = None  # reason when the frame was rejected and not fused
    round_skipped: str | None = None  # why the round due at this frame did not run (None: ran, or none due)
    # in [0, 1], for a caller to threshold, the same on every map: the reported mode's share of
    # the tracker's weight, times its confirmation, times how far the map explains what the
    # sensor sees; 0 on a `lost` frame or when the frame's own evidence contradicts the pose
    # (tracking/confidence.py); nan before any pose
    confidence: float = float("nan")
    # the caller's pose prior (prior.py): None without one; "pending" (given, no frame fused
    # since), "active" (it steers the search and the tracker), "released" (a mode inside it
    # was tracked long enough: the evidence alone goes on), "contradicted" (the frames are
    # clearly better explained elsewhere, or nowhere inside it: dropped, the search is global)
    prior: str | None = None

    @property
    def scale(self) -> float:
        return self.alignment.s if self.alignment is not None else float("nan")

    @property
    def n_hypotheses(self) -> int:
        return len(self.alternatives)
