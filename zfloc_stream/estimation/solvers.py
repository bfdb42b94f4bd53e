"""Minimal solvers for the Sim(2) alignment x' = s R x + t (BEV -> floorplan), paper 3.2.

Every solver is a plain function from a BATCH of minimal samples (arrays with a leading
axis B) to a batch of models: an (M, 4) array of rows (tx, ty, theta, s) and an (M,) array
naming the sample each model came from. A sample may give zero, one or two models.
Degenerate samples (parallel lines, coincident centres, a centre on its line, a scale that
is non-positive, non-finite or outside [min_scale, max_scale]) give no model: never an
exception, never a NaN.

Lines are in normal form n.x + d = 0. Under the transform a BEV line (n, d) becomes
(R n, s d - (R n).t); a floorplan line (m, e) matches it up to the sign of its normal, so
with sigma = sign((R n).m) and u = sigma m (~ R n) every correspondence gives
    u.t = s d - sigma e.
Rotation comes from the first (anchor) line pair: R n_1 = m_1 or R n_1 = -m_1. For the
free-scale solvers the second candidate gives exactly the first transform with s and R
negated (the linear systems are odd in R), i.e. one of the two always has s < 0; solving
once and flipping (theta + pi, -s) when s < 0 is therefore the same as trying both and
discarding the negative one. With a known scale (2L, fixed mode) both candidates are
genuinely different transforms and both are returned.

Scale modes ("free" | "prior" | "fixed"):
  free   3L, 2C, LC estimate s (2L needs a prior: it is not used in this mode).
  prior  as free, plus 2L with s = prior + GGD noise.
  fixed  s = 1 exactly: 3L and 2L both reduce to one rigid two-line solver (the third
         line is not needed), 2C to a rigid two-point fit, LC to rotation from the line
         and translation from the centre. The scale the sample implies (distance ratio for
         2C, offset ratio for LC) must still be positive and inside [min_scale, max_scale],
         which rejects samples that cannot be metric-consistent.
"""

from __future__ import annotations

import functools

import numpy as np

from ..config import ScaleMode, SolverSettings

MODEL_COLUMNS = ("tx", "ty", "theta", "s")


def _quiet(solver):
    """Non-finite or degenerate inputs are filtered by masks, never by warnings: silence
    numpy's floating-point warnings inside a solver (the final finiteness mask is what
    guarantees no NaN model escapes)."""

    @functools.wraps(solver)
    def wrapped(*args, **kwargs):
        with np.errstate(all="ignore"):
            return solver(*args, **kwargs)

    return wrapped


def _empty() -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)


def _angle(v: np.ndarray) -> np.ndarray:
    return np.arctan2(v[..., 1], v[..., 0])


def _rotate(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 2) vectors by per-row angles theta (broadcast over trailing axes)."""
    c, s = np.cos(theta), np.sin(theta)
    while c.ndim < v.ndim - 1:
        c, s = c[..., None], s[..., None]
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _wrap(theta: np.ndarray) -> np.ndarray:
    return (theta + np.pi) % (2.0 * np.pi) - np.pi


def _pack(tx, ty, theta, s, keep, source) -> tuple[np.ndarray, np.ndarray]:
    theta = _wrap(theta)
    keep = keep & np.isfinite(tx) & np.isfinite(ty) & np.isfinite(theta) & np.isfinite(s)
    idx = np.flatnonzero(keep)
    return np.stack([tx[idx], ty[idx], theta[idx], s[idx]], axis=-1), source[idx]


def _scale_ok(s: np.ndarray, settings: SolverSettings) -> np.ndarray:
    return np.isfinite(s) & (s >= settings.min_scale) & (s <= settings.max_scale)


def _parallel(a: np.ndarray, b: np.ndarray, settings: SolverSettings) -> np.ndarray:
    """Unit normals a, b (..., 2) are parallel (either sign) within parallel_angle_deg."""
    return np.abs(_cross(a, b)) < np.sin(np.deg2rad(settings.parallel_angle_deg))


def _as(x, shape_tail: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    return a.reshape((-1, *shape_tail))


# --------------------------------------------------------------------------------------
# scale prior noise (2L)
# --------------------------------------------------------------------------------------


def scale_prior_sigma(scale_prior: float, settings: SolverSettings) -> float:
    """sigma of the GGD(0, sigma, beta) with P(|eps| <= window * prior) = prob.

    For a generalised Gaussian, |eps / sigma|^beta ~ Gamma(1 / beta), so
    P(|eps| <= a) = P(Gamma(1/beta) <= (a / sigma)^beta) and
    sigma = a / gammaincinv(1/beta, prob)^(1/beta).
    """
    from scipy.special import gammaincinv  # here, not at import: a CLI error must not pay for it

    beta = settings.scale_prior_ggd_shape
    a = settings.scale_prior_window * scale_prior
    return float(a / gammaincinv(1.0 / beta, settings.scale_prior_prob) ** (1.0 / beta))


def sample_scale_noise(n: int, scale_prior: float, settings: SolverSettings, rng: np.random.Generator) -> np.ndarray:
    """n draws of eps ~ GGD(0, sigma, beta) from the given generator."""
    beta = settings.scale_prior_ggd_shape
    sigma = scale_prior_sigma(scale_prior, settings)
    magnitude = rng.gamma(1.0 / beta, 1.0, size=n) ** (1.0 / beta)
    sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    return sigma * sign * magnitude


# --------------------------------------------------------------------------------------
# line solvers
# --------------------------------------------------------------------------------------


def _anchor_rotation(n: np.ndarray, m: np.ndarray) -> np.ndarray:
    """theta with R n_1 = m_1 (the first of the two candidates)."""
    return _angle(m[:, 0]) - _angle(n[:, 0])


def _det3(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Determinants of the 3x3 matrices with columns a, b, c (each (B, 3))."""
    return (
        a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
        - b[:, 0] * (a[:, 1] * c[:, 2] - a[:, 2] * c[:, 1])
        + c[:, 0] * (a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1])
    )


def _signed_fp(theta, n, m, e):
    """u_i = sigma_i m_i ~ R n_i, sigma_i e_i and |cos| between R n_i and m_i."""
    rn = _rotate(theta, n)
    cos = np.einsum("bij,bij->bi", rn, m)
    sigma = np.where(cos < 0, -1.0, 1.0)
    return sigma[..., None] * m, sigma * e, np.abs(cos)


@_quiet
def solve_3l(bev_normals, bev_offsets, fp_normals, fp_offsets, settings: SolverSettings = SolverSettings(), scale_mode: ScaleMode = "free"):
    """Three line correspondences -> models. Arrays: normals (B, 3, 2), offsets (B, 3);
    line 0 is the anchor fixing the rotation. Normal consistency |(R n_i).m_i| > tau_p is
    checked for lines 1, 2 before the 3x3 system is solved. In fixed mode the third line
    is ignored (rigid two-line solver)."""
    n, d = _as(bev_normals, (3, 2)), _as(bev_offsets, (3,))
    m, e = _as(fp_normals, (3, 2)), _as(fp_offsets, (3,))
    if scale_mode == "fixed":
        return _solve_two_lines(n[:, :2], d[:, :2], m[:, :2], e[:, :2], np.ones(len(n)), settings)
    B = len(n)
    if B == 0:
        return _empty()
    theta = _anchor_rotation(n, m)
    ok = _normals_consistent(theta, [(n[:, i, 0], n[:, i, 1], m[:, i, 0], m[:, i, 1]) for i in (1, 2)], settings)
    source = np.flatnonzero(ok)
    n, d, m, e = n[source], d[source], m[source], e[source]
    return _solve_3l_components(
        [(n[:, k, 0], n[:, k, 1]) for k in range(3)], [d[:, k] for k in range(3)],
        [(m[:, k, 0], m[:, k, 1]) for k in range(3)], [e[:, k] for k in range(3)], theta[source], source, settings,
    )


def _normals_consistent(theta, lines, settings: SolverSettings, c=None, sn=None, cos_out: list | None = None) -> np.ndarray:
    """|(R(theta) n_i).m_i| > normal_consistency for every line i, lines = [(nx, ny, mx,
    my), ...] (normal components, one array each): the arithmetic of _signed_fp, element
    by element, so the same test. c, sn: cos and sin of theta when known; cos_out
    collects the signed cosines."""
    if c is None:
        c, sn = np.cos(theta), np.sin(theta)
    ok = np.ones(len(theta), dtype=bool)
    for nx, ny, mx, my in lines:
        cos_i = (c * nx - sn * ny) * mx + (sn * nx + c * ny) * my
        ok &= np.abs(cos_i) > settings.normal_consistency
        if cos_out is not None:
            cos_out.append(cos_i)
    return ok


@_quiet
def solve_3l_indexed(bev_lines, fp_lines, b, f, bev_angles, fp_angles, settings: SolverSettings = SolverSettings(), kernels: str = "numpy"):
    """solve_3l (free / prior scale) for samples given by line indices: b = (b0, b1, b2)
    into bev_lines, f = (f0, f1, f2) into fp_lines (three index arrays each, or (B, 3)
    arrays), with the normal angles of both line sets given (_angle of their normals).
    The normal test runs on gathers of single components and only its survivors are
    gathered, one contiguous array per component. The same models as solve_3l on the
    gathered arrays, bit for bit. kernels: "numba" runs the three stages in one compiled
    loop per sample (solvers_numba), the same models in the same order."""
    b = [np.asarray(v) for v in (b.T if isinstance(b, np.ndarray) else b)]
    f = [np.asarray(v) for v in (f.T if isinstance(f, np.ndarray) else f)]
    if len(b[0]) == 0:
        return _empty()
    bnx, bny, fnx, fny = (np.ascontiguousarray(a) for a in (bev_lines.normals[:, 0], bev_lines.normals[:, 1], fp_lines.normals[:, 0], fp_lines.normals[:, 1]))
    if kernels == "numba":
        from .solvers_numba import solve_3l_indexed as compiled  # the optional [fast] extra, imported on first use

        return compiled(bnx, bny, bev_lines.offsets, fnx, fny, fp_lines.offsets, b, f, bev_angles, fp_angles, settings)
    # The rotation depends on the anchor pair only: theta, cos and sin are computed once
    # per (floorplan line, BEV line) pair and gathered (element-wise functions of the same
    # theta: the same values as computing them per sample).
    pair = f[0].astype(np.int64) * len(bev_angles) + b[0]
    table = (fp_angles[:, None] - bev_angles[None, :]).ravel()
    theta = table[pair]
    c, sn = np.cos(table)[pair], np.sin(table)[pair]
    cos12: list = []
    ok = _normals_consistent(theta, [(bnx[b[i]], bny[b[i]], fnx[f[i]], fny[f[i]]) for i in (1, 2)], settings, c, sn, cos12)
    source = np.flatnonzero(ok)
    bd, fd = bev_lines.offsets, fp_lines.offsets
    bs, fs, cs = ([v[source] for v in arrays] for arrays in (b, f, cos12))
    plausible = _scale_plausible(bs, fs, cs, bd, fd, fnx, fny, settings)
    source = source[plausible]
    bs, fs, cs = ([v[plausible] for v in arrays] for arrays in (bs, fs, cs))
    return _solve_3l_components(
        [(bnx[i], bny[i]) for i in bs], [bd[i] for i in bs], [(fnx[i], fny[i]) for i in fs], [fd[i] for i in fs],
        theta[source], source, settings, c[source], sn[source], cs,
    )


# A sample is solved exactly only when its scale, computed the short way, lies within the
# bounds widened by this factor: far beyond any rounding difference between the two ways
# (a regular system's determinant is >= singular_tolerance times its row norms), so the
# models kept are the same; at a metric prior ~93% of the samples end here.
_SCALE_SLACK = 1.05


def _scale_plausible(b, f, cos12, bd, fd, fnx, fny, settings: SolverSettings) -> np.ndarray:
    """Which 3L samples (line indices b, f; signed cosines of lines 1 and 2) can have a
    scale within [min_scale, max_scale]. Cramer's rule for s in _solve_3l_components
    involves the floorplan normals and the signs only: expanding both determinants along
    their first column, s = sum_k sigma_k e_k C_k / sum_k d_k C_k with C_k the signed
    2x2 minors of the columns -sigma m_x, -sigma m_y (sigma_0 = +1: the anchor's rotation
    maps its normal onto the floorplan's). Gathers and a dozen products per sample,
    against the full solve's three 3x3 determinants."""
    m = [(fnx[i], fny[i]) for i in f]
    sg1, sg2 = (np.where(c < 0, -1.0, 1.0) for c in cos12)
    x12 = m[1][0] * m[2][1] - m[2][0] * m[1][1]
    x02 = m[0][0] * m[2][1] - m[2][0] * m[0][1]
    x01 = m[0][0] * m[1][1] - m[1][0] * m[0][1]
    cof = (sg1 * sg2 * x12, -sg2 * x02, sg1 * x01)
    den = bd[b[0]] * cof[0] + bd[b[1]] * cof[1] + bd[b[2]] * cof[2]
    num = fd[f[0]] * cof[0] + sg1 * fd[f[1]] * cof[1] + sg2 * fd[f[2]] * cof[2]
    a_num, a_den = np.abs(num), np.abs(den)
    with np.errstate(all="ignore"):
        inside = (a_num >= settings.min_scale / _SCALE_SLACK * a_den) & (a_num <= settings.max_scale * _SCALE_SLACK * a_den)
    return inside | ~np.isfinite(num) | ~np.isfinite(den)


def _solve_3l_components(N, D, M, E, theta, source, settings: SolverSettings, c=None, sn=None, cos12=None):
    """The rest of solve_3l for samples that passed the normal test, on per-line
    component arrays: N[k] = (nx, ny) and D[k] of BEV line k, M[k], E[k] of its floorplan
    line. Element by element the arithmetic of _parallel, _signed_fp and _det3 (the
    columns-of-A formulation below), so the models are the same to the bit. c, sn: cos
    and sin of theta when known; cos12: the signed cosines of lines 1 and 2 when known."""
    sin_par = np.sin(np.deg2rad(settings.parallel_angle_deg))

    def parallel(a, b):
        return np.abs(a[0] * b[1] - a[1] * b[0]) < sin_par

    keep = ~(parallel(N[0], N[1]) & parallel(N[0], N[2]) & parallel(N[1], N[2]))
    if not keep.any():
        return _empty()
    if not keep.all():
        N = [(x[keep], y[keep]) for x, y in N]
        M = [(x[keep], y[keep]) for x, y in M]
        D, E = [v[keep] for v in D], [v[keep] for v in E]
        theta, source = theta[keep], source[keep]
        if c is not None:
            c, sn = c[keep], sn[keep]
        if cos12 is not None:
            cos12 = [v[keep] for v in cos12]
    if c is None:
        c, sn = np.cos(theta), np.sin(theta)
    # u_k = sigma_k m_k ~ R n_k, se_k = sigma_k e_k (as _signed_fp)
    A1, A2, SE = [], [], []  # columns of A (minus u) and right-hand side, per row k
    for k, ((nx, ny), (mx, my), e) in enumerate(zip(N, M, E)):
        if k > 0 and cos12 is not None:
            cos = cos12[k - 1]
        else:
            cos = (c * nx - sn * ny) * mx + (sn * nx + c * ny) * my
        sigma = np.where(cos < 0, -1.0, 1.0)
        A1.append(-(sigma * mx))
        A2.append(-(sigma * my))
        SE.append(sigma * e)
    # rows: s d_i - u_i.t = sigma_i e_i  ->  A [s, tx, ty]^T = b, solved by Cramer's
    # rule (closed form: np.linalg on millions of 3x3 systems is several times slower)
    A0 = D
    det = _det3_rows(A0, A1, A2)
    # Hadamard's bound: |det| <= product of row norms; a tiny ratio means (near) singular
    norms = [np.sqrt(A0[k] * A0[k] + A1[k] * A1[k] + A2[k] * A2[k]) for k in range(3)]
    row_norms = norms[0] * norms[1] * norms[2]
    regular = np.abs(det) > settings.singular_tolerance * np.maximum(row_norms, 1e-300)
    safe = np.where(regular, det, 1.0)
    s = _det3_rows(SE, A1, A2) / safe
    tx = _det3_rows(A0, SE, A2) / safe
    ty = _det3_rows(A0, A1, SE) / safe
    flip = s < 0  # the R n_1 = -m_1 candidate: same t, theta + pi, -s
    theta = np.where(flip, theta + np.pi, theta)
    s = np.abs(s)
    return _pack(tx, ty, theta, s, regular & _scale_ok(s, settings), source)


def _det3_rows(a, b, c):
    """_det3 for columns given as three per-row arrays each (a[k] = a[:, k])."""
    return a[0] * (b[1] * c[2] - b[2] * c[1]) - b[0] * (a[1] * c[2] - a[2] * c[1]) + c[0] * (a[1] * b[2] - a[2] * b[1])


def _solve_two_lines(n, d, m, e, s, settings: SolverSettings, skip_scale_check: bool = False):
    """Two line correspondences with known scales s (B,): both rotation candidates."""
    B = len(n)
    if B == 0:
        return _empty()
    source = np.arange(B)
    ok = ~_parallel(n[:, 0], n[:, 1], settings)
    if not skip_scale_check:
        ok &= _scale_ok(s, settings)
    out_models, out_source = [], []
    theta0 = _anchor_rotation(n, m)
    for flip in (0.0, np.pi):
        theta = theta0 + flip
        u, se, cos = _signed_fp(theta, n, m, e)
        keep = ok & (cos[:, 1] > settings.normal_consistency)
        # u_i.t = s d_i - sigma_i e_i, a 2x2 system solved by Cramer's rule
        rhs = s[:, None] * d - se
        det = _cross(u[:, 0], u[:, 1])
        keep &= ~_parallel(u[:, 0], u[:, 1], settings)
        safe = np.where(keep, det, 1.0)
        tx = (rhs[:, 0] * u[:, 1, 1] - rhs[:, 1] * u[:, 0, 1]) / safe
        ty = (u[:, 0, 0] * rhs[:, 1] - u[:, 1, 0] * rhs[:, 0]) / safe
        mod, src = _pack(tx, ty, theta, s, keep, source)
        out_models.append(mod)
        out_source.append(src)
    return _merge_by_source(out_models, out_source)


def _merge_by_source(models: list[np.ndarray], sources: list[np.ndarray]):
    """Concatenate candidate batches, ordered by sample (stable), so output is deterministic."""
    mod = np.concatenate(models)
    src = np.concatenate(sources)
    order = np.argsort(src, kind="stable")
    return mod[order], src[order]


@_quiet
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
    n, d = _as(bev_normals, (2, 2)), _as(bev_offsets, (2,))
    m, e = _as(fp_normals, (2, 2)), _as(fp_offsets, (2,))
    B = len(n)
    if scale_mode == "fixed":
        return _solve_two_lines(n, d, m, e, np.ones(B), settings, skip_scale_check=True)
    if rng is None:
        raise ValueError("solve_2l needs a Generator for the scale noise")  # programming error
    if not (np.isfinite(scale_prior) and scale_prior > 0):
        return _empty()
    s = scale_prior + sample_scale_noise(B, scale_prior, settings, rng)
    return _solve_two_lines(n, d, m, e, s, settings)


# --------------------------------------------------------------------------------------
# circle solvers
# --------------------------------------------------------------------------------------


def _radius_ok(r_bev, r_fp, s, settings: SolverSettings) -> np.ndarray:
    if r_bev is None or r_fp is None:
        return np.ones(np.shape(s), dtype=bool)
    ratio = np.asarray(r_fp, dtype=float) / (s * np.asarray(r_bev, dtype=float))
    tol = 1.0 + settings.radius_tolerance
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.isfinite(ratio) & (ratio <= tol) & (ratio * tol >= 1.0)


@_quiet
def solve_2c(
    bev_centers,
    fp_centers,
    settings: SolverSettings = SolverSettings(),
    scale_mode: ScaleMode = "free",
    bev_radii=None,
    fp_radii=None,
):
    """Two circle-centre correspondences -> models. centers (B, 2, 2); optional radii
    (B, 2) prune pairs whose radius ratio disagrees with the scale."""
    c, cp = _as(bev_centers, (2, 2)), _as(fp_centers, (2, 2))
    B = len(c)
    if B == 0:
        return _empty()
    v, vp = c[:, 1] - c[:, 0], cp[:, 1] - cp[:, 0]
    lv, lvp = np.linalg.norm(v, axis=1), np.linalg.norm(vp, axis=1)
    ok = (lv >= settings.min_baseline) & (lvp > 0)
    implied = lvp / np.where(ok, lv, 1.0)
    ok &= _scale_ok(implied, settings)
    s = np.ones(B) if scale_mode == "fixed" else implied
    theta = _angle(vp) - _angle(v)
    # centroid alignment: exact for noise-free data, least squares for noisy pairs
    t = cp.mean(axis=1) - s[:, None] * _rotate(theta, c.mean(axis=1))
    ok &= _radius_ok(None if bev_radii is None else _as(bev_radii, (2,)), None if fp_radii is None else _as(fp_radii, (2,)), s[:, None], settings).all(axis=1)
    return _pack(t[:, 0], t[:, 1], theta, s, ok, np.arange(B))


@_quiet
def solve_lc(
    bev_normal,
    bev_offset,
    bev_center,
    fp_normal,
    fp_offset,
    fp_center,
    settings: SolverSettings = SolverSettings(),
    scale_mode: ScaleMode = "free",
    bev_radius=None,
    fp_radius=None,
):
    """One line + one circle-centre correspondence -> models. normal (B, 2), offset (B,),
    center (B, 2). Rotation from the line; scale from the centre's signed distance to the
    line, s = (u.c' + sigma e) / (n.c + d); translation t = c' - s R c."""
    n, d, c = _as(bev_normal, (2,)), _as(bev_offset, ()), _as(bev_center, (2,))
    m, e, cp = _as(fp_normal, (2,)), _as(fp_offset, ()), _as(fp_center, (2,))
    B = len(n)
    if B == 0:
        return _empty()
    theta = _angle(m) - _angle(n)  # R n = m (first candidate)
    lever = np.einsum("ij,ij->i", n, c) + d  # signed distance of the BEV centre to its line
    ok = np.abs(lever) >= settings.min_baseline
    implied = (np.einsum("ij,ij->i", m, cp) + e) / np.where(ok, lever, 1.0)
    flip = implied < 0  # the other candidate (R n = -m) makes the scale positive
    theta = np.where(flip, theta + np.pi, theta)
    implied = np.abs(implied)
    ok &= _scale_ok(implied, settings)
    s = np.ones(B) if scale_mode == "fixed" else implied
    t = cp - s[:, None] * _rotate(theta, c)
    ok &= _radius_ok(bev_radius, fp_radius, s, settings)
    return _pack(t[:, 0], t[:, 1], theta, s, ok, np.arange(B))
