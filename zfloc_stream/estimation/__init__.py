"""Hybrid RANSAC estimator: minimal solvers, coarse-to-fine scoring, LM/Huber refinement."""

from .ransac import localize
from .results import Hypothesis, LocalizationResult

__all__ = ["Hypothesis", "LocalizationResult", "localize"]
