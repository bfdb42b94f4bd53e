"""Compiled parts of the correlative search (estimator.kernels: numba; the [fast] extra).

The transforms stay scipy.fft's; compiled are what surrounds them: the template's
rasterisation, the products with the mask's transform (both angles of a 180-degree pair
in one pass) and the peak picking (row maxima, candidates, rounding check, even spread of
ties) in one pass over the float32 correlation, without temporaries.

Exactness: the per-angle peaks are the float64 reference's (correlative._exact_peaks), as
on the numpy path: the float32 correlation differs from the numpy path's only in float
rounding (another order of products), every count it reports is checked to round to its
integer within correlative._ROUNDING_SLACK, and an angle whose check fails (or whose
correlation is not finite) is recomputed by the exact float64 pass. The picking itself
(k-th largest, np.round, the np.linspace spread of ties) is integer-exact and replicates
numpy's, so the models equal the numpy path's bit for bit.
"""

from __future__ import annotations

import numpy as np

from .. import threads
from ..numba_support import njit
from . import correlative as C


@njit
def _template(ij, side, W):
    """The template (side rows, W columns: the rfft's zero padding included) with
    ij's (col, row) cells counted, float32 (small integers: exact)."""
    t = np.zeros((side, W), np.float32)
    for p in range(ij.shape[0]):
        t[ij[p, 1], ij[p, 0]] += np.float32(1.0)
    return t


@njit
def _pair_products(F, M, M2, b):
    """F (the template's forward transform) becomes conj(F) * M in place (the angle's
    correlation spectrum); with b (b.shape == F.shape, else ignored), b = F * M2, the
    spectrum of the template turned by 180 degrees (M2 = M * mirror phase)."""
    both = b.shape[0] == F.shape[0]
    for r in range(F.shape[0]):
        for k in range(F.shape[1]):
            f = F[r, k]
            if both:
                b[r, k] = f * M2[r, k]
            F[r, k] = np.conj(f) * M[r, k]


@njit
def _row_maxima(score, n_j):
    """The maxima of score[r, :n_j] per row (float32, exact), or an empty array when a
    value is not finite. Eight running maxima and sums of v - v (0 where finite) per row:
    independent lanes that the compiler vectorises (one running maximum would not be,
    without fastmath)."""
    n_i = score.shape[0]
    out = np.empty(n_i, np.float32)
    zero = np.float32(0.0)
    for r in range(n_i):
        m0 = m1 = m2 = m3 = m4 = m5 = m6 = m7 = score[r, 0]
        d0 = d1 = d2 = d3 = d4 = d5 = d6 = d7 = zero
        c = 0
        while c + 8 <= n_j:
            v = score[r, c]
            m0 = v if v > m0 else m0
            d0 += v - v
            v = score[r, c + 1]
            m1 = v if v > m1 else m1
            d1 += v - v
            v = score[r, c + 2]
            m2 = v if v > m2 else m2
            d2 += v - v
            v = score[r, c + 3]
            m3 = v if v > m3 else m3
            d3 += v - v
            v = score[r, c + 4]
            m4 = v if v > m4 else m4
            d4 += v - v
            v = score[r, c + 5]
            m5 = v if v > m5 else m5
            d5 += v - v
            v = score[r, c + 6]
            m6 = v if v > m6 else m6
            d6 += v - v
            v = score[r, c + 7]
            m7 = v if v > m7 else m7
            d7 += v - v
            c += 8
        m = max(max(max(m0, m1), max(m2, m3)), max(max(m4, m5), max(m6, m7)))
        d = ((d0 + d1) + (d2 + d3)) + ((d4 + d5) + (d6 + d7))
        while c < n_j:
            v = score[r, c]
            m = v if v > m else m
            d += v - v
            c += 1
        if d != 0 or m - m != 0:  # a NaN or an infinity
            return out[:0]
        out[r] = m
    return out


@njit
def _kth_largest(values, k):
    s = np.sort(values)
    return s[values.shape[0] - k]


@njit
def _pick(score, n_j, per_angle, slack):
    """correlative._fast_peaks' picking on score (n_i rows, >= n_j columns, float32):
    (flat placement indices i * n_j + j, counts, ok). ok False: the float32 pass cannot
    vouch for its counts (too few candidates, a count off its integer by more than slack,
    or a non-finite value): use the exact pass."""
    n_i = score.shape[0]
    none = (np.zeros(0, np.int64), np.zeros(0, np.float64), False)
    row_max = _row_maxima(score, n_j)
    if row_max.shape[0] != n_i:
        return none
    # the per_angle-th largest count is at least the per_angle-th largest row maximum, so
    # every placement at or above it lies in these rows
    floor_count = np.rint(_kth_largest(row_max, per_angle))
    threshold = floor_count - np.float32(0.5)
    n = 0
    for r in range(n_i):
        if row_max[r] >= threshold:
            for c in range(n_j):
                n += score[r, c] >= threshold
    if n < per_angle:
        return none
    cand = np.empty(n, np.int64)
    counts = np.empty(n, np.float64)
    q = 0
    for r in range(n_i):
        if row_max[r] >= threshold:
            for c in range(n_j):
                if score[r, c] >= threshold:
                    raw = np.float64(score[r, c])
                    count = np.rint(raw)
                    if not abs(raw - count) <= slack:
                        return none
                    cand[q] = r * n_j + c
                    counts[q] = count
                    q += 1
    # correlative._spread_best: every count above the boundary, then the tied ones at
    # np.round(np.linspace(0, n_at - 1, wanted)) of them, in index order
    boundary = _kth_largest(counts, per_angle)
    n_above = 0
    n_at = 0
    for q in range(n):
        n_above += counts[q] > boundary
        n_at += counts[q] == boundary
    wanted = per_angle - n_above
    picked = np.zeros(n_at, np.bool_)
    if n_at <= wanted:
        picked[:] = True
    elif wanted == 1:
        picked[0] = True  # np.linspace(0, stop, 1) == [0.0]
    elif wanted > 1:
        step = np.float64(n_at - 1) / np.float64(wanted - 1)
        for k in range(wanted - 1):
            picked[np.int64(np.rint(np.float64(k) * step + 0.0))] = True
        picked[n_at - 1] = True  # linspace's endpoint is stop exactly
    best = np.empty(per_angle, np.int64)
    best_counts = np.empty(per_angle, np.float64)
    k = 0
    t = 0
    for q in range(n):
        keep = counts[q] > boundary
        if counts[q] == boundary:
            keep = picked[t]
            t += 1
        if keep:
            best[k] = cand[q]
            best_counts[k] = counts[q]
            k += 1
    return best[:k], best_counts[:k], True


def _forward(ij, side, H, W):
    """The template's (unconjugated) transform on the H x W grid, complex64: the row
    transforms of its side rows only, then the column transforms."""
    import scipy.fft as sfft  # here, not at import: ~0.3 s a CLI error must not pay

    return sfft.fft(sfft.rfft(_template(ij, side, W), axis=1), n=H, axis=0, overwrite_x=True)


def _peaks(spec, n_i, n_j, W, per_angle):
    """(flat indices, counts) from one angle's correlation spectrum (overwritten), or None."""
    import scipy.fft as sfft  # here, not at import: ~0.3 s a CLI error must not pay

    # the inverse keeps only the n_i rows of valid placements before its row transform
    score = sfft.irfft(sfft.ifft(spec, axis=0, overwrite_x=True)[:n_i], n=W, axis=1)
    best, counts, ok = _pick(score, n_j, per_angle, C._ROUNDING_SLACK)
    return (best, counts) if ok else None


def search_angles(spectrum, local, thetas_grid, searched, half_turn, cell, half, n_i, n_j, per_angle):
    """Per angle of the grid, (flat placement indices, counts) of its per_angle best
    placements (empty for angles not searched): correlative's numpy loop, compiled parts
    and paired products, the same peaks."""
    n_angles = len(thetas_grid)
    side = 2 * half
    nothing = (np.zeros(0, dtype=np.int64), np.zeros(0))
    found = [nothing] * n_angles
    templates = [None] * n_angles

    def template(a):
        if templates[a] is None:
            templates[a] = np.ascontiguousarray(C._angle_template(local, thetas_grid[a], cell, half))
        return templates[a]

    if n_i * n_j <= per_angle or n_i < per_angle:  # nothing to prune: the exact pass
        for a in np.flatnonzero(searched):
            found[a] = C._exact_peaks(spectrum, template(a), n_i, n_j, per_angle)
        return found
    H, W, M = C._fast_grid(spectrum, side, n_i, n_j)
    # turn partners: a and a + half_turn (a's 180-degree turn), whose spectrum is F * M2
    pairs = [(a, a + half_turn) for a in range(half_turn)] + [(a, -1) for a in range(2 * half_turn, n_angles)]
    M2 = M * C._mirror_phase(side, H, W) if half_turn else None
    empty = np.zeros((0, 0), np.complex64)

    def search_pair(pair):
        a, b = pair
        do_a, do_b = bool(searched[a]), b >= 0 and bool(searched[b])
        if not do_a:
            a, b, do_a, do_b = b, -1, True, False
        ij = template(a)
        F = _forward(ij, side, H, W)
        # b's template is a's reflected cell by cell (floor rounding can differ: checked)
        mirrored = do_b and np.array_equal(template(b), (side - 1) - ij)
        spec_b = np.empty_like(F) if mirrored else empty
        _pair_products(F, M, M2 if mirrored else M, spec_b)
        for angle, spec in ((a, F), (b, spec_b if mirrored else None)):
            if angle < 0 or (angle == b and not do_b):
                continue
            if spec is None:
                spec = _forward(template(angle), side, H, W)
                _pair_products(spec, M, M, empty)
            fast = _peaks(spec, n_i, n_j, W, per_angle)
            found[angle] = fast if fast is not None else C._exact_peaks(spectrum, template(angle), n_i, n_j, per_angle)

    # pairs are independent (each writes its own angles' slots): spread over the round's threads
    threads.run(search_pair, [(a, b) for a, b in pairs if searched[a] or (b >= 0 and searched[b])])
    return found
