"""Model refinement (paper 3.4): min over p = (tx, ty, theta, log s) of
sum_x huber(f(T_p(x))) over BEV wall points x, f a wall distance field.

Solver choice: a Levenberg-Marquardt loop with Huber weights (iteratively reweighted
least squares), written here and vectorised over hypotheses. scipy.optimize.least_squares
was the first choice and was measured: method="lm" (MINPACK) does not support a robust
loss, and method="trf" with loss="huber" spends ~0.8 ms of per-iteration overhead on this
4-parameter problem (6-9 ms per hypothesis), several times the cost of the residual
itself. One LM step here is a batch of 4x4 solves on J^T W J for all hypotheses at once.
Algorithm: weights w_i = min(1, delta / |r_i|) (the Huber IRLS weights), step
(H + lambda diag H) dp = -g with H = J^T W J, g = J^T W r; a step is accepted only if the
Huber cost decreases (lambda / factor), otherwise lambda * factor and retry. With
refine.outlier_distance > 0 the loss is truncated there (weight 0 beyond it), so points
that no floorplan wall explains (a room the map lacks, clutter) stop pulling the fit.

The field is given by the caller: localize() passes the wall-SURFACE field
(scoring.FaceField) rather than the floorplan's f^c, which is 0 inside thick walls and so
lets a BEV scaled a few percent too large rest inside them. Values are bilinear like
Floorplan.distance; the Jacobian is analytic: the gradient of the bilinear interpolant
chained with
d x' / d(tx, ty, theta, log s) = (e_x, e_y, perp(s R x), s R x). In fixed-scale mode
log s is held constant (3 parameters); otherwise it is clamped to the solvers' scale
bounds (shrinking the BEV onto one wall would otherwise drive every residual to zero).
"""

from __future__ import annotations

import numpy as np

from ..config import RefineSettings, ScaleMode


def thin_points(points: np.ndarray, max_points: int) -> np.ndarray:
    """At most max_points of the points, evenly spread over the array (deterministic)."""
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if len(points) <= max_points:
        return points
    return points[np.unique(np.linspace(0, len(points) - 1, max_points).astype(np.int64))]


def field_value_and_gradient(floorplan, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A distance field (floorplan.distance_field on its grid) at points q (N, 2), exactly
    as Floorplan.distance computes f^c (bilinear between
    cell centres; outside the grid the edge value plus the distance to the grid), and its
    gradient (N, 2) (that of the bilinear interpolant; the outside term is left out), in
    one pass over the four neighbouring cells."""
    value, gu, gv = _field_value_and_gradient_xy(floorplan, q[:, 0], q[:, 1])
    return value, np.stack([gu, gv], axis=1)


def _field_value_and_gradient_xy(floorplan, qx: np.ndarray, qy: np.ndarray):
    """field_value_and_gradient for coordinates given as two arrays (any shape)."""
    grid = np.asarray(floorplan.distance_field)
    h, w = grid.shape
    field = grid.ravel()  # a view for the (C-contiguous) field: no copy per call
    res = float(floorplan.resolution)
    u = (qx - floorplan.origin[0]) / res - 0.5
    v = (qy - floorplan.origin[1]) / res - 0.5
    uc, vc = np.clip(u, 0.0, w - 1.0), np.clip(v, 0.0, h - 1.0)
    c0 = np.minimum(uc.astype(np.int64), w - 2)
    r0 = np.minimum(vc.astype(np.int64), h - 2)
    fu, fv = uc - c0, vc - r0
    i = r0 * w + c0
    f00, f01, f10, f11 = field[i], field[i + 1], field[i + w], field[i + w + 1]
    bottom = f00 + (f01 - f00) * fu
    top = f10 + (f11 - f10) * fu
    value = bottom + (top - bottom) * fv + np.hypot(u - uc, v - vc) * res
    gu = (f01 - f00) + (f11 - f10 - f01 + f00) * fv
    gv = top - bottom
    gu = np.where(u == uc, gu, 0.0) / res
    gv = np.where(v == vc, gv, 0.0) / res
    return value, gu, gv


def huber_cost(r: np.ndarray, delta: float, cutoff: float = 0.0) -> np.ndarray:
    """Huber loss summed over the last axis; with cutoff > 0 each |r| is capped there first
    (a truncated Huber: a point farther than cutoff from any wall costs the same wherever it is)."""
    a = np.abs(r) if cutoff <= 0 else np.minimum(np.abs(r), cutoff)
    return np.where(a <= delta, 0.5 * a * a, delta * (a - 0.5 * delta)).sum(axis=-1)


def refine(
    field,
    points: np.ndarray,
    model,
    settings: RefineSettings = RefineSettings(),
    scale_mode: ScaleMode = "free",
    scale_bounds: tuple[float, float] = (0.5, 2.0),
) -> np.ndarray:
    """Refined model row (tx, ty, theta, s); the input model if nothing improves."""
    return refine_batch(field, points, np.asarray(model, dtype=float).reshape(1, 4), settings, scale_mode, scale_bounds)[0]


def refinable(points, models, settings: RefineSettings, scale_mode: ScaleMode, scale_bounds: tuple[float, float]):
    """What both refine_batch paths start from: the models (H, 4), their copy to write into,
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


def refine_batch(
    field,
    points: np.ndarray,
    models,
    settings: RefineSettings = RefineSettings(),
    scale_mode: ScaleMode = "free",
    scale_bounds: tuple[float, float] = (0.5, 2.0),
    kernels: str = "numpy",
) -> np.ndarray:
    """Refine several models (H, 4) at once: each has its own damping and stopping test,
    but every LM iteration evaluates all still-active models in one vectorised pass (the
    per-call overhead, not the arithmetic, dominates a 4-parameter problem).

    field: anything with distance_field, origin and resolution (a Floorplan, or the
    estimator's wall-face field, scoring.FaceField). kernels: "numba" runs the same
    iteration compiled, one model at a time (refine_numba.py; the optional [fast] extra)."""
    if kernels == "numba":
        from .refine_numba import refine_batch_numba  # the optional [fast] extra, imported on first use

        return refine_batch_numba(field, points, models, settings, scale_mode, scale_bounds)
    models, out, pts, free_scale, lo, hi, log_s, ok = refinable(points, models, settings, scale_mode, scale_bounds)
    if len(pts) < 4 or not ok.any():
        return out
    delta, cutoff = settings.huber_delta, settings.outlier_distance
    n_par = 4 if free_scale else 3

    def evaluate(P):
        """Residuals f^c(T_p(x)) (A, N) and their Jacobians (A, N, n_par)."""
        s = np.exp(P[:, 3:4])
        c, sn = np.cos(P[:, 2:3]), np.sin(P[:, 2:3])
        rx = s * (c * pts[:, 0] - sn * pts[:, 1])
        ry = s * (sn * pts[:, 0] + c * pts[:, 1])
        # the same values as stacking (x, y) and calling field_value_and_gradient, without
        # the interleaved copies
        r, gx, gy = _field_value_and_gradient_xy(field, rx + P[:, 0:1], ry + P[:, 1:2])
        J = np.empty((*rx.shape, n_par))
        J[..., 0], J[..., 1] = gx, gy
        J[..., 2] = gy * rx - gx * ry
        if free_scale:
            J[..., 3] = gx * rx + gy * ry
        return r, J

    P = np.column_stack([models[ok, :3], log_s[ok]])
    r, J = evaluate(P)
    cost = huber_cost(r, delta, cutoff)
    lam = np.full(len(P), settings.initial_damping)
    active = np.ones(len(P), dtype=bool)
    evaluations = 1
    while evaluations < settings.max_evaluations and active.any():
        a = np.flatnonzero(active)
        ra, Ja = r[a], J[a]
        absr = np.abs(ra)
        w = np.where(absr <= delta, 1.0, delta / np.maximum(absr, 1e-300))
        if cutoff > 0:
            w = np.where(absr > cutoff, 0.0, w)
        WJt = (Ja * w[..., None]).transpose(0, 2, 1)
        H = WJt @ Ja  # J^T W J, (A, p, p)
        g = (WJt @ ra[..., None])[..., 0]  # J^T W r, (A, p)
        done = ~np.isfinite(H).all(axis=(1, 2)) | (np.abs(g).max(axis=1) < settings.tolerance)
        diag = np.maximum(np.diagonal(H, axis1=1, axis2=2), 1e-12)
        A = H + (lam[a, None] * diag)[:, :, None] * np.eye(n_par)
        try:
            step = np.linalg.solve(np.where(done[:, None, None], np.eye(n_par), A), -g[..., None])[..., 0]
        except np.linalg.LinAlgError:
            break
        trial = P[a].copy()
        trial[:, :n_par] += step
        trial[:, 3] = np.clip(trial[:, 3], lo, hi) if free_scale else P[a, 3]
        r_new, J_new = evaluate(trial)
        evaluations += 1
        cost_new = huber_cost(r_new, delta, cutoff)
        better = (cost_new < cost[a]) & ~done
        converged = better & (
            (cost[a] - cost_new <= settings.tolerance * np.maximum(cost[a], 1e-12)) | (np.abs(step).max(axis=1) < settings.tolerance)
        )
        b = a[better]
        P[b], r[b], J[b], cost[b] = trial[better], r_new[better], J_new[better], cost_new[better]
        lam[b] = np.maximum(lam[b] / settings.damping_factor, 1e-12)
        worse = a[~better & ~done]
        lam[worse] *= settings.damping_factor
        active[a[done | converged]] = False
        active[worse[lam[worse] > 1e12]] = False
    refined = np.column_stack([P[:, 0], P[:, 1], (P[:, 2] + np.pi) % (2 * np.pi) - np.pi, np.exp(P[:, 3])])
    finite = np.isfinite(refined).all(axis=1)
    idx = np.flatnonzero(ok)
    out[idx[finite]] = refined[finite]
    return out
