"""What a round's estimation returns: ranked hypotheses (an alignment, its score C = Cc - Cv
and the solver that proposed it) and the model-row layout (tx, ty, theta, s) that the
solvers, scoring and the LM share."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..geometry.sim2 import Sim2

WARM = "warm"
CORRELATIVE = "correlative"
GUIDED = "guided"


@dataclass(frozen=True)
class Hypothesis:
    alignment: Sim2  # BEV / odometry plane -> floorplan
    score: float  # C = Cc - Cv
    cc: float
    cv: float
    solver: str  # "3L", "2L", "2C", "LC", "guided", "correlative" or "warm"


@dataclass(frozen=True)
class LocalizationResult:
    hypotheses: list[Hypothesis]  # best first, pairwise distinct
    timings: dict[str, float] = field(default_factory=dict)  # seconds: model_estimation, scoring, refinement
    n_models: int = 0  # models generated (solver outputs + warm starts) before scoring
    cpu_timings: dict[str, float] = field(default_factory=dict)  # the same stages in CPU seconds of the calling thread

    @property
    def best(self) -> Hypothesis | None:
        return self.hypotheses[0] if self.hypotheses else None


def model_rows(alignments: Sequence[Sim2]) -> np.ndarray:
    """(K, 4) model rows (tx, ty, theta, s), the layout solvers, scoring and LM work on."""
    return np.array([[a.t[0], a.t[1], a.theta, a.s] for a in alignments], dtype=float).reshape(-1, 4)


def alignment_of(model: np.ndarray) -> Sim2:
    """The Sim2 of one model row (tx, ty, theta, s)."""
    return Sim2(model[3], model[2], (model[0], model[1]))
