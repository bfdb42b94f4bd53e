"""Compiled loops of the hybrid RANSAC (estimator.kernels: numba; the [fast] extra).

Integer index arithmetic only, so the results equal the numpy path exactly. The draw of
one table row (_draw_row) is shared with the fused draw-and-solve kernels of
solvers_numba, which call it from their own loops."""

from __future__ import annotations

import numpy as np

from ..numba_support import njit


@njit
def _cumulate(sizes, b, cum):
    """cum[r] = sizes[b, 0] + ... + sizes[b, r] (the running count of query b's
    candidates up to range r, integers: exact); returns n_b."""
    n = 0
    for r in range(sizes.shape[1]):
        n += sizes[b, r]
        cum[r] = n
    return n


@njit
def _draw_row(starts, sizes, cum, b, n, uniform):
    """The table row of one draw for query b with n > 0 candidates, cum from _cumulate:
    uniform in [0, 1) scaled to n (u = min(floor(uniform * n), n - 1), as the numpy path)
    and mapped to starts[b, r] + u - (cum[b, r] - sizes[b, r]), r the range holding u: the
    number of cumulative counts <= u, as numpy's searchsorted(side="right") finds it
    (counted without branches: which range a random draw lands in is unpredictable).

    NB solvers_numba's fused kernels call this function and numba's disk cache does not
    notice a change in another file: after editing it, delete solvers_numba's cached
    kernels (__pycache__/solvers_numba.*.nbi / .nbc)."""
    u = np.int64(uniform * n)  # truncation, as numpy's astype(int64) of a non-negative value
    if u > n - 1:
        u = n - 1
    r = 0
    for k in range(cum.shape[0]):
        r += cum[k] <= u
    return starts[b, r] + u - (cum[r] - sizes[b, r])


@njit
def _draw_rows(starts, sizes, counts, uniform):
    """For each query b, counts[b] draws, uniform[j] mapped to its table row by
    _draw_row. Returns (query, row) per draw."""
    total = uniform.shape[0]
    query = np.empty(total, np.int64)
    row = np.empty(total, np.int64)
    cum = np.empty(sizes.shape[1], np.int64)
    j = 0
    for b in range(starts.shape[0]):
        n = _cumulate(sizes, b, cum)
        for _ in range(counts[b]):
            query[j] = b
            row[j] = _draw_row(starts, sizes, cum, b, n, uniform[j])
            j += 1
    return query, row


def draw_uniforms(starts: np.ndarray, sizes: np.ndarray, fraction: float, rng: np.random.Generator):
    """What ransac._draw takes from rng, taken the same way: the number of draws per query
    (ceil(fraction * n_b), at least one where n_b > 0) and one uniform per draw (none, and
    nothing taken from rng, when there are no draws). Also starts and sizes as contiguous
    int64, as the kernels take them."""
    n = sizes.sum(axis=1)
    k = np.where(n > 0, np.maximum(np.ceil(fraction * n), 1), 0).astype(np.int64)
    total = int(k.sum())
    uniform = rng.random(total) if total else np.zeros(0)
    return np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(sizes, dtype=np.int64), k, uniform


def draw(starts: np.ndarray, sizes: np.ndarray, fraction: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """ransac._draw compiled: the same random numbers drawn from rng, the same (query, row)."""
    starts, sizes, k, uniform = draw_uniforms(starts, sizes, fraction, rng)
    if len(uniform) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return _draw_rows(starts, sizes, k, uniform)


@njit
def _admissible_triplets(indptr, indices, parallel, lengths):
    """ransac._ordered_triplets of the CSR neighbour lists (rows (i, j, k), j != k both
    neighbours of i, j-major in list order) without those whose j and k are both parallel
    to i: the rows BevSamples keeps, in the same order. Counted first, so the table is one
    allocation (the numpy path builds it per line and filters a copy). Also each row's
    sampling weight, the shortest of its three lines' lengths (exact: a minimum)."""
    n = indptr.shape[0] - 1
    total = 0
    for i in range(n):
        m = indptr[i + 1] - indptr[i]
        if m >= 2:
            total += m * (m - 1)
    out = np.empty((total, 3), np.int64)
    weight = np.empty(total, np.float64)
    t = 0
    for i in range(n):
        lo, hi = indptr[i], indptr[i + 1]
        if hi - lo < 2:
            continue
        for a in range(lo, hi):
            j = indices[a]
            j_parallel = parallel[i, j]
            for b in range(lo, hi):
                k = indices[b]
                if j == k or (j_parallel and parallel[i, k]):
                    continue
                out[t, 0] = i
                out[t, 1] = j
                out[t, 2] = k
                weight[t] = min(lengths[i], lengths[j], lengths[k])
                t += 1
    return out[:t].copy(), weight[:t].copy()


def admissible_triplets(neighbours, alpha: np.ndarray, max_angle: float, lengths: np.ndarray):
    """BevSamples' triplet table compiled: the same (T, 3) int64 rows in the same order,
    and their weights (lengths[rows].min(axis=1)).
    The parallel test is ransac._parallel_mod_pi's arithmetic on every (i, j) pair at once,
    alpha[i] - alpha[j] and numpy's sin on a contiguous array, as the numpy path applies it
    to the contiguous differences of its gathered triplets: the same booleans."""
    n = len(neighbours)
    if n == 0:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0)
    parallel = np.abs(np.sin(alpha[:, None] - alpha[None, :])) < np.sin(max_angle)
    sizes = np.array([len(nb) for nb in neighbours], dtype=np.int64)
    indptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    indices = np.concatenate([np.asarray(nb, dtype=np.int64) for nb in neighbours]) if indptr[-1] else np.zeros(0, np.int64)
    return _admissible_triplets(indptr, indices, parallel, np.ascontiguousarray(lengths, dtype=np.float64))
