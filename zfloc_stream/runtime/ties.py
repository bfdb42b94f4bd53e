"""Ranking keys that do not flip on last-bit differences.

Scores and weights are sums and products whose last bits depend on the machine (numpy's
SIMD kernels and the BLAS pick code paths by CPU). Where a decision compares two of them
(which hypothesis ranks first, which mode is reported, whether a refinement is kept),
two values that are equal in exact arithmetic, as mirrored hypotheses in a symmetric
building are, could order differently on another machine. Rounded to TIE_DECIMALS they
tie exactly, and the tie goes to the next key (sample index, mode id), which is the same
everywhere. Scores C, weights and running scores lie in [-1, 1], so 1e-9 is far below any
difference that means something and far above a last-bit one (about 1e-16).
"""

from __future__ import annotations

import numpy as np

TIE_DECIMALS = 9


def tie_key(value: float) -> float:
    """A scalar rank key: equal to TIE_DECIMALS decimals means a tie."""
    return round(float(value), TIE_DECIMALS)


def tie_keys(values) -> np.ndarray:
    return np.round(np.asarray(values, dtype=float), TIE_DECIMALS)


def descending(values) -> np.ndarray:
    """Indices from the largest value down; ties (at TIE_DECIMALS) keep index order."""
    return np.argsort(-tie_keys(values), kind="stable")
