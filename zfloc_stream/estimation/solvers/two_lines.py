"""The two-line (2L) solver (paper 3.2): two BEV line <-> floorplan line correspondences
give the Sim(2) at a known scale, the metric prior's (s = prior + GGD noise, one draw per
sample) or 1 exactly at a fixed scale, where it is also the rigid form of 3L.

Line 0 fixes the rotation, R n_0 = m_0 or R n_0 = -m_0; with the scale known the two are
different transforms, so both candidates are solved (a before b). Each line gives
u_k.t = s d_k - sigma_k e_k (solvers/__init__.py), two lines a 2x2 system in t.

solve_2l solves given samples; drawn_2l draws RANSAC's samples (draws.py) and solves each
block of draws as it is drawn. Both run the same compiled per-sample solve."""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from ...runtime.numba_support import njit
from ...settings.loading import ScaleMode, SolverSettings
from ..draws import DRAW_BLOCK, block_buffers, draw_block, draw_uniforms, whole
from .models import (anchor_table, append_model, as_batch, flat_line_columns, line_columns, no_models, quiet, rotation_table,
                     sample_lines, sign_of, wrapped)
from .scale_prior import sample_scale_noise
from .models import NORMAL_CONSISTENCY, PARALLEL_ANGLE_DEG

# The anchor rotation per (floorplan line, BEV line) pair, at theta[fp_line * n_bev +
# bev_line], and the cosine and sine of the two candidates' angles theta + 0.0 (a) and
# theta + pi (b) (computed in numpy on whole arrays, only gathered by the kernels).
CandidateRotations = namedtuple("CandidateRotations", "theta cos_a sin_a cos_b sin_b n_bev")

# The 2L sample's tests: |(R n_1).m_1| > normal_consistency, BEV normals and the matched
# floorplan normals not parallel (|sin| < sin_par), and where check_scale the scale inside
# [min_scale, max_scale] (a drawn prior scale; 1 at a fixed scale is not checked).
Limits2L = namedtuple("Limits2L", "normal_consistency sin_par min_scale max_scale check_scale")


def limits_2l(settings: SolverSettings, check_scale: bool) -> Limits2L:
    sin_par = float(np.sin(np.deg2rad(PARALLEL_ANGLE_DEG)))
    return Limits2L(float(NORMAL_CONSISTENCY), sin_par, float(settings.min_scale), float(settings.max_scale), check_scale)


# --------------------------------------------------------------------------------------
# the compiled solve
# --------------------------------------------------------------------------------------


@njit
def _candidate(c, sn, bev_normals, fp_normals, bev_offsets, fp_offsets, s, limits):
    """One rotation candidate of a two-line sample (cos c, sin sn of its angle; normals
    (n0x, n0y, n1x, n1y), offsets (d0, d1) on the BEV side, likewise on the floorplan
    side): (kept, tx, ty); the sample's own tests (parallel BEV lines, scale) are the
    caller's."""
    n0x, n0y, n1x, n1y = bev_normals
    m0x, m0y, m1x, m1y = fp_normals
    d0, d1 = bev_offsets
    e0, e1 = fp_offsets
    # R n . m
    cos0 = (c * n0x - sn * n0y) * m0x + (sn * n0x + c * n0y) * m0y
    cos1 = (c * n1x - sn * n1y) * m1x + (sn * n1x + c * n1y) * m1y
    if not abs(cos1) > limits.normal_consistency:  # NaN fails
        return False, 0.0, 0.0
    sg0 = sign_of(cos0)
    sg1 = sign_of(cos1)
    u0x, u0y, u1x, u1y = sg0 * m0x, sg0 * m0y, sg1 * m1x, sg1 * m1y
    # u_i.t = s d_i - sigma_i e_i by Cramer's rule; parallel u: no model
    det = u0x * u1y - u0y * u1x
    if abs(det) < limits.sin_par:
        return False, 0.0, 0.0
    rhs0 = s * d0 - sg0 * e0
    rhs1 = s * d1 - sg1 * e1
    tx = (rhs0 * u1y - rhs1 * u0y) / det
    ty = (u0x * rhs1 - u1x * rhs0) / det
    if not (np.isfinite(tx) and np.isfinite(ty)):
        return False, 0.0, 0.0
    return True, tx, ty


@njit
def _solve_one(bev_ids, fp_ids, s, bev, fp, rotations, limits):
    """One two-line sample with scale s, BEV lines bev_ids matched to floorplan lines
    fp_ids: (theta_a, kept_a, tx_a, ty_a, theta_b, kept_b, tx_b, ty_b) for the candidates
    R n_1 = m_1 (a) and R n_1 = -m_1 (b), theta NOT yet wrapped."""
    i0, i1 = bev_ids
    j0, j1 = fp_ids
    bnx, bny, bd = bev
    fnx, fny, fd = fp
    pair = np.int64(j0) * rotations.n_bev + i0
    theta_a = rotations.theta[pair] + 0.0  # as theta0 + flip: turns a -0.0 into +0.0
    theta_b = rotations.theta[pair] + np.pi
    n0x, n0y, n1x, n1y = bnx[i0], bny[i0], bnx[i1], bny[i1]
    # the sample's tests (the BEV normals not parallel, scale_ok) and pack's finiteness
    # of s and theta (finite exactly when its wrap is)
    ok = not abs(n0x * n1y - n0y * n1x) < limits.sin_par
    if limits.check_scale:
        ok = ok and np.isfinite(s) and s >= limits.min_scale and s <= limits.max_scale
    ok = ok and np.isfinite(s)
    if not ok:
        return theta_a, False, 0.0, 0.0, theta_b, False, 0.0, 0.0
    bev_normals = (n0x, n0y, n1x, n1y)
    fp_normals = (fnx[j0], fny[j0], fnx[j1], fny[j1])
    bev_offsets, fp_offsets = (bd[i0], bd[i1]), (fd[j0], fd[j1])
    ok_a, tx_a, ty_a = _candidate(rotations.cos_a[pair], rotations.sin_a[pair], bev_normals, fp_normals, bev_offsets, fp_offsets, s, limits)
    ok_b, tx_b, ty_b = _candidate(rotations.cos_b[pair], rotations.sin_b[pair], bev_normals, fp_normals, bev_offsets, fp_offsets, s, limits)
    ok_a = ok_a and np.isfinite(theta_a)
    ok_b = ok_b and np.isfinite(theta_b)
    return theta_a, ok_a, tx_a, ty_a, theta_b, ok_b, tx_b, ty_b


@njit
def _append_candidates(out, src, kept, i, s, res):
    """Appends sample i's surviving candidates, a before b (ordered by sample)."""
    theta_a, ok_a, tx_a, ty_a, theta_b, ok_b, tx_b, ty_b = res
    if ok_a:
        kept = append_model(out, src, kept, i, tx_a, ty_a, theta_a, s)
    if ok_b:
        kept = append_model(out, src, kept, i, tx_b, ty_b, theta_b, s)
    return kept


@njit
def _solve_samples(bev_ids, fp_ids, scales, bev, fp, rotations, limits):
    """Sample i: BEV lines bev_ids[i] matched to floorplan lines fp_ids[i] ((B, 2) each)
    at scale scales[i]. Models (tx, ty, theta, s) with theta NOT yet wrapped and their
    sample indices, in sample order, each sample's candidate a before b."""
    n = bev_ids.shape[0]
    out = np.empty((2 * n, 4), np.float64)
    src = np.empty(2 * n, np.int64)
    kept = 0
    for i in range(n):
        res = _solve_one((bev_ids[i, 0], bev_ids[i, 1]), (fp_ids[i, 0], fp_ids[i, 1]), scales[i], bev, fp, rotations, limits)
        kept = _append_candidates(out, src, kept, i, scales[i], res)
    return out[:kept].copy(), src[:kept].copy()


@njit
def _solve_drawn(draws, piece, picks, rows, scales, bev, fp, rotations, limits):
    """The draws of piece (draws.piece_cursor) solved a block at a time: BEV pair b (lines
    picks[b]) meets counts[b] floorplan pairs, rows of the table rows (P, 2); draw j has
    scale scales[j]. Models with theta NOT yet wrapped, and the draw each came from, in
    draw order, each draw's candidate a before b."""
    j_start, j_end = piece[0], piece[1]
    out = np.empty((2 * (j_end - j_start), 4), np.float64)
    src = np.empty(2 * (j_end - j_start), np.int64)
    cum, query, lines, cursor = block_buffers(draws, piece, 2)
    kept = 0
    for j in range(j_start, j_end, DRAW_BLOCK):
        m = min(DRAW_BLOCK, j_end - j)
        cursor = draw_block(draws, rows, j, m, cursor, cum, query, lines)
        for k in range(m):
            q = query[k]
            res = _solve_one((picks[q, 0], picks[q, 1]), (lines[k, 0], lines[k, 1]), scales[j + k], bev, fp, rotations, limits)
            kept = _append_candidates(out, src, kept, j + k, scales[j + k], res)
    return out[:kept].copy(), src[:kept].copy()


# --------------------------------------------------------------------------------------
# the solver
# --------------------------------------------------------------------------------------


def two_lines_at_scales(n, d, m, e, s, settings: SolverSettings, check_scale: bool):
    """Two line correspondences (normals n, m (B, 2, 2), offsets d, e (B, 2)) with known
    scales s (B,): both rotation candidates, the scale checked against the bounds where
    check_scale."""
    if len(n) == 0:
        return no_models()
    table = anchor_table(n, m, 2)
    rotations = CandidateRotations(table, np.cos(table + 0.0), np.sin(table + 0.0), np.cos(table + np.pi), np.sin(table + np.pi), 0)
    ids = sample_lines(len(n), 2)
    models, source = _solve_samples(ids, ids, np.ascontiguousarray(s, dtype=np.float64), flat_line_columns(n, d), flat_line_columns(m, e),
                                    rotations, limits_2l(settings, check_scale))
    return wrapped(models, source)


@quiet
def solve_2l(
    bev_normals,
    bev_offsets,
    fp_normals,
    fp_offsets,
    scale_prior: float,
    rng: np.random.Generator | None,
    settings: SolverSettings = SolverSettings(),
    scale_mode: ScaleMode = "prior",
):
    """Two line correspondences with a metric scale prior: s = prior + eps,
    eps ~ GGD(0, sigma, shape) (one draw per sample, shared by both rotation candidates).
    In fixed mode s = 1 exactly and rng is not used. normals (B, 2, 2), offsets (B, 2)."""
    n, d = as_batch(bev_normals, (2, 2)), as_batch(bev_offsets, (2,))
    m, e = as_batch(fp_normals, (2, 2)), as_batch(fp_offsets, (2,))
    if scale_mode == "fixed":
        return two_lines_at_scales(n, d, m, e, np.ones(len(n)), settings, check_scale=False)
    if rng is None:
        raise ValueError("solve_2l needs a Generator for the scale noise")  # programming error
    if not (np.isfinite(scale_prior) and scale_prior > 0):
        return no_models()
    s = scale_prior + sample_scale_noise(len(n), scale_prior, settings, rng)
    return two_lines_at_scales(n, d, m, e, s, settings, check_scale=True)


def drawn_2l(starts, sizes, fraction: float, rng: np.random.Generator, picks, rows, bev_lines, fp_lines, bev_angles, fp_angles,
             scale_prior: float, settings: SolverSettings, scale_mode: str):
    """draws.draw then solve_2l (prior or fixed scale_mode) on the drawn samples, a block
    of draws at a time: BEV pairs picks (B, 2), the floorplan pair table rows (P, 2). Takes
    from rng the draws' uniforms, then at a prior the scale noise (one per draw); returns
    the models and the index of the draw each came from, in draw order."""
    draws = draw_uniforms(starts, sizes, fraction, rng)
    total = len(draws.uniform)
    if scale_mode == "fixed":
        scales, check_scale = np.ones(total), False
    else:
        if not (np.isfinite(scale_prior) and scale_prior > 0):
            return no_models()
        with np.errstate(all="ignore"):  # as solve_2l (quiet)
            scales, check_scale = scale_prior + sample_scale_noise(total, scale_prior, settings, rng), True
    if total == 0:
        return no_models()
    table, trig = rotation_table(bev_angles, fp_angles, 0.0, np.pi)
    rotations = CandidateRotations(table, *trig, len(bev_angles))
    models, source = _solve_drawn(draws, whole(draws), np.ascontiguousarray(picks, dtype=np.int64), np.ascontiguousarray(rows), scales,
                                  line_columns(bev_lines), line_columns(fp_lines), rotations, limits_2l(settings, check_scale))
    return wrapped(models, source)
