"""Compiled loops of the hybrid RANSAC (estimator.kernels: numba; the [fast] extra).

Integer index arithmetic only, so the results equal the numpy path exactly."""

from __future__ import annotations

import numpy as np

from ..numba_support import njit


@njit
def _draw_rows(starts, sizes, counts, uniform):
    """For each query b, counts[b] draws: uniform[j] in [0, 1) scaled to the query's n_b
    candidates (u = min(floor(uniform * n_b), n_b - 1), as the numpy path) and mapped to
    the table row starts[b, r] + u - (candidates in ranges before r), r the range
    holding u. Returns (query, row) per draw."""
    total = uniform.shape[0]
    query = np.empty(total, np.int64)
    row = np.empty(total, np.int64)
    j = 0
    for b in range(starts.shape[0]):
        n = 0
        for r in range(sizes.shape[1]):
            n += sizes[b, r]
        for _ in range(counts[b]):
            u = np.int64(uniform[j] * n)  # truncation, as numpy's astype(int64) of a non-negative value
            if u > n - 1:
                u = n - 1
            before = 0
            r = 0
            while before + sizes[b, r] <= u:  # the range whose cumulative size first exceeds u
                before += sizes[b, r]
                r += 1
            query[j] = b
            row[j] = starts[b, r] + u - before
            j += 1
    return query, row


def draw(starts: np.ndarray, sizes: np.ndarray, fraction: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """ransac._draw compiled: the same random numbers drawn from rng, the same (query, row)."""
    n = sizes.sum(axis=1)
    k = np.where(n > 0, np.maximum(np.ceil(fraction * n), 1), 0).astype(np.int64)
    total = int(k.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    uniform = rng.random(total)
    return _draw_rows(np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(sizes, dtype=np.int64), k, uniform)
