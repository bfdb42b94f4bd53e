"""Model refinement (paper 3.4): min over p = (tx, ty, theta, log s) of
sum_x huber(f^c(T_p(x))) over BEV wall points x.

Solver choice: a Levenberg-Marquardt loop with Huber weights (iteratively reweighted
least squares), written here. scipy.optimize.least_squares was the first choice and was
measured: method="lm" (MINPACK) does not support a robust loss, and method="trf" with
loss="huber" spends ~0.8 ms of per-iteration overhead on this 4-parameter problem
(6-9 ms per hypothesis, 5 hypotheses per localization), several times the cost of the
residual itself. One LM step here is a 4x4 solve on J^T W J, so refining costs ~1-2 ms.
Algorithm: weights w_i = min(1, delta / |r_i|) (the Huber IRLS weights), step
(H + lambda diag H) dp = -g with H = J^T W J, g = J^T W r; a step is accepted only if the
Huber cost decreases (lambda / factor), otherwise lambda * factor and retry.

f^c is the floorplan's bilinear distance field (Floorplan.distance); its Jacobian is
analytic: the gradient of the bilinear interpolant chained with
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


def field_gradient(floorplan, q: np.ndarray) -> np.ndarray:
    """(N, 2) gradient of the bilinear f^c at points q (zero along clamped axes outside)."""
    field = np.asarray(floorplan.distance_field)
    h, w = field.shape
    res = float(floorplan.resolution)
    u = (q[:, 0] - floorplan.origin[0]) / res - 0.5
    v = (q[:, 1] - floorplan.origin[1]) / res - 0.5
    uc, vc = np.clip(u, 0.0, w - 1.0), np.clip(v, 0.0, h - 1.0)
    c0 = np.minimum(uc.astype(np.int64), w - 2)
    r0 = np.minimum(vc.astype(np.int64), h - 2)
    fu, fv = uc - c0, vc - r0
    f00, f01 = field[r0, c0], field[r0, c0 + 1]
    f10, f11 = field[r0 + 1, c0], field[r0 + 1, c0 + 1]
    gu = (f01 - f00) * (1.0 - fv) + (f11 - f10) * fv
    gv = (f10 - f00) * (1.0 - fu) + (f11 - f01) * fu
    inside_u = (u > 0) & (u < w - 1)
    inside_v = (v > 0) & (v < h - 1)
    return np.stack([np.where(inside_u, gu, 0.0), np.where(inside_v, gv, 0.0)], axis=1) / res


def huber_cost(r: np.ndarray, delta: float) -> float:
    a = np.abs(r)
    return float(np.where(a <= delta, 0.5 * r * r, delta * (a - 0.5 * delta)).sum())


def refine(
    floorplan,
    points: np.ndarray,
    model,
    settings: RefineSettings = RefineSettings(),
    scale_mode: ScaleMode = "free",
    scale_bounds: tuple[float, float] = (0.5, 2.0),
) -> np.ndarray:
    """Refined model row (tx, ty, theta, s); the input model if nothing improves."""
    model = np.asarray(model, dtype=float).reshape(4)
    pts = thin_points(points, settings.max_points)
    if len(pts) < 4 or not np.isfinite(model).all() or model[3] <= 0:
        return model
    free_scale = scale_mode != "fixed"
    lo, hi = np.log(scale_bounds[0]), np.log(scale_bounds[1])
    if free_scale and not lo <= np.log(model[3]) <= hi:
        return model
    delta = settings.huber_delta
    n_par = 4 if free_scale else 3

    def evaluate(p):
        s = np.exp(p[3])
        c, sn = np.cos(p[2]), np.sin(p[2])
        rx = s * (c * pts[:, 0] - sn * pts[:, 1])
        ry = s * (sn * pts[:, 0] + c * pts[:, 1])
        q = np.stack([rx + p[0], ry + p[1]], axis=1)
        return floorplan.distance(q), rx, ry, q

    def jacobian(rx, ry, q):
        g = field_gradient(floorplan, q)
        cols = [g[:, 0], g[:, 1], -g[:, 0] * ry + g[:, 1] * rx, g[:, 0] * rx + g[:, 1] * ry]
        return np.stack(cols[:n_par], axis=1)

    p = np.array([model[0], model[1], model[2], np.log(model[3])])
    r, rx, ry, q = evaluate(p)
    cost = huber_cost(r, delta)
    J = jacobian(rx, ry, q)
    lam = settings.initial_damping
    evaluations = 1
    while evaluations < settings.max_evaluations:
        a = np.abs(r)
        w = np.where(a <= delta, 1.0, delta / np.maximum(a, 1e-300))
        H = J.T @ (w[:, None] * J)
        g = J.T @ (w * r)
        if not np.isfinite(H).all() or np.abs(g).max() < settings.tolerance:
            break
        A = H + lam * np.diag(np.maximum(np.diag(H), 1e-12))
        try:
            step = np.linalg.solve(A, -g)
        except np.linalg.LinAlgError:
            break
        trial = p.copy()
        trial[:n_par] += step
        trial[3] = np.clip(trial[3], lo, hi) if free_scale else p[3]
        r_new, rx_new, ry_new, q_new = evaluate(trial)
        evaluations += 1
        cost_new = huber_cost(r_new, delta)
        if cost_new < cost:
            converged = cost - cost_new <= settings.tolerance * max(cost, 1e-12)
            p, r, cost = trial, r_new, cost_new
            J = jacobian(rx_new, ry_new, q_new)
            lam = max(lam / settings.damping_factor, 1e-12)
            if converged or np.abs(step).max() < settings.tolerance:
                break
        else:
            lam *= settings.damping_factor
            if lam > 1e12:
                break
    out = np.array([p[0], p[1], (p[2] + np.pi) % (2 * np.pi) - np.pi, np.exp(p[3])])
    return out if np.isfinite(out).all() else model
