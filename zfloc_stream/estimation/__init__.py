"""Hybrid RANSAC estimator: minimal solvers, coarse-to-fine scoring, LM/Huber refinement."""

from .ransac import Hypothesis, LocalizationResult, localize

__all__ = ["Hypothesis", "LocalizationResult", "localize"]
