"""Model refinement (paper 3.4): min over p = (tx, ty, theta, log s) of
sum_x huber(f(T_p(x))) over BEV wall points x, f a wall distance field.

Solver choice: a Levenberg-Marquardt loop with Huber weights (iteratively reweighted
least squares), written here and compiled (numba), one model at a time: each model's
iteration is independent, and one model at a time lets a single pass over the points
compute the residuals, the Jacobian, the weights, J^T W J, J^T W r and the Huber cost
together, with no (hypotheses, points, 4) temporaries. scipy.optimize.least_squares
was the first choice and was measured: method="lm" (MINPACK) does not support a robust
loss, and method="trf" with loss="huber" spends ~0.8 ms of per-iteration overhead on this
4-parameter problem (6-9 ms per hypothesis), several times the cost of the residual
itself. One LM step here is one 4x4 solve on J^T W J.
Algorithm: weights w_i = min(1, delta / |r_i|) (the Huber IRLS weights), step
(H + lambda diag(max(diag H, 1e-12))) dp = -g with H = J^T W J, g = J^T W r; a step is accepted only if the
Huber cost decreases (lambda / factor), otherwise lambda * factor and retry. With
refine.outlier_distance > 0 the loss is truncated there (weight 0 beyond it), so points
that no floorplan wall explains (a room the map lacks, clutter) stop pulling the fit.

The field is given by the caller: the estimator (estimation/ransac.py, model_generation.py,
local_refinement.py) passes the wall-SURFACE field (face_field.FaceField) rather than the
floorplan's f^c, which is 0 inside thick walls and so lets a BEV scaled a few percent too
large rest inside them; the laser scan matcher (frontend/scan_match.py) passes its own field
of the BEV's walls, and the offline correlative_search (correlative.py) the floorplan itself.
Values are bilinear between cell centres plus the distance to the grid outside it
(geometry/bilinear.py's bilinear_and_gradient_at, the difference form that shares its terms
with the gradient; Floorplan.distance reads the same interpolant in the corner-weight form,
equal to a few ulps). The Jacobian is analytic: the gradient of the bilinear interpolant
chained with d x' / d(tx, ty, theta, log s) = (e_x, e_y, perp(s R x), s R x). In
fixed-scale mode log s is held constant (3 parameters); otherwise it is clamped to the
solvers' scale bounds (shrinking the BEV onto one wall would otherwise drive every
residual to zero).
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime import threads
from ..settings.loading import RefineSettings, ScaleMode
from ..runtime.numba_support import njit
from ..geometry.bilinear import bilinear_and_gradient_at, bilinear_and_gradient_lookup, centre_coordinates


def thin_points(points: np.ndarray, max_points: int) -> np.ndarray:
    """At most max_points of the points, evenly spread over the array (deterministic)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) <= max_points:
        return points
    return points[np.unique(np.linspace(0, len(points) - 1, max_points).astype(np.int64))]


def field_value_and_gradient(floorplan, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A distance field (`floorplan`: anything with distance_field, origin and resolution)
    at points q (N, 2) and its gradient (N, 2): the LM's residuals and their gradient,
    geometry/bilinear.py's difference form (bilinear between cell centres; outside the grid
    the edge value plus the distance to the grid, whose gradient is left out), compiled,
    in one pass over the four neighbouring cells. A NaN point reads NaN."""
    field = np.ascontiguousarray(floorplan.distance_field)
    h, w = field.shape
    q = np.asarray(q, dtype=float).reshape(-1, 2)
    value, gx, gy = np.empty(len(q)), np.empty(len(q)), np.empty(len(q))
    bilinear_and_gradient_lookup(field.ravel(), h, w, float(floorplan.origin[0]), float(floorplan.origin[1]),
                                 float(floorplan.resolution), np.ascontiguousarray(q[:, 0]), np.ascontiguousarray(q[:, 1]),
                                 value, gx, gy)
    return value, np.stack([gx, gy], axis=1)


def huber_cost(r: np.ndarray, delta: float, cutoff: float = 0.0) -> np.ndarray:
    """Huber loss summed over the last axis; with cutoff > 0 each |r| is capped there first
    (a truncated Huber: a point farther than cutoff from any wall costs the same wherever it is)."""
    a = np.abs(r) if cutoff <= 0 else np.minimum(np.abs(r), cutoff)
    return np.where(a <= delta, 0.5 * a * a, delta * (a - 0.5 * delta)).sum(axis=-1)


# m, residuals up to this weigh quadratically in the fit, beyond it linearly (Huber): the
# spread of a good fit's residuals (a 0.05 m cell, range noise, wall thickness drawn a
# little off) while farther points pull less; a caller matching something else passes its
# own (scan_match, in units of its inlier distance). Was estimator.refine.huber_delta.
HUBER_DELTA = 0.1
# Levenberg-Marquardt damping: lambda starts at INITIAL_DAMPING (almost Gauss-Newton: a
# start from RANSAC or from the last frame is near the minimum) and is divided by
# DAMPING_FACTOR after a step that lowers the cost, multiplied after one that does not (the
# textbook schedule). Were estimator.refine.initial_damping and damping_factor; every
# recorded result used these (the replay samples, eval_real, the benchmark scenes).
INITIAL_DAMPING = 1e-3
DAMPING_FACTOR = 10.0


def refine(
    field,
    points: np.ndarray,
    model,
    settings: RefineSettings = RefineSettings(),
    scale_mode: ScaleMode = "free",
    scale_bounds: tuple[float, float] = (0.5, 2.0),
    huber_delta: float = HUBER_DELTA,
) -> np.ndarray:
    """Refined model row (tx, ty, theta, s); the input model if nothing improves."""
    return refine_batch(field, points, np.asarray(model, dtype=float).reshape(1, 4), settings, scale_mode, scale_bounds,
                        huber_delta)[0]


def refinable(points, models, settings: RefineSettings, scale_mode: ScaleMode, scale_bounds: tuple[float, float]):
    """What refine_batch starts from: the models (H, 4), their copy to write into,
    the thinned points, whether the scale is free, the log scale bounds, log s per model
    and which models can be refined (finite, positive scale, within the bounds when free)."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    out = models.copy()
    pts = thin_points(points, settings.max_points)
    free_scale = scale_mode != "fixed"
    lo, hi = np.log(scale_bounds[0]), np.log(scale_bounds[1])
    with np.errstate(all="ignore"):
        log_s = np.log(models[:, 3])
    ok = np.isfinite(models).all(axis=1) & (models[:, 3] > 0)
    if free_scale:
        ok &= (log_s >= lo) & (log_s <= hi)
    return models, out, pts, free_scale, lo, hi, log_s, ok


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
    gradient are geometry/bilinear.py's bilinear_and_gradient_at, the same code as
    field_value_and_gradient. Returns NaN (the trial is then rejected) when a transformed
    point is NaN."""
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
            u, v = centre_coordinates(rx + tx, ry + ty, ox, oy, res)
            if u != u or v != v:
                return np.nan  # casting NaN to a cell index is undefined: no lookup
            r, gx, gy = bilinear_and_gradient_at(field, h, w, res, u, v)
            j = k - start
            scratch[0, j] = r
            scratch[1, j] = gx
            scratch[2, j] = gy
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
            # (J * w) first, then times J or r: one fixed order of the products
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
    pivoting (A and b are overwritten). False on an exactly zero pivot (a singular system:
    the model's iteration stops there)."""
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
        evaluations = 1  # per model: each model has its own budget of max_evaluations
        while evaluations < max_evaluations:
            # stop: a non-finite H, or every |g| below the tolerance (a NaN in g counts as
            # not below it)
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


def refine_batch(
    field,
    points: np.ndarray,
    models,
    settings: RefineSettings = RefineSettings(),
    scale_mode: ScaleMode = "free",
    scale_bounds: tuple[float, float] = (0.5, 2.0),
    huber_delta: float = HUBER_DELTA,
) -> np.ndarray:
    """Refine several models (H, 4) at once, each on its own (its own damping and
    stopping test), in the compiled LM loop above; ranges of models run on the round's
    threads (threads.py). Rows that cannot be refined come back unchanged.

    field: anything with distance_field, origin and resolution (a Floorplan, or the
    estimator's wall-face field, face_field.FaceField)."""
    models, out, pts, free_scale, lo, hi, log_s, ok = refinable(points, models, settings, scale_mode, scale_bounds)
    if len(pts) < 4 or not ok.any():
        return out
    grid = np.ascontiguousarray(field.distance_field)  # float32 or float64, as given
    h, w = grid.shape
    P = np.ascontiguousarray(np.column_stack([models[ok, :3], log_s[ok]]))
    field_args = (grid.ravel(), w, h, float(field.origin[0]), float(field.origin[1]), float(field.resolution),
                  np.ascontiguousarray(pts))
    lm_args = (free_scale, float(lo), float(hi), float(huber_delta), float(settings.outlier_distance),
               float(INITIAL_DAMPING), float(DAMPING_FACTOR), float(settings.tolerance),
               int(settings.max_evaluations))

    def piece(r):  # models are refined one by one: ranges of them on the round's threads (threads.py)
        _refine_models(*field_args, P[slice(*r)], *lm_args)

    threads.run(piece, threads.ranges(len(P), _MIN_MODELS_PER_THREAD))
    refined = np.column_stack([P[:, 0], P[:, 1], (P[:, 2] + np.pi) % (2 * np.pi) - np.pi, np.exp(P[:, 3])])
    finite = np.isfinite(refined).all(axis=1)
    idx = np.flatnonzero(ok)
    out[idx[finite]] = refined[finite]
    return out
