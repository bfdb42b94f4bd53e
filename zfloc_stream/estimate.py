"""What the localizer reports for every pushed frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .sim2 import Sim2

Status = Literal["initializing", "tracking", "ambiguous", "lost"]
STATUSES: tuple[str, ...] = ("initializing", "tracking", "ambiguous", "lost")


@dataclass(frozen=True)
class Alternative:
    """One live mode: an odom-plane -> floorplan alignment and the pose it implies."""

    alignment: Sim2
    pose: np.ndarray  # (3,) x, y, theta of the sensor in the floorplan frame
    weight: float  # normalised over modes
    score: float  # latest C = Cc - Cv


@dataclass(frozen=True)
class Estimate:
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
    # in [0, 1], for a caller to threshold: the reported mode's share of the tracker's weight,
    # scaled by its confirmation, 0 when the frame's own evidence contradicts the pose
    # (tracking.HypothesisTracker.assess_frame); nan before any pose
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
