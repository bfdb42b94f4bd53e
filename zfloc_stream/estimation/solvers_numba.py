"""The 3L minimal solver at free / prior scale compiled (estimator.kernels: numba; the
[fast] extra).

solvers.solve_3l_indexed runs its samples through three vectorised stages: the normal
test, the scale plausibility test and Cramer's rule, each gathering and filtering whole
arrays (most samples fail the first two tests). Here one loop runs all three per sample
and writes only the models that survive, so no per-sample temporaries are built.

Bit for bit the numpy path: every expression below is the numpy code's, in its order of
operations (_normals_consistent, _scale_plausible, _solve_3l_components, _det3_rows,
_scale_ok, _pack), evaluated without fastmath (no reassociation, no fused
multiply-add). The transcendental functions stay in numpy: cos and sin of the
(floorplan line, BEV line) rotation table are computed there exactly as the numpy path
computes them and only gathered here, and the final angle wrap is solvers._wrap on the
survivors.
"""

from __future__ import annotations

import numpy as np

from ..config import SolverSettings
from ..numba_support import njit
from .solvers import _SCALE_SLACK, _empty, _wrap


@njit
def _det3(a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """solvers._det3_rows for one sample: columns a, b, c given by their three rows."""
    return a0 * (b1 * c2 - b2 * c1) - b0 * (a1 * c2 - a2 * c1) + c0 * (a1 * b2 - a2 * b1)


@njit
def _sign(cos):
    """np.where(cos < 0, -1.0, 1.0): a NaN or -0.0 cosine gives +1."""
    return -1.0 if cos < 0 else 1.0


@njit
def _solve(bnx, bny, bd, fnx, fny, fd, b0, b1, b2, f0, f1, f2, table, cos_table, sin_table, n_bev,
           normal_consistency, plausible_lo, plausible_hi, sin_par, singular_tolerance, min_scale, max_scale):
    """Models (tx, ty, theta, s) with theta NOT yet wrapped, and the index of the sample
    each came from, in sample order. Buffers are sized for every sample surviving and
    trimmed at the end (untouched pages of the over-allocation cost nothing)."""
    n = b0.shape[0]
    out = np.empty((n, 4), np.float64)
    src = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        # rotation of the anchor pair, from the per-(floorplan line, BEV line) tables
        pair = np.int64(f0[i]) * n_bev + b0[i]
        theta = table[pair]
        c = cos_table[pair]
        sn = sin_table[pair]
        i0, i1, i2 = b0[i], b1[i], b2[i]
        j0, j1, j2 = f0[i], f1[i], f2[i]
        n0x, n0y, n1x, n1y, n2x, n2y = bnx[i0], bny[i0], bnx[i1], bny[i1], bnx[i2], bny[i2]
        m0x, m0y, m1x, m1y, m2x, m2y = fnx[j0], fny[j0], fnx[j1], fny[j1], fnx[j2], fny[j2]

        # normal consistency of lines 1 and 2 (_normals_consistent); NaN fails
        cos1 = (c * n1x - sn * n1y) * m1x + (sn * n1x + c * n1y) * m1y
        if not abs(cos1) > normal_consistency:
            continue
        cos2 = (c * n2x - sn * n2y) * m2x + (sn * n2x + c * n2y) * m2y
        if not abs(cos2) > normal_consistency:
            continue

        # scale plausibility from the floorplan normals and the signs (_scale_plausible);
        # a non-finite numerator or denominator is left for the exact solve to judge
        sg1 = _sign(cos1)
        sg2 = _sign(cos2)
        x12 = m1x * m2y - m2x * m1y
        x02 = m0x * m2y - m2x * m0y
        x01 = m0x * m1y - m1x * m0y
        cof0 = sg1 * sg2 * x12
        cof1 = -sg2 * x02
        cof2 = sg1 * x01
        d0, d1, d2 = bd[i0], bd[i1], bd[i2]
        e0, e1, e2 = fd[j0], fd[j1], fd[j2]
        den = d0 * cof0 + d1 * cof1 + d2 * cof2
        num = e0 * cof0 + sg1 * e1 * cof1 + sg2 * e2 * cof2
        a_num = abs(num)
        a_den = abs(den)
        inside = (a_num >= plausible_lo * a_den) and (a_num <= plausible_hi * a_den)
        if not (inside or not np.isfinite(num) or not np.isfinite(den)):
            continue

        # all three BEV normals pairwise parallel: no model (_solve_3l_components)
        if (abs(n0x * n1y - n0y * n1x) < sin_par and abs(n0x * n2y - n0y * n2x) < sin_par
                and abs(n1x * n2y - n1y * n2x) < sin_par):
            continue

        # rows s d_k - u_k.t = sigma_k e_k: A = [D, -sigma m_x, -sigma m_y], rhs sigma e;
        # the anchor's cosine is computed here, lines 1 and 2 reuse the normal test's
        cos0 = (c * n0x - sn * n0y) * m0x + (sn * n0x + c * n0y) * m0y
        sg0 = _sign(cos0)
        a10, a11, a12 = -(sg0 * m0x), -(sg1 * m1x), -(sg2 * m2x)
        a20, a21, a22 = -(sg0 * m0y), -(sg1 * m1y), -(sg2 * m2y)
        se0, se1, se2 = sg0 * e0, sg1 * e1, sg2 * e2
        det = _det3(d0, d1, d2, a10, a11, a12, a20, a21, a22)
        # Hadamard's bound; np.maximum(row_norms, 1e-300) propagates a NaN, and a NaN
        # bound makes the sample irregular as in numpy
        r0 = np.sqrt(d0 * d0 + a10 * a10 + a20 * a20)
        r1 = np.sqrt(d1 * d1 + a11 * a11 + a21 * a21)
        r2 = np.sqrt(d2 * d2 + a12 * a12 + a22 * a22)
        row_norms = r0 * r1 * r2
        bound = row_norms if (row_norms >= 1e-300 or np.isnan(row_norms)) else 1e-300
        if not abs(det) > singular_tolerance * bound:
            continue
        s = _det3(se0, se1, se2, a10, a11, a12, a20, a21, a22) / det
        tx = _det3(d0, d1, d2, se0, se1, se2, a20, a21, a22) / det
        ty = _det3(d0, d1, d2, a10, a11, a12, se0, se1, se2) / det
        if s < 0:  # the R n_1 = -m_1 candidate
            theta = theta + np.pi
        s = abs(s)
        # _scale_ok and _pack's finiteness filter; theta is finite exactly when its
        # wrapped value is (the wrap of inf is NaN)
        if not (np.isfinite(s) and s >= min_scale and s <= max_scale):
            continue
        if not (np.isfinite(tx) and np.isfinite(ty) and np.isfinite(theta)):
            continue
        out[kept, 0] = tx
        out[kept, 1] = ty
        out[kept, 2] = theta
        out[kept, 3] = s
        src[kept] = i
        kept += 1
    return out[:kept].copy(), src[:kept].copy()


def solve_3l_indexed(bnx, bny, bev_offsets, fnx, fny, fp_offsets, b, f, bev_angles, fp_angles, settings: SolverSettings):
    """solvers.solve_3l_indexed after its argument checks, compiled: the BEV and
    floorplan normal components and offsets (float64), b and f three index arrays each
    (any integer dtype, non-empty), the normal angles of both line sets. The same models
    and source indices, in the same order, bit for bit."""
    # as the numpy path: theta, cos and sin per (floorplan line, BEV line) pair
    table = (fp_angles[:, None] - bev_angles[None, :]).ravel()
    cos_table, sin_table = np.cos(table), np.sin(table)
    sin_par = float(np.sin(np.deg2rad(settings.parallel_angle_deg)))
    idx = [np.ascontiguousarray(v) for v in (*b, *f)]
    models, source = _solve(
        bnx, bny, np.ascontiguousarray(bev_offsets), fnx, fny, np.ascontiguousarray(fp_offsets), *idx,
        table, cos_table, sin_table, len(bev_angles),
        settings.normal_consistency, settings.min_scale / _SCALE_SLACK, settings.max_scale * _SCALE_SLACK, sin_par,
        settings.singular_tolerance, settings.min_scale, settings.max_scale,
    )
    if len(source) == 0:
        return _empty()
    models[:, 2] = _wrap(models[:, 2])
    return models, source
