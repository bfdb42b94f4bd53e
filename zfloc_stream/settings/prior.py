"""Settings of the pose prior: what the caller knows of where the sensor starts (prior.py),
AMCL's initial pose. Empty by default: the search is global."""

from __future__ import annotations

from pydantic import Field, field_validator

from .base import Section


class PriorSettings(Section):
    # the sensor's pose in the floorplan at the first frame: x, y (m), heading (deg); none: no pose prior
    pose: list[float] | None = Field(None, min_length=3, max_length=3)
    sigma_xy: float = Field(1.0, gt=0, le=1e4)  # m, standard deviation of the prior's position
    sigma_theta_deg: float = Field(15.0, gt=0, le=360)  # deg, standard deviation of its heading
    # the first frame's position lies inside this polygon (floorplan frame, m; >= 3 vertices); none: anywhere
    region: list[list[float]] | None = Field(None, min_length=3)
    # a pose within this many sigmas (position and heading apart) is consistent with the prior
    gate_sigmas: float = Field(2.5, gt=0, le=100)
    # m, grid of the seeds a pose prior adds to each global search (orebro 222 #15, a map covering half
    # the frames: at 0.5 m the first round's best inside was 4.9 m off, at 0.25 m 0.2 m)
    seed_step: float = Field(0.25, gt=0, le=100)
    seed_angle_step_deg: float = Field(5.0, gt=0, le=180)  # deg, their heading grid
    max_seeds: int = Field(100_000, ge=0, le=10_000_000)  # at most this many seeds per round (the grid coarsens to fit)
    # while the prior holds, the hypotheses outside it are pruned; a round whose best hypothesis
    # outside scores more than this above the best inside (or that has none inside) contradicts
    # it. Held-out real windows (eval_real --lengths 15 --windows 2): a right prior (3 m / 30 deg)
    # met -0.19..+1.0, a prior 10 m off -0.6..-0.2 (the -0.2 where the map covers half the frames)
    contradiction_gap: float = Field(0.25, ge=0, le=10)
    # while the prior holds, a frame is not `tracking` (but `ambiguous`) when the latest round's
    # best outside scored more than this above the best inside: the prior picked the place, the
    # frames do not back it (eval_real, a prior 10 m off: 3 of 80 windows tracked 12-14 m off at 0.25)
    doubt_gap: float = Field(0.05, ge=0, le=10)
    # contradicting rounds in a row, naming one place (prior.SAME_PLACE), before the prior is
    # dropped: a right 3 m / 30 deg prior was contradicted by the first round (5 frames) in 4 of
    # 40 held-out laser windows, each by a far place the next round does not name again
    contradiction_rounds: int = Field(2, ge=1, le=1000)
    # hits a mode born inside the prior needs before it is tracked, when the round agrees
    # with the prior (its best hypothesis lies inside); tracking.confirm_rounds without a prior
    confirm_rounds: int = Field(1, ge=1, le=1000)
    # the prior is let go once a mode inside it was tracked this many rounds and a round's best
    # inside leads every hypothesis outside by contradiction_gap: later rounds follow the
    # evidence alone (the gate is the start pose's, and odometry drifts)
    release_rounds: int = Field(5, ge=1, le=10_000)

    @field_validator("region")
    @classmethod
    def _vertices(cls, value):
        if value is not None and any(len(v) != 2 for v in value):
            raise ValueError("each region vertex must be two numbers [x, y]")
        return value
