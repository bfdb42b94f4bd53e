"""The refinement's Levenberg-Marquardt loop compiled (estimator.kernels: numba; the
[fast] extra).

The same algorithm as refine.refine_batch, step for step: the same thinned points, Huber
IRLS weights (truncated at refine.outlier_distance), damping schedule, acceptance and
stopping tests, evaluation budget and scale clamping. Where the numpy path vectorises
over hypotheses, the kernel loops over them: each model's iteration is independent
anyway, and one model at a time lets a single pass over the points compute the residuals,
the Jacobian, the weights, J^T W J, J^T W r and the Huber cost together, with no
(hypotheses, points, 4) temporaries.

Not bit-identical to numpy, by design: numpy sums the cost pairwise and J^T W J in BLAS,
the kernel sums sequentially, and exp/cos/sin of the parameters come from libm rather
than numpy. The residual of each point is the same arithmetic as
refine._field_value_and_gradient_xy, so results agree to ~1e-12, except where a step's
acceptance is a near-tie that the last bits decide (the two paths then take different,
equally good, steps). Two corner cases differ on purpose, both unreachable with finite
fields and models: a damped system with an exactly zero pivot stops only its own model
(numpy's batched solve raises and the whole batch stops), and a trial whose transformed
points are NaN is rejected like any costlier step (numpy would index the field with
garbage).
"""

from __future__ import annotations

import math

import numpy as np

from .. import threads
from ..config import RefineSettings, ScaleMode
from ..numba_support import njit
from .refine import refinable


# Points per evaluation stage. A point's lookup is a long dependency chain (transform,
# divide, clip, cast, four loads); done for a block of points first, the chains of
# neighbouring points overlap in the CPU, which one fused loop body per point (~150
# instructions) does not allow; the block's scratch (5 x 64 doubles) stays in L1. Measured
# 1.5x faster per evaluation than a single loop, with the same results bit for bit.
BLOCK = 64
# a refinement is split over threads only in pieces of at least this many models (each
# runs up to max_evaluations passes over the points)
_MIN_MODELS_PER_THREAD = 2


@njit
def _evaluate(field, w, h, ox, oy, res, pts, tx, ty, theta, log_s, free_scale, delta, cutoff, H, g, scratch):
    """Huber cost of the model (tx, ty, theta, log s) over pts, and its IRLS normal
    equations H = J^T W J, g = J^T W r written into H (4, 4) and g (4,) (the scale row and
    column only in free-scale mode), in one pass over the points, BLOCK at a time
    (scratch: (5, BLOCK)).

    field is the distance field raveled (h rows of w cells); per point, the residual and its
    gradient are refine._field_value_and_gradient_xy's arithmetic, operation for operation
    (a float32 field's differences stay float32 as in numpy). Returns NaN (the trial is then
    rejected) when a transformed point is NaN."""
    s = math.exp(log_s)
    c = math.cos(theta)
    sn = math.sin(theta)
    # scalar accumulators (upper triangle of the symmetric H): they stay in registers
    h00 = h01 = h02 = h03 = h11 = h12 = h13 = h22 = h23 = h33 = 0.0
    g0 = g1 = g2 = g3 = 0.0
    cost = 0.0
    n = pts.shape[0]
    for start in range(0, n, BLOCK):
        stop = min(start + BLOCK, n)
        # stage 1: the transformed points, their field values and gradients
        for k in range(start, stop):
            x = pts[k, 0]
            y = pts[k, 1]
            rx = s * (c * x - sn * y)
            ry = s * (sn * x + c * y)
            u = (rx + tx - ox) / res - 0.5
            v = (ry + ty - oy) / res - 0.5
            if u != u or v != v:
                return np.nan  # casting NaN to a cell index is undefined: no lookup
            # np.clip(u, 0, w - 1) and np.clip(v, 0, h - 1)
            uc = u
            if uc < 0.0:
                uc = 0.0
            elif uc > w - 1.0:
                uc = w - 1.0
            vc = v
            if vc < 0.0:
                vc = 0.0
            elif vc > h - 1.0:
                vc = h - 1.0
            c0 = np.int64(uc)  # truncation of a non-negative value, as astype(int64)
            if c0 > w - 2:
                c0 = w - 2
            r0 = np.int64(vc)
            if r0 > h - 2:
                r0 = h - 2
            fu = uc - c0
            fv = vc - r0
            i = r0 * w + c0
            f00 = field[i]
            f01 = field[i + 1]
            f10 = field[i + w]
            f11 = field[i + w + 1]
            bottom = f00 + (f01 - f00) * fu
            top = f10 + (f11 - f10) * fu
            r = bottom + (top - bottom) * fv
            # the distance to the grid (hypot(0, 0) * res = +0.0 inside it; the libm call is skipped)
            r += math.hypot(u - uc, v - vc) * res if u != uc or v != vc else 0.0
            gu = (f01 - f00) + (f11 - f10 - f01 + f00) * fv
            gv = top - bottom
            j = k - start
            scratch[0, j] = r
            # outside the grid the gradient of the edge-distance term is left out, as in numpy
            scratch[1, j] = (gu if u == uc else 0.0) / res
            scratch[2, j] = (gv if v == vc else 0.0) / res
            scratch[3, j] = rx
            scratch[4, j] = ry
        # stage 2: Jacobian rows, weights, cost and the normal equations
        for j in range(stop - start):
            r = scratch[0, j]
            gx = scratch[1, j]
            gy = scratch[2, j]
            rx = scratch[3, j]
            ry = scratch[4, j]
            j2 = gy * rx - gx * ry
            j3 = gx * rx + gy * ry if free_scale else 0.0
            # Huber IRLS weight min(1, delta / |r|), 0 beyond the cutoff; NaN stays NaN (as
            # np.maximum would give) so a NaN residual makes H non-finite and stops the model
            a = abs(r)
            if a <= delta:
                wt = 1.0
            else:
                wt = delta / (1e-300 if a < 1e-300 else a)
            if cutoff > 0 and a > cutoff:
                wt = 0.0
                a = cutoff  # the truncated loss: |r| capped at the cutoff
            cost += 0.5 * a * a if a <= delta else delta * (a - 0.5 * delta)
            # (J * w) then times J or r, the order of numpy's products
            w0 = gx * wt
            w1 = gy * wt
            w2 = j2 * wt
            w3 = j3 * wt
            h00 += w0 * gx
            h01 += w0 * gy
            h02 += w0 * j2
            h03 += w0 * j3
            h11 += w1 * gy
            h12 += w1 * j2
            h13 += w1 * j3
            h22 += w2 * j2
            h23 += w2 * j3
            h33 += w3 * j3
            g0 += w0 * r
            g1 += w1 * r
            g2 += w2 * r
            g3 += w3 * r
    H[0, 0] = h00
    H[0, 1] = H[1, 0] = h01
    H[0, 2] = H[2, 0] = h02
    H[0, 3] = H[3, 0] = h03
    H[1, 1] = h11
    H[1, 2] = H[2, 1] = h12
    H[1, 3] = H[3, 1] = h13
    H[2, 2] = h22
    H[2, 3] = H[3, 2] = h23
    H[3, 3] = h33
    g[0] = g0
    g[1] = g1
    g[2] = g2
    g[3] = g3
    return cost


@njit
def _solve(A, b, n, x):
    """x = A^-1 b for the leading n x n block, by Gaussian elimination with partial
    pivoting (A and b are overwritten). False on an exactly zero pivot, where LAPACK's
    solve raises LinAlgError."""
    for col in range(n):
        piv = col
        for row in range(col + 1, n):
            if abs(A[row, col]) > abs(A[piv, col]):
                piv = row
        if A[piv, col] == 0.0:
            return False
        if piv != col:
            for k in range(n):
                A[col, k], A[piv, k] = A[piv, k], A[col, k]
            b[col], b[piv] = b[piv], b[col]
        for row in range(col + 1, n):
            f = A[row, col] / A[col, col]
            for k in range(col + 1, n):
                A[row, k] -= f * A[col, k]
            b[row] -= f * b[col]
    for row in range(n - 1, -1, -1):
        acc = b[row]
        for k in range(row + 1, n):
            acc -= A[row, k] * x[k]
        x[row] = acc / A[row, row]
    return True


@njit
def _refine_models(field, w, h, ox, oy, res, pts, P, free_scale, lo, hi, delta, cutoff,
                   initial_damping, damping_factor, tolerance, max_evaluations):
    """Run the LM iteration on each row (tx, ty, theta, log s) of P in place."""
    n = 4 if free_scale else 3
    H = np.empty((4, 4))
    g = np.empty(4)
    H_new = np.empty((4, 4))
    g_new = np.empty(4)
    A = np.empty((4, 4))
    rhs = np.empty(4)
    step = np.empty(4)
    scratch = np.empty((5, BLOCK))
    for m in range(P.shape[0]):
        tx, ty, theta, log_s = P[m, 0], P[m, 1], P[m, 2], P[m, 3]
        cost = _evaluate(field, w, h, ox, oy, res, pts, tx, ty, theta, log_s, free_scale, delta, cutoff, H, g, scratch)
        lam = initial_damping
        evaluations = 1  # per model, as numpy's batch counter is for every model still active
        while evaluations < max_evaluations:
            # numpy's `done`: a non-finite H or every |g| below the tolerance (a NaN in g
            # fails the test, as NaN < tolerance does in numpy's max)
            finite = True
            small = True
            for i in range(n):
                if abs(g[i]) >= tolerance or g[i] != g[i]:
                    small = False
                for j in range(n):
                    if not math.isfinite(H[i, j]):
                        finite = False
            if not finite or small:
                break
            # (H + lam diag(max(diag H, 1e-12))) step = -g
            for i in range(n):
                for j in range(n):
                    A[i, j] = H[i, j]
                d = H[i, i] if H[i, i] > 1e-12 else 1e-12
                A[i, i] = H[i, i] + lam * d
                rhs[i] = -g[i]
            if not _solve(A, rhs, n, step):
                break
            t_tx = tx + step[0]
            t_ty = ty + step[1]
            t_theta = theta + step[2]
            t_log_s = log_s
            if free_scale:
                t_log_s = log_s + step[3]
                if t_log_s < lo:
                    t_log_s = lo
                elif t_log_s > hi:
                    t_log_s = hi
            cost_new = _evaluate(field, w, h, ox, oy, res, pts, t_tx, t_ty, t_theta, t_log_s, free_scale, delta, cutoff, H_new, g_new, scratch)
            evaluations += 1
            if cost_new < cost:
                small_step = True
                for i in range(n):
                    if not abs(step[i]) < tolerance:
                        small_step = False
                converged = cost - cost_new <= tolerance * (cost if cost > 1e-12 else 1e-12) or small_step
                tx, ty, theta, log_s, cost = t_tx, t_ty, t_theta, t_log_s, cost_new
                H, H_new = H_new, H
                g, g_new = g_new, g
                lam = lam / damping_factor
                if lam < 1e-12:
                    lam = 1e-12
                if converged:
                    break
            else:
                lam *= damping_factor
                if lam > 1e12:
                    break
        P[m, 0] = tx
        P[m, 1] = ty
        P[m, 2] = theta
        P[m, 3] = log_s


def refine_batch_numba(
    field,
    points: np.ndarray,
    models,
    settings: RefineSettings = RefineSettings(),
    scale_mode: ScaleMode = "free",
    scale_bounds: tuple[float, float] = (0.5, 2.0),
) -> np.ndarray:
    """refine.refine_batch with the LM loop compiled: same arguments, same output
    conventions (rows that cannot be refined come back unchanged)."""
    models, out, pts, free_scale, lo, hi, log_s, ok = refinable(points, models, settings, scale_mode, scale_bounds)
    if len(pts) < 4 or not ok.any():
        return out
    grid = np.ascontiguousarray(field.distance_field)  # float32 or float64, as given
    h, w = grid.shape
    # log s from numpy (not libm), so the starting point equals the numpy path's
    P = np.ascontiguousarray(np.column_stack([models[ok, :3], log_s[ok]]))
    field_args = (grid.ravel(), w, h, float(field.origin[0]), float(field.origin[1]), float(field.resolution),
                  np.ascontiguousarray(pts))
    lm_args = (free_scale, float(lo), float(hi), float(settings.huber_delta), float(settings.outlier_distance),
               float(settings.initial_damping), float(settings.damping_factor), float(settings.tolerance),
               int(settings.max_evaluations))

    def piece(r):  # models are refined one by one: ranges of them on the round's threads (threads.py)
        _refine_models(*field_args, P[slice(*r)], *lm_args)

    threads.run(piece, threads.ranges(len(P), _MIN_MODELS_PER_THREAD))
    # the output conversion in numpy, exactly as refine_batch writes it
    refined = np.column_stack([P[:, 0], P[:, 1], (P[:, 2] + np.pi) % (2 * np.pi) - np.pi, np.exp(P[:, 3])])
    finite = np.isfinite(refined).all(axis=1)
    idx = np.flatnonzero(ok)
    out[idx[finite]] = refined[finite]
    return out
