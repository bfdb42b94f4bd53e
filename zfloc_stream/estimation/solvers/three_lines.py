"""The three-line (3L) solver (paper 3.2): three BEV line <-> floorplan line
correspondences give the Sim(2) with its scale.

Line 0 (the anchor) fixes the rotation: R n_0 = m_0 (or -m_0); every line then gives one
linear equation s d_k - u_k.t = sigma_k e_k in (s, tx, ty) (solvers/__init__.py), three
lines a 3x3 system solved by Cramer's rule. Solving with R n_0 = -m_0 gives the same
transform with s and R negated, so the sample is solved once and flipped (theta + pi,
-s) when s < 0. At a fixed scale the third line adds nothing: the rigid two-line solver
(two_lines.py) takes the anchor and line 1.

solve_3l solves given samples; drawn_3l draws RANSAC's samples (draws.py) and solves each
block of draws as it is drawn. Both run the same compiled per-sample solve."""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ...runtime.numba_support import njit
from ...settings.loading import ScaleMode, SolverSettings
from ..draws import DRAW_BLOCK, block_buffers, draw_block, draw_uniforms, in_pieces
from .models import (anchor_table, append_model, as_batch, flat_line_columns, line_columns, no_models, quiet, rotation_table,
                     sample_lines, sign_of, wrapped)
from .two_lines import two_lines_at_scales
from .models import NORMAL_CONSISTENCY, PARALLEL_ANGLE_DEG, SINGULAR_TOLERANCE

# A sample is solved exactly only when its scale, computed the short way (_screen), lies
# within the bounds widened by this factor: far beyond any rounding difference between the
# two ways (a regular system's determinant is >= SINGULAR_TOLERANCE times its row norms),
# so the models kept are the same; at a metric prior ~93% of the samples end there.
SCALE_SLACK = 1.05

# The anchor rotation per (floorplan line, BEV line) pair, at theta[fp_line * n_bev +
# bev_line], and its cosine and sine (computed in numpy on whole arrays, only gathered by
# the kernels).
AnchorRotations = namedtuple("AnchorRotations", "theta cos sin n_bev")

# The 3L sample's tests: |(R n_i).m_i| > normal_consistency for lines 1 and 2, the short
# scale inside [plausible_lo, plausible_hi], BEV normals not all pairwise parallel
# (|sin| < sin_par), a regular system (|det| > singular_tolerance times Hadamard's bound),
# and the scale inside [min_scale, max_scale].
Limits3L = namedtuple("Limits3L", "normal_consistency plausible_lo plausible_hi sin_par singular_tolerance min_scale max_scale")


def limits_3l(settings: SolverSettings) -> Limits3L:
    sin_par = float(np.sin(np.deg2rad(PARALLEL_ANGLE_DEG)))
    return Limits3L(float(NORMAL_CONSISTENCY), settings.min_scale / SCALE_SLACK, settings.max_scale * SCALE_SLACK, sin_par,
                    float(SINGULAR_TOLERANCE), float(settings.min_scale), float(settings.max_scale))


# --------------------------------------------------------------------------------------
# the compiled solve: one call runs a sample's whole solve (the normal test, the scale
# plausibility test, Cramer's rule) and returns only what survives, so no per-sample
# temporaries are built
# --------------------------------------------------------------------------------------


@njit
def _det3_scalar(a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """Determinant of the 3x3 matrix with columns a, b, c given by their three rows."""
    return a0 * (b1 * c2 - b2 * c1) - b0 * (a1 * c2 - a2 * c1) + c0 * (a1 * b2 - a2 * b1)


@njit
def _screen(bev_ids, fp_ids, bev, fp, anchor, limits):
    """The two cheap tests of a 3L sample (BEV lines bev_ids matched to floorplan lines
    fp_ids): (passed, c, sn, cos1, cos2), c and sn the cos and sin of its anchor rotation,
    cos1 and cos2 the signed cosines of lines 1 and 2. Every value is computed and the
    tests combined without branching, so a loop of screens does not stall on the
    unpredictable outcomes (about half the drawn samples fail the first test, most of the
    rest the second)."""
    i0, i1, i2 = bev_ids
    j0, j1, j2 = fp_ids
    bnx, bny, bd = bev
    fnx, fny, fd = fp
    # rotation of the anchor pair, from the per-(floorplan line, BEV line) tables
    pair = np.int64(j0) * anchor.n_bev + i0
    c = anchor.cos[pair]
    sn = anchor.sin[pair]
    n1x, n1y, n2x, n2y = bnx[i1], bny[i1], bnx[i2], bny[i2]
    m0x, m0y, m1x, m1y, m2x, m2y = fnx[j0], fny[j0], fnx[j1], fny[j1], fnx[j2], fny[j2]
    # normal consistency of lines 1 and 2: |(R n_i).m_i| > normal_consistency; NaN fails
    cos1 = (c * n1x - sn * n1y) * m1x + (sn * n1x + c * n1y) * m1y
    cos2 = (c * n2x - sn * n2y) * m2x + (sn * n2x + c * n2y) * m2y
    consistent = (abs(cos1) > limits.normal_consistency) & (abs(cos2) > limits.normal_consistency)
    # scale plausibility from the floorplan normals and the signs; a non-finite numerator
    # or denominator is left for the exact solve to judge
    sg1 = sign_of(cos1)
    sg2 = sign_of(cos2)
    x12 = m1x * m2y - m2x * m1y
    x02 = m0x * m2y - m2x * m0y
    x01 = m0x * m1y - m1x * m0y
    cof0 = sg1 * sg2 * x12
    cof1 = -sg2 * x02
    cof2 = sg1 * x01
    den = bd[i0] * cof0 + bd[i1] * cof1 + bd[i2] * cof2
    num = fd[j0] * cof0 + sg1 * fd[j1] * cof1 + sg2 * fd[j2] * cof2
    a_num = abs(num)
    a_den = abs(den)
    inside = (a_num >= limits.plausible_lo * a_den) & (a_num <= limits.plausible_hi * a_den)
    plausible = inside | (not np.isfinite(num)) | (not np.isfinite(den))
    return consistent & plausible, c, sn, cos1, cos2


@njit
def _solve_one(bev_ids, fp_ids, bev, fp, anchor, limits):
    """One 3L sample, BEV lines bev_ids matched to floorplan lines fp_ids: (kept, tx, ty,
    theta, s) with theta NOT yet wrapped; kept False (and the rest meaningless) where the
    sample gives no model."""
    sin_par = limits.sin_par
    passed, c, sn, cos1, cos2 = _screen(bev_ids, fp_ids, bev, fp, anchor, limits)
    if not passed:
        return False, 0.0, 0.0, 0.0, 0.0
    i0, i1, i2 = bev_ids
    j0, j1, j2 = fp_ids
    bnx, bny, bd = bev
    fnx, fny, fd = fp
    theta = anchor.theta[np.int64(j0) * anchor.n_bev + i0]
    n0x, n0y, n1x, n1y, n2x, n2y = bnx[i0], bny[i0], bnx[i1], bny[i1], bnx[i2], bny[i2]
    m0x, m0y, m1x, m1y, m2x, m2y = fnx[j0], fny[j0], fnx[j1], fny[j1], fnx[j2], fny[j2]
    d0, d1, d2 = bd[i0], bd[i1], bd[i2]
    e0, e1, e2 = fd[j0], fd[j1], fd[j2]
    sg1 = sign_of(cos1)
    sg2 = sign_of(cos2)

    # all three BEV normals pairwise parallel: no model
    if (abs(n0x * n1y - n0y * n1x) < sin_par and abs(n0x * n2y - n0y * n2x) < sin_par
            and abs(n1x * n2y - n1y * n2x) < sin_par):
        return False, 0.0, 0.0, 0.0, 0.0

    # rows s d_k - u_k.t = sigma_k e_k: A = [D, -sigma m_x, -sigma m_y], rhs sigma e;
    # the anchor's cosine is computed here, lines 1 and 2 reuse the normal test's
    cos0 = (c * n0x - sn * n0y) * m0x + (sn * n0x + c * n0y) * m0y
    sg0 = sign_of(cos0)
    a10, a11, a12 = -(sg0 * m0x), -(sg1 * m1x), -(sg2 * m2x)
    a20, a21, a22 = -(sg0 * m0y), -(sg1 * m1y), -(sg2 * m2y)
    se0, se1, se2 = sg0 * e0, sg1 * e1, sg2 * e2
    det = _det3_scalar(d0, d1, d2, a10, a11, a12, a20, a21, a22)
    # Hadamard's bound; np.maximum(row_norms, 1e-300) propagates a NaN, and a NaN
    # bound makes the sample irregular
    r0 = np.sqrt(d0 * d0 + a10 * a10 + a20 * a20)
    r1 = np.sqrt(d1 * d1 + a11 * a11 + a21 * a21)
    r2 = np.sqrt(d2 * d2 + a12 * a12 + a22 * a22)
    row_norms = r0 * r1 * r2
    bound = row_norms if (row_norms >= 1e-300 or np.isnan(row_norms)) else 1e-300
    if not abs(det) > limits.singular_tolerance * bound:
        return False, 0.0, 0.0, 0.0, 0.0
    s = _det3_scalar(se0, se1, se2, a10, a11, a12, a20, a21, a22) / det
    tx = _det3_scalar(d0, d1, d2, se0, se1, se2, a20, a21, a22) / det
    ty = _det3_scalar(d0, d1, d2, a10, a11, a12, se0, se1, se2) / det
    if s < 0:  # the R n_1 = -m_1 candidate
        theta = theta + np.pi
    s = abs(s)
    # scale_ok and pack's finiteness filter; theta is finite exactly when its wrapped
    # value is (the wrap of inf is NaN)
    if not (np.isfinite(s) and s >= limits.min_scale and s <= limits.max_scale):
        return False, 0.0, 0.0, 0.0, 0.0
    if not (np.isfinite(tx) and np.isfinite(ty) and np.isfinite(theta)):
        return False, 0.0, 0.0, 0.0, 0.0
    return True, tx, ty, theta, s


@njit
def _solve_samples(bev_ids, fp_ids, bev, fp, anchor, limits):
    """Sample i: BEV lines bev_ids[i] matched to floorplan lines fp_ids[i] ((B, 3) each).
    Models (tx, ty, theta, s) with theta NOT yet wrapped, and the index of the sample each
    came from, in sample order. Buffers are sized for every sample surviving and trimmed
    at the end (untouched pages of the over-allocation cost nothing)."""
    n = bev_ids.shape[0]
    out = np.empty((n, 4), np.float64)
    src = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        ok, tx, ty, theta, s = _solve_one((bev_ids[i, 0], bev_ids[i, 1], bev_ids[i, 2]), (fp_ids[i, 0], fp_ids[i, 1], fp_ids[i, 2]),
                                          bev, fp, anchor, limits)
        if ok:
            kept = append_model(out, src, kept, i, tx, ty, theta, s)
    return out[:kept].copy(), src[:kept].copy()


@njit
def _solve_drawn(draws, piece, picks, rows, bev, fp, anchor, limits):
    """The draws of piece (draws.piece_cursor) solved a block at a time: BEV sample b
    (lines picks[b]) meets counts[b] floorplan triplets, rows of the table rows (T, 3).
    Models with theta NOT yet wrapped, and the draw each came from, in draw order.

    Per block, three passes: the draws and their floorplan lines (draws.draw_block), the
    branch-free screen (_screen), then the full solve of the samples that passed it
    (which screens them again: the same function of the same values, so the same
    outcome)."""
    j_start, j_end = piece[0], piece[1]
    out = np.empty((j_end - j_start, 4), np.float64)
    src = np.empty(j_end - j_start, np.int64)
    cum, query, lines, cursor = block_buffers(draws, piece, 3)
    passed = np.empty(DRAW_BLOCK, np.int64)
    kept = 0
    for j in range(j_start, j_end, DRAW_BLOCK):
        m = min(DRAW_BLOCK, j_end - j)
        cursor = draw_block(draws, rows, j, m, cursor, cum, query, lines)
        count = 0
        for k in range(m):
            q = query[k]
            ok = _screen((picks[q, 0], picks[q, 1], picks[q, 2]), (lines[k, 0], lines[k, 1], lines[k, 2]), bev, fp, anchor, limits)[0]
            passed[count] = k
            count += ok
        for h in range(count):
            k = passed[h]
            q = query[k]
            ok, tx, ty, theta, s = _solve_one((picks[q, 0], picks[q, 1], picks[q, 2]), (lines[k, 0], lines[k, 1], lines[k, 2]),
                                              bev, fp, anchor, limits)
            if ok:
                kept = append_model(out, src, kept, j + k, tx, ty, theta, s)
    return out[:kept].copy(), src[:kept].copy()


# --------------------------------------------------------------------------------------
# the solver
# --------------------------------------------------------------------------------------


@quiet
def solve_3l(bev_normals, bev_offsets, fp_normals, fp_offsets, settings: SolverSettings = SolverSettings(), scale_mode: ScaleMode = "free"):
    """Three line correspondences -> models. Arrays: normals (B, 3, 2), offsets (B, 3);
    line 0 is the anchor fixing the rotation. Normal consistency |(R n_i).m_i| > tau_p is
    checked for lines 1, 2 before the 3x3 system is solved. In fixed mode the third line
    is ignored (rigid two-line solver)."""
    n, d = as_batch(bev_normals, (3, 2)), as_batch(bev_offsets, (3,))
    m, e = as_batch(fp_normals, (3, 2)), as_batch(fp_offsets, (3,))
    if scale_mode == "fixed":
        return two_lines_at_scales(n[:, :2], d[:, :2], m[:, :2], e[:, :2], np.ones(len(n)), settings, check_scale=True)
    if len(n) == 0:
        return no_models()
    table = anchor_table(n, m, 3)
    ids = sample_lines(len(n), 3)
    anchor = AnchorRotations(table, np.cos(table), np.sin(table), 0)
    models, source = _solve_samples(ids, ids, flat_line_columns(n, d), flat_line_columns(m, e), anchor, limits_3l(settings))
    return wrapped(models, source)


def drawn_3l(starts, sizes, fraction: float, rng: np.random.Generator, picks, rows, bev_lines, fp_lines, bev_angles, fp_angles,
             settings: SolverSettings):
    """draws.draw then solve_3l (free / prior scale) on the drawn samples, a block of draws
    at a time: BEV triplets picks (B, 3), the floorplan triplet table rows (T, 3) (its row
    r: the lines of candidate r), the queries' candidate ranges (starts, sizes) and the
    match fraction. Takes the draw's random numbers from rng; returns the models and the
    index of the draw each came from, in draw order (the same with any thread count)."""
    draws = draw_uniforms(starts, sizes, fraction, rng)
    if len(draws.uniform) == 0:
        return no_models()
    table, (cos_table, sin_table) = rotation_table(bev_angles, fp_angles, None)
    anchor = AnchorRotations(table, cos_table, sin_table, len(bev_angles))
    picks = np.ascontiguousarray(picks, dtype=np.int64)
    rows = np.ascontiguousarray(rows)
    bev, fp, limits = line_columns(bev_lines), line_columns(fp_lines), limits_3l(settings)
    models, source = in_pieces(lambda piece: _solve_drawn(draws, piece, picks, rows, bev, fp, anchor, limits), draws)
    return wrapped(models, source)
