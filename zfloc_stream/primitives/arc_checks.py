"""Whether the inliers of a fitted circle are a pillar (circle_fitting.py): they wrap far
enough around the centre (angular coverage) without long holes (angular span), and no two
lines fit them better (a corner). Compiled."""

from __future__ import annotations

import math

import numpy as np

from ..runtime.numba_support import njit

TWO_PI = 2 * np.pi


@njit
def angular_coverage_and_span(angles, max_gap):
    """(2*pi minus the largest gap between consecutive angles, longest contiguous span whose
    consecutive gaps are all < max_gap), both in radians (angles taken mod 2*pi)."""
    n = angles.shape[0]
    if n < 2:
        return 0.0, 0.0
    a = np.empty(n)
    for i in range(n):
        m = np.fmod(angles[i], TWO_PI)  # npy_divmod with a positive divisor:
        a[i] = m + TWO_PI if m < 0 else (m if m != 0.0 else 0.0)  # sign of the divisor, zero as +0
    a = np.sort(a)
    gaps = np.empty(n)
    for i in range(n - 1):
        gaps[i] = a[i + 1] - a[i]
    gaps[n - 1] = (a[0] + TWO_PI) - a[n - 1]
    coverage = TWO_PI - gaps.max()
    start = -1
    for i in range(n):
        if not gaps[i] < max_gap:
            start = i + 1
            break
    if start < 0:
        return coverage, TWO_PI
    cum = np.empty(n + 1)
    cum[0] = 0.0
    small = np.empty(n, np.bool_)
    acc = 0.0
    for i in range(n):
        g = gaps[(i + start) % n]
        small[i] = g < max_gap
        acc += g if small[i] else 0.0
        cum[i + 1] = acc
    span = 0.0
    lo = -1
    for hi in range(n + 1):
        if hi == n or not small[hi]:
            span = max(span, cum[hi] - cum[lo + 1] if hi > lo + 1 else 0.0)
            lo = hi
    return coverage, span


@njit
def best_two_line_sse(p, min_part):
    """Smallest total squared orthogonal residual of two lines fitted to a prefix and the
    remaining suffix of the ordered points p (every split point, by cumulative sums)."""
    n = p.shape[0]
    if n < 2 * min_part:
        return np.inf
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += p[i, 0]
        my += p[i, 1]
    mx /= n
    my /= n
    terms = np.empty((n, 6))
    total = np.zeros(6)
    for i in range(n):
        x = p[i, 0] - mx
        y = p[i, 1] - my
        terms[i, 0] = 1.0
        terms[i, 1] = x
        terms[i, 2] = y
        terms[i, 3] = x * x
        terms[i, 4] = x * y
        terms[i, 5] = y * y
        for j in range(6):
            total[j] += terms[i, j]
    best = np.inf
    prefix = np.zeros(6)
    suffix = np.empty(6)
    for k in range(n - min_part):  # prefix of k + 1 points
        for j in range(6):
            prefix[j] += terms[k, j]
        if k < min_part - 1:
            continue
        for j in range(6):
            suffix[j] = total[j] - prefix[j]
        value = _line_sse(prefix) + _line_sse(suffix)
        if value < best or k == min_part - 1:
            best = value
    return best


@njit
def _line_sse(m):
    cnt, sx, sy, sxx, sxy, syy = m[0], m[1], m[2], m[3], m[4], m[5]
    a = sxx - sx * sx / cnt
    b = sxy - sx * sy / cnt
    d = syy - sy * sy / cnt
    return max(0.5 * (a + d) - math.sqrt(0.25 * ((a - d) * (a - d)) + b * b), 0.0)
