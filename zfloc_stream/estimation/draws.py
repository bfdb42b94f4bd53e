"""The hybrid RANSAC's draws, compiled: which floorplan tuples each BEV sample meets, and
the admissible BEV / floorplan line triplets.

For each query b with candidate ranges (starts[b], sizes[b]): ceil(fraction * n_b) uniform
draws (with replacement) from its n_b candidates. Integer index arithmetic only (exact).

The line solvers (solvers/three_lines.py, solvers/two_lines.py) solve their samples as
they are drawn, a block of draws at a time (draw_block), so the draws are never laid out
whole; a round's draws are split over its threads in consecutive pieces (in_pieces).

NB the solvers' compiled loops call draw_block (and through it draw_row and cumulate), and
numba's disk cache does not notice a change in another file: after editing one of them,
delete the solvers' cached kernels (solvers/__pycache__/*.nbi / .nbc)."""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ..runtime import threads
from ..runtime.numba_support import njit

# What a round's draws are made from (draw_uniforms): per query b its candidate ranges
# (starts[b], sizes[b]) in a table, the number of draws counts[b], and one uniform in
# [0, 1) per draw, the draws of query 0 first.
Draws = namedtuple("Draws", "starts sizes counts uniform")

# draws per block of draw_block: a solver's block buffers stay in the L1 cache
DRAW_BLOCK = 512
# in_pieces splits the draws over the round's threads only in pieces of at least this
# many (~1 ms of line solving)
MIN_DRAWS_PER_THREAD = 32_768


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
    (counted without branches: which range a random draw lands in is unpredictable)."""
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


def draw_uniforms(starts: np.ndarray, sizes: np.ndarray, fraction: float, rng: np.random.Generator) -> Draws:
    """What a draw takes from rng: the number of draws per query
    (ceil(fraction * n_b), at least one where n_b > 0) and one uniform per draw (none, and
    nothing taken from rng, when there are no draws). Also starts and sizes as contiguous
    int64, as the kernels take them."""
    n = sizes.sum(axis=1)
    k = np.where(n > 0, np.maximum(np.ceil(fraction * n), 1), 0).astype(np.int64)
    total = int(k.sum())
    uniform = rng.random(total) if total else np.zeros(0)
    return Draws(np.ascontiguousarray(starts, dtype=np.int64), np.ascontiguousarray(sizes, dtype=np.int64), k, uniform)


@njit
def piece_cursor(draws, piece, cum):
    """Where the draws of piece (j_start, j_end, b_start, left_start) begin: its first
    draw is one of query b_start's, which has left_start draws left there. Returns the
    cursor (query, its candidate count, its draws left) that draw_block continues from,
    cum holding the query's running counts (cumulate)."""
    b, left = piece[2], piece[3]
    n = 0
    if left > 0:
        n = cumulate(draws.sizes, b, cum)
    return b, n, left


@njit
def block_buffers(draws, piece, width):
    """What a solver's draw loop over piece needs before its first draw_block: the
    query's running counts (cum), a block's query of each draw (query) and its `width`
    table rows (lines), and the cursor (piece_cursor)."""
    cum = np.empty(draws.sizes.shape[1], np.int64)
    query = np.empty(DRAW_BLOCK, np.int64)
    lines = np.empty((DRAW_BLOCK, width), np.int64)
    return cum, query, lines, piece_cursor(draws, piece, cum)


@njit
def draw_block(draws, rows, j, m, cursor, cum, query, lines):
    """Draws j to j + m - 1 (draw_row), continuing from cursor (piece_cursor, or the
    previous block's): query[k] the query of draw j + k, lines[k] the table row it drew
    (rows (T, width)). The rows are looked up here, a block at a time: random memory
    accesses independent of one another, so they overlap. Returns the cursor after the
    block."""
    b, n, left = cursor
    for k in range(m):
        while left == 0:  # total = sum(counts): a query with draws follows
            b += 1
            n = cumulate(draws.sizes, b, cum)
            left = draws.counts[b]
        row = draw_row(draws.starts, draws.sizes, cum, b, n, draws.uniform[j + k])
        query[k] = b
        for c in range(rows.shape[1]):
            lines[k, c] = rows[row, c]
        left -= 1
    return b, n, left


def whole(draws: Draws) -> tuple:
    """The piece of all the draws (piece_cursor's (j_start, j_end, b_start, left_start))."""
    return piece_of(np.cumsum(draws.counts), 0, len(draws.uniform))


def piece_of(ends: np.ndarray, j_start: int, j_end: int) -> tuple:
    """Draws j_start to j_end - 1 as a piece: it starts inside the query whose draws
    cover its first draw (ends: the cumulative counts)."""
    b = int(np.searchsorted(ends, j_start, side="right"))
    return j_start, j_end, b, int(ends[b] - j_start)


def in_pieces(solve_piece, draws: Draws):
    """solve_piece(piece) -> (models, source) over the draws in consecutive pieces, one
    per thread of the round (at least MIN_DRAWS_PER_THREAD each), joined in draw order:
    the same rows with any thread count."""
    ends = np.cumsum(draws.counts)

    def piece(r):
        return solve_piece(piece_of(ends, r[0], r[1]))

    parts = threads.run(piece, threads.ranges(len(draws.uniform), MIN_DRAWS_PER_THREAD))
    return np.concatenate([m for m, _ in parts]), np.concatenate([src for _, src in parts])


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
