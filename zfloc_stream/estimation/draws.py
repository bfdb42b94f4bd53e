"""The hybrid RANSAC's draws, compiled: which floorplan tuples each BEV sample meets, and
the admissible BEV / floorplan line triplets.

For each query b with candidate ranges (starts[b], sizes[b]): ceil(fraction * n_b) uniform
draws (with replacement) from its n_b candidates. Integer index arithmetic only (exact).
The draw of one table row (draw_row) is shared with the fused draw-and-solve kernels of
solvers.py, which call it from their own loops."""

from __future__ import annotations

import numpy as np

from ..runtime.numba_support import njit


@njit
def cumulate(sizes, b, cum):
    """cum[r] = sizes[b, 0] + ... + sizes[b, r] (the running count of query b's
    candidates up to range r, integers: exact); returns n_b."""
    n = 0
    for r in range(sizes.shape[1]):
        n += sizes[b, r]
        cum[r] = n
    return n


@njit
def draw_row(starts, sizes, cum, b, n, uniform):
    """The table row of one draw for query b with n > 0 candidates, cum from cumulate:
    uniform in [0, 1) scaled to n (u = min(floor(uniform * n), n - 1))
    and mapped to starts[b, r] + u - (cum[b, r] - sizes[b, r]), r the range holding u: the
    number of cumulative counts <= u, as numpy's searchsorted(side="right") finds it
    (counted without branches: which range a random draw lands in is unpredictable).

    NB solvers.py's fused kernels call this function and numba's disk cache does not
    notice a change in another file: after editing it, delete solvers' cached kernels
    (__pycache__/solvers.*.nbi / .nbc)."""
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
    draw_row. Returns (query, row) per draw."""
    total = uniform.shape[0]
    query = np.empty(total, np.int64)
    row = np.empty(total, np.int64)
    cum = np.empty(sizes.shape[1], np.int64)
    j = 0
    for b in range(starts.shape[0]):
        n = cumulate(sizes, b, cum)
        for _ in range(counts[b]):
            query[j] = b
            row[j] = draw_row(starts, sizes, cum, b, n, uniform[j])
            j += 1
    return query, row


def draw_uniforms(starts: np.ndarray, sizes: np.ndarray, fraction: float, rng: np.random.Generator):
    """What a draw takes from rng: the number of draws per query
    (ceil(fraction * n_b), at least one where n_b > 0) and one uniform per draw (none, and
    nothing taken from rng, when there are no draws). Also starts and sizes as contiguous
    int64, as the kernels take them."""
    n = sizes.sum(axis=1)
    k = np.where(n > 0, np.maximum(np.ceil(fraction * n), 1), 0).astype(np.int64)
    total = int(k.sum())
    uniform = rng.random(total) if total else np.zeros(0)
    return np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(sizes, dtype=np.int64), k, uniform


def draw(starts: np.ndarray, sizes: np.ndarray, fraction: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(query, table row) of every draw: ceil(fraction * n_b) uniform draws (with
    replacement) from query b's n_b candidates."""
    starts, sizes, k, uniform = draw_uniforms(starts, sizes, fraction, rng)
    if len(uniform) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    return _draw_rows(starts, sizes, k, uniform)


@njit
def _admissible_triplets(indptr, indices, parallel, lengths):
    """The ordered triplets of the CSR neighbour lists (rows (i, j, k), j != k both
    neighbours of i, j-major in list order) without those whose j and k are both parallel
    to i (parallel[a]: list entry a is parallel to its line). Counted first, so the table
    is one allocation. Also each row's sampling weight,
    the shortest of its three lines' lengths (exact: a minimum)."""
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
            j_parallel = parallel[a]
            for b in range(lo, hi):
                k = indices[b]
                if j == k or (j_parallel and parallel[b]):
                    continue
                out[t, 0] = i
                out[t, 1] = j
                out[t, 2] = k
                weight[t] = min(lengths[i], lengths[j], lengths[k])
                t += 1
    return out[:t].copy(), weight[:t].copy()


def admissible_triplets(neighbours, alpha: np.ndarray, max_angle: float, lengths: np.ndarray):
    """The 3L triplet table of a line set (BEV samples, floorplan tuples): (T, 3) int64
    rows, a line and two of its neighbours, not all parallel (within max_angle, mod pi,
    ransac._parallel_mod_pi's test), and their weights (lengths[rows].min(axis=1))."""
    n = len(neighbours)
    if n == 0:
        return np.zeros((0, 3), dtype=np.int64), np.zeros(0)
    sizes = np.array([len(nb) for nb in neighbours], dtype=np.int64)
    indptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    indices = np.concatenate([np.asarray(nb, dtype=np.int64) for nb in neighbours]) if indptr[-1] else np.zeros(0, np.int64)
    # is each listed neighbour parallel to its line: per list entry, not an (N, N) matrix
    # (46,000 plan lines would need a 17 GB temporary); the same expression element by element
    alpha = np.asarray(alpha, dtype=np.float64)
    parallel = np.abs(np.sin(alpha[np.repeat(np.arange(n), sizes)] - alpha[indices])) < np.sin(max_angle)
    return _admissible_triplets(indptr, indices, parallel, np.ascontiguousarray(lengths, dtype=np.float64))
