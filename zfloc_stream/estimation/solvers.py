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

from ..runtime import threads
from ..settings.loading import ScaleMode, SolverSettings
from ..runtime.numba_support import njit
from ..geometry.sim2 import wrap_angle
from .draws import cumulate, draw_row, draw_uniforms

MODEL_COLUMNS = ("tx", "ty", "theta", "s")

# The solvers' degeneracy and consistency tests (were estimator.solvers.*; every recorded
# result used these: the replay samples, eval_real, the benchmark scenes). They reject
# samples that cannot give a model, not models a user might want: what a user sets is the
# scale (scale_mode, min_scale, max_scale, prior_range, the scale prior's window and prob).
NORMAL_CONSISTENCY = 0.95  # the paper's tau_p: |cos(R n_i, n'_i)| required of the non-anchor lines (3L, 2L), ~18 deg
SCALE_PRIOR_GGD_SHAPE = 4.0  # 2L: shape of the generalised Gaussian on the metric scale (flat-topped: the prior's window is a soft box)
PARALLEL_ANGLE_DEG = 10.0  # lines closer than this in direction count as parallel (their intersection is ill-conditioned)
MIN_BASELINE = 0.3  # m (BEV units): 2C centres, or an LC centre and its line, closer than this are degenerate
SINGULAR_TOLERANCE = 1e-9  # relative determinant below which a linear solve is degenerate (far above rounding)
RADIUS_TOLERANCE = 0.5  # 2C/LC: model rejected when r_floorplan / (s r_bev) leaves [1/(1+x), 1+x] (pillar radii are rough)


def _quiet(solver):
    """Non-finite or degenerate inputs are filtered by masks, never by warnings: silence
    numpy's floating-point warnings inside a solver (the final finiteness mask is what
    guarantees no NaN model escapes)."""

    @functools.wraps(solver)
    def wrapped(*args, **kwargs):
        with np.errstate(all="ignore"):
            return solver(*args, **kwargs)

    return wrapped


def no_models() -> tuple[np.ndarray, np.ndarray]:
    """No models: (0, 4) rows and their (0,) sample indices."""
    return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)


def normal_angle(v: np.ndarray) -> np.ndarray:
    """Angle of normal vectors (..., 2), as the solvers compute it for a sample's anchor."""
    return np.arctan2(v[..., 1], v[..., 0])


def _rotate(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 2) vectors by per-row angles theta (broadcast over trailing axes)."""
    c, s = np.cos(theta), np.sin(theta)
    while c.ndim < v.ndim - 1:
        c, s = c[..., None], s[..., None]
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def _pack(tx, ty, theta, s, keep, source) -> tuple[np.ndarray, np.ndarray]:
    theta = wrap_angle(theta)
    keep = keep & np.isfinite(tx) & np.isfinite(ty) & np.isfinite(theta) & np.isfinite(s)
    idx = np.flatnonzero(keep)
    return np.stack([tx[idx], ty[idx], theta[idx], s[idx]], axis=-1), source[idx]


def _scale_ok(s: np.ndarray, settings: SolverSettings) -> np.ndarray:
    return np.isfinite(s) & (s >= settings.min_scale) & (s <= settings.max_scale)


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

    beta = SCALE_PRIOR_GGD_SHAPE
    a = settings.scale_prior_window * scale_prior
    return float(a / gammaincinv(1.0 / beta, settings.scale_prior_prob) ** (1.0 / beta))


def sample_scale_noise(n: int, scale_prior: float, settings: SolverSettings, rng: np.random.Generator) -> np.ndarray:
    """n draws of eps ~ GGD(0, sigma, beta) from the given generator."""
    beta = SCALE_PRIOR_GGD_SHAPE
    sigma = scale_prior_sigma(scale_prior, settings)
    magnitude = rng.gamma(1.0 / beta, 1.0, size=n) ** (1.0 / beta)
    sign = np.where(rng.random(n) < 0.5, -1.0, 1.0)
    return sigma * sign * magnitude


# --------------------------------------------------------------------------------------
# line solvers, compiled: one loop runs a sample's whole solve (_solve_3l_one,
# _solve_2l_one: the normal test, the scale plausibility test, Cramer's rule) and writes
# only the models that survive, so no per-sample temporaries are built; the fused kernels
# (_drawn_3l, _drawn_2l) also draw the sample's floorplan tuple in that loop (draws.py).
# The transcendental functions stay in numpy: the anchor rotation and its cos and sin per
# (floorplan line, BEV line) pair are computed on whole arrays and only gathered here.
# --------------------------------------------------------------------------------------


# A sample is solved exactly only when its scale, computed the short way (_screen_3l), lies
# within the bounds widened by this factor: far beyond any rounding difference between the
# two ways (a regular system's determinant is >= SINGULAR_TOLERANCE times its row norms),
# so the models kept are the same; at a metric prior ~93% of the samples end there.
SCALE_SLACK = 1.05


@njit
def _det3_scalar(a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """Determinant of the 3x3 matrix with columns a, b, c given by their three rows."""
    return a0 * (b1 * c2 - b2 * c1) - b0 * (a1 * c2 - a2 * c1) + c0 * (a1 * b2 - a2 * b1)


@njit
def _sign(cos):
    """np.where(cos < 0, -1.0, 1.0): a NaN or -0.0 cosine gives +1."""
    return -1.0 if cos < 0 else 1.0


# --------------------------------------------------------------------------------------
# 3L, free / prior scale
# --------------------------------------------------------------------------------------


@njit
def _screen_3l(i0, i1, i2, j0, j1, j2, bnx, bny, bd, fnx, fny, fd, cos_table, sin_table, n_bev, limits):
    """The two cheap tests of a 3L sample: (passed, c, sn, cos1, cos2), c and sn the
    cos and sin of its anchor rotation, cos1 and cos2 the signed cosines of lines 1 and
    2. Every value is computed and the tests combined without branching, so a loop of
    screens does not stall on the unpredictable outcomes (about half the drawn samples
    fail the first test, most of the rest the second)."""
    normal_consistency, plausible_lo, plausible_hi = limits[0], limits[1], limits[2]
    # rotation of the anchor pair, from the per-(floorplan line, BEV line) tables
    pair = np.int64(j0) * n_bev + i0
    c = cos_table[pair]
    sn = sin_table[pair]
    n1x, n1y, n2x, n2y = bnx[i1], bny[i1], bnx[i2], bny[i2]
    m0x, m0y, m1x, m1y, m2x, m2y = fnx[j0], fny[j0], fnx[j1], fny[j1], fnx[j2], fny[j2]
    # normal consistency of lines 1 and 2: |(R n_i).m_i| > normal_consistency; NaN fails
    cos1 = (c * n1x - sn * n1y) * m1x + (sn * n1x + c * n1y) * m1y
    cos2 = (c * n2x - sn * n2y) * m2x + (sn * n2x + c * n2y) * m2y
    consistent = (abs(cos1) > normal_consistency) & (abs(cos2) > normal_consistency)
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
    den = bd[i0] * cof0 + bd[i1] * cof1 + bd[i2] * cof2
    num = fd[j0] * cof0 + sg1 * fd[j1] * cof1 + sg2 * fd[j2] * cof2
    a_num = abs(num)
    a_den = abs(den)
    inside = (a_num >= plausible_lo * a_den) & (a_num <= plausible_hi * a_den)
    plausible = inside | (not np.isfinite(num)) | (not np.isfinite(den))
    return consistent & plausible, c, sn, cos1, cos2


@njit
def _solve_3l_one(i0, i1, i2, j0, j1, j2, bnx, bny, bd, fnx, fny, fd, table, cos_table, sin_table, n_bev, limits):
    """One 3L sample, BEV lines i0..i2 matched to floorplan lines j0..j2: (kept, tx, ty,
    theta, s) with theta NOT yet wrapped; kept False (and the rest meaningless) where the
    sample gives no model. limits: (normal_consistency, plausible_lo, plausible_hi,
    sin_par, singular_tolerance, min_scale, max_scale)."""
    sin_par, singular_tolerance, min_scale, max_scale = limits[3], limits[4], limits[5], limits[6]
    passed, c, sn, cos1, cos2 = _screen_3l(i0, i1, i2, j0, j1, j2, bnx, bny, bd, fnx, fny, fd, cos_table, sin_table, n_bev, limits)
    if not passed:
        return False, 0.0, 0.0, 0.0, 0.0
    theta = table[np.int64(j0) * n_bev + i0]
    n0x, n0y, n1x, n1y, n2x, n2y = bnx[i0], bny[i0], bnx[i1], bny[i1], bnx[i2], bny[i2]
    m0x, m0y, m1x, m1y, m2x, m2y = fnx[j0], fny[j0], fnx[j1], fny[j1], fnx[j2], fny[j2]
    d0, d1, d2 = bd[i0], bd[i1], bd[i2]
    e0, e1, e2 = fd[j0], fd[j1], fd[j2]
    sg1 = _sign(cos1)
    sg2 = _sign(cos2)

    # all three BEV normals pairwise parallel: no model
    if (abs(n0x * n1y - n0y * n1x) < sin_par and abs(n0x * n2y - n0y * n2x) < sin_par
            and abs(n1x * n2y - n1y * n2x) < sin_par):
        return False, 0.0, 0.0, 0.0, 0.0

    # rows s d_k - u_k.t = sigma_k e_k: A = [D, -sigma m_x, -sigma m_y], rhs sigma e;
    # the anchor's cosine is computed here, lines 1 and 2 reuse the normal test's
    cos0 = (c * n0x - sn * n0y) * m0x + (sn * n0x + c * n0y) * m0y
    sg0 = _sign(cos0)
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
    if not abs(det) > singular_tolerance * bound:
        return False, 0.0, 0.0, 0.0, 0.0
    s = _det3_scalar(se0, se1, se2, a10, a11, a12, a20, a21, a22) / det
    tx = _det3_scalar(d0, d1, d2, se0, se1, se2, a20, a21, a22) / det
    ty = _det3_scalar(d0, d1, d2, a10, a11, a12, se0, se1, se2) / det
    if s < 0:  # the R n_1 = -m_1 candidate
        theta = theta + np.pi
    s = abs(s)
    # _scale_ok and _pack's finiteness filter; theta is finite exactly when its
    # wrapped value is (the wrap of inf is NaN)
    if not (np.isfinite(s) and s >= min_scale and s <= max_scale):
        return False, 0.0, 0.0, 0.0, 0.0
    if not (np.isfinite(tx) and np.isfinite(ty) and np.isfinite(theta)):
        return False, 0.0, 0.0, 0.0, 0.0
    return True, tx, ty, theta, s


@njit
def _append_model(out, src, kept, sample, tx, ty, theta, s):
    """Writes one surviving model (and the sample it came from) at row kept; the next row."""
    out[kept, 0] = tx
    out[kept, 1] = ty
    out[kept, 2] = theta
    out[kept, 3] = s
    src[kept] = sample
    return kept + 1


@njit
def _solve(bnx, bny, bd, fnx, fny, fd, b0, b1, b2, f0, f1, f2, table, cos_table, sin_table, n_bev, limits):
    """Models (tx, ty, theta, s) with theta NOT yet wrapped, and the index of the sample
    each came from, in sample order. Buffers are sized for every sample surviving and
    trimmed at the end (untouched pages of the over-allocation cost nothing)."""
    n = b0.shape[0]
    out = np.empty((n, 4), np.float64)
    src = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        ok, tx, ty, theta, s = _solve_3l_one(b0[i], b1[i], b2[i], f0[i], f1[i], f2[i], bnx, bny, bd, fnx, fny, fd,
                                             table, cos_table, sin_table, n_bev, limits)
        if ok:
            kept = _append_model(out, src, kept, i, tx, ty, theta, s)
    return out[:kept].copy(), src[:kept].copy()


# draws per block of _drawn_3l: its buffers stay in the L1 cache
_BLOCK = 512
# drawn_3l splits its draws over the round's threads only in pieces of at least this many
# (~1 ms)
_MIN_DRAWS_PER_THREAD = 32_768


@njit
def _drawn_3l(starts, sizes, counts, uniform, j_start, j_end, b_start, left_start, p0, p1, p2, rows, bnx, bny, bd, fnx, fny, fd,
              table, cos_table, sin_table, n_bev, limits):
    """draws._draw_rows and _solve in one loop: BEV sample b (lines p0[b], p1[b],
    p2[b]) meets counts[b] floorplan triplets, the table rows (of rows, (T, 3)) drawn as
    _draw_rows draws them. Models with theta NOT yet wrapped, and the draw each came
    from, in draw order.

    A block of draws at a time, in three passes: the rows and their floorplan lines (the
    table lookups, random memory accesses, independent of one another so they overlap),
    the branch-free screen (_screen_3l), then the full solve of the samples that passed
    it (which screens them again: the same function of the same values, so the same
    outcome).

    Only draws j_start to j_end - 1 are made (a piece of the whole, threads.py): the
    first of them is one of query b_start's, which has left_start draws left there."""
    out = np.empty((j_end - j_start, 4), np.float64)
    src = np.empty(j_end - j_start, np.int64)
    cum = np.empty(sizes.shape[1], np.int64)
    query = np.empty(_BLOCK, np.int64)
    lines = np.empty((_BLOCK, 3), np.int64)
    passed = np.empty(_BLOCK, np.int64)
    kept = 0
    b, n, left = b_start, 0, left_start  # the current query, its candidates and draws left
    if left > 0:
        n = cumulate(sizes, b, cum)
    j = j_start
    while j < j_end:
        m = min(_BLOCK, j_end - j)
        for k in range(m):
            while left == 0:  # total = sum(counts): a query with draws follows
                b += 1
                n = cumulate(sizes, b, cum)
                left = counts[b]
            row = draw_row(starts, sizes, cum, b, n, uniform[j + k])
            query[k] = b
            lines[k, 0] = rows[row, 0]
            lines[k, 1] = rows[row, 1]
            lines[k, 2] = rows[row, 2]
            left -= 1
        count = 0
        for k in range(m):
            q = query[k]
            ok = _screen_3l(p0[q], p1[q], p2[q], lines[k, 0], lines[k, 1], lines[k, 2], bnx, bny, bd, fnx, fny, fd,
                            cos_table, sin_table, n_bev, limits)[0]
            passed[count] = k
            count += ok
        for h in range(count):
            k = passed[h]
            q = query[k]
            ok, tx, ty, theta, s = _solve_3l_one(p0[q], p1[q], p2[q], lines[k, 0], lines[k, 1], lines[k, 2], bnx, bny, bd, fnx, fny,
                                                 fd, table, cos_table, sin_table, n_bev, limits)
            if ok:
                kept = _append_model(out, src, kept, j + k, tx, ty, theta, s)
        j += m
    return out[:kept].copy(), src[:kept].copy()


def _rotation_table(bev_angles, fp_angles, *shifts):
    """theta = fp_angle - bev_angle per (floorplan line, BEV line)
    pair (row-major, pair = fp line * n_bev + BEV line), and cos and sin of theta + shift
    for each shift."""
    table = (fp_angles[:, None] - bev_angles[None, :]).ravel()
    trig = []
    for shift in shifts:
        t = table if shift is None else table + shift
        trig += [np.cos(t), np.sin(t)]
    return table, trig


def _limits_3l(settings: SolverSettings) -> tuple:
    sin_par = float(np.sin(np.deg2rad(PARALLEL_ANGLE_DEG)))
    return (float(NORMAL_CONSISTENCY), settings.min_scale / SCALE_SLACK, settings.max_scale * SCALE_SLACK, sin_par,
            float(SINGULAR_TOLERANCE), float(settings.min_scale), float(settings.max_scale))


def _lines(lines):
    """Normal components and offsets of a LineSet, contiguous float64."""
    return tuple(np.ascontiguousarray(a, dtype=np.float64) for a in (lines.normals[:, 0], lines.normals[:, 1], lines.offsets))


@njit
def _wrap_headings(models):
    """sim2.wrap_angle of column 2, in place: (theta + pi) % (2 pi) - pi, numba's float %
    being numpy's (the remainder with the divisor's sign), so the same bits; one pass over
    a strided column that numpy would walk with three temporaries."""
    two_pi = 2.0 * np.pi
    for i in range(models.shape[0]):
        models[i, 2] = (models[i, 2] + np.pi) % two_pi - np.pi


def _wrapped(models, source):
    if len(source) == 0:
        return no_models()
    _wrap_headings(models)
    return models, source


def _pick_columns(picks):
    return [np.ascontiguousarray(picks[:, k], dtype=np.int64) for k in range(picks.shape[1])]


def drawn_3l(starts, sizes, fraction: float, rng: np.random.Generator, picks, rows, bev_lines, fp_lines, bev_angles, fp_angles,
             settings: SolverSettings):
    """draws.draw then solve_3l (free / prior scale) on the drawn samples, in one compiled
    loop: BEV triplets picks (B, 3), the floorplan triplet table rows (T, 3) (its row r:
    the lines of candidate r), the queries' candidate ranges (starts, sizes) and the match
    fraction. Takes the draw's random numbers from rng; returns the models and the index of
    the draw each came from, in draw order (the same with any thread count)."""
    starts, sizes, counts, uniform = draw_uniforms(starts, sizes, fraction, rng)
    if len(uniform) == 0:
        return no_models()
    table, (cos_table, sin_table) = _rotation_table(bev_angles, fp_angles, None)
    rest = (*_pick_columns(picks), np.ascontiguousarray(rows), *_lines(bev_lines), *_lines(fp_lines),
            table, cos_table, sin_table, len(bev_angles), _limits_3l(settings))
    # the draws in consecutive pieces, one per thread of the round, joined in draw order;
    # a piece starts inside the query whose draws cover its first draw
    ends = np.cumsum(counts)

    def piece(r):
        b = int(np.searchsorted(ends, r[0], side="right"))
        return _drawn_3l(starts, sizes, counts, uniform, r[0], r[1], b, int(ends[b] - r[0]), *rest)

    parts = threads.run(piece, threads.ranges(len(uniform), _MIN_DRAWS_PER_THREAD))
    models = np.concatenate([m for m, _ in parts])
    source = np.concatenate([src for _, src in parts])
    return _wrapped(models, source)


# --------------------------------------------------------------------------------------
# two lines, known scale (2L at a prior, 3L and 2L at a fixed scale)
# --------------------------------------------------------------------------------------


@njit
def _two_lines_candidate(c, sn, n0x, n0y, n1x, n1y, m0x, m0y, m1x, m1y, d0, d1, e0, e1, s, normal_consistency, sin_par):
    """One rotation candidate of a two-line sample (cos c, sin sn of its angle): (kept, tx,
    ty); the sample's own tests (parallel BEV lines, scale) are the caller's."""
    # R n . m
    cos0 = (c * n0x - sn * n0y) * m0x + (sn * n0x + c * n0y) * m0y
    cos1 = (c * n1x - sn * n1y) * m1x + (sn * n1x + c * n1y) * m1y
    if not abs(cos1) > normal_consistency:  # NaN fails
        return False, 0.0, 0.0
    sg0 = _sign(cos0)
    sg1 = _sign(cos1)
    u0x, u0y, u1x, u1y = sg0 * m0x, sg0 * m0y, sg1 * m1x, sg1 * m1y
    # u_i.t = s d_i - sigma_i e_i by Cramer's rule; parallel u: no model
    det = u0x * u1y - u0y * u1x
    if abs(det) < sin_par:
        return False, 0.0, 0.0
    rhs0 = s * d0 - sg0 * e0
    rhs1 = s * d1 - sg1 * e1
    tx = (rhs0 * u1y - rhs1 * u0y) / det
    ty = (u0x * rhs1 - u1x * rhs0) / det
    if not (np.isfinite(tx) and np.isfinite(ty)):
        return False, 0.0, 0.0
    return True, tx, ty


@njit
def _solve_2l_one(i0, i1, j0, j1, s, bnx, bny, bd, fnx, fny, fd, table, trig, n_bev, check_scale, limits):
    """One two-line sample with scale s, BEV lines i0, i1 matched to floorplan lines j0, j1:
    (theta_a, kept_a, tx_a, ty_a, theta_b, kept_b, tx_b, ty_b) for the candidates
    R n_1 = m_1 (a) and R n_1 = -m_1 (b), theta NOT yet wrapped. trig: cos and sin of
    theta + 0.0 and of theta + pi per pair; limits: (normal_consistency, sin_par,
    min_scale, max_scale)."""
    normal_consistency, sin_par, min_scale, max_scale = limits
    cos_a, sin_a, cos_b, sin_b = trig
    pair = np.int64(j0) * n_bev + i0
    theta_a = table[pair] + 0.0  # as theta0 + flip: turns a -0.0 into +0.0
    theta_b = table[pair] + np.pi
    n0x, n0y, n1x, n1y = bnx[i0], bny[i0], bnx[i1], bny[i1]
    # the sample's tests (_parallel of the BEV normals, _scale_ok) and _pack's finiteness
    # of s and theta (finite exactly when its wrap is)
    ok = not abs(n0x * n1y - n0y * n1x) < sin_par
    if check_scale:
        ok = ok and np.isfinite(s) and s >= min_scale and s <= max_scale
    ok = ok and np.isfinite(s)
    if not ok:
        return theta_a, False, 0.0, 0.0, theta_b, False, 0.0, 0.0
    m0x, m0y, m1x, m1y = fnx[j0], fny[j0], fnx[j1], fny[j1]
    d0, d1, e0, e1 = bd[i0], bd[i1], fd[j0], fd[j1]
    ok_a, tx_a, ty_a = _two_lines_candidate(cos_a[pair], sin_a[pair], n0x, n0y, n1x, n1y, m0x, m0y, m1x, m1y, d0, d1, e0, e1, s,
                                            normal_consistency, sin_par)
    ok_b, tx_b, ty_b = _two_lines_candidate(cos_b[pair], sin_b[pair], n0x, n0y, n1x, n1y, m0x, m0y, m1x, m1y, d0, d1, e0, e1, s,
                                            normal_consistency, sin_par)
    ok_a = ok_a and np.isfinite(theta_a)
    ok_b = ok_b and np.isfinite(theta_b)
    return theta_a, ok_a, tx_a, ty_a, theta_b, ok_b, tx_b, ty_b


@njit
def _write_2l(out, src, kept, i, s, res):
    """Appends sample i's surviving candidates, a before b (ordered by sample)."""
    theta_a, ok_a, tx_a, ty_a, theta_b, ok_b, tx_b, ty_b = res
    if ok_a:
        kept = _append_model(out, src, kept, i, tx_a, ty_a, theta_a, s)
    if ok_b:
        kept = _append_model(out, src, kept, i, tx_b, ty_b, theta_b, s)
    return kept


@njit
def _solve_2l(bnx, bny, bd, fnx, fny, fd, b0, b1, f0, f1, scales, table, trig, n_bev, check_scale, limits):
    """Models (tx, ty, theta, s) with theta NOT yet wrapped and their sample indices, in
    sample order, each sample's candidate a before b."""
    n = b0.shape[0]
    out = np.empty((2 * n, 4), np.float64)
    src = np.empty(2 * n, np.int64)
    kept = 0
    for i in range(n):
        res = _solve_2l_one(b0[i], b1[i], f0[i], f1[i], scales[i], bnx, bny, bd, fnx, fny, fd, table, trig, n_bev, check_scale, limits)
        kept = _write_2l(out, src, kept, i, scales[i], res)
    return out[:kept].copy(), src[:kept].copy()


@njit
def _drawn_2l(starts, sizes, counts, uniform, p0, p1, rows, scales, bnx, bny, bd, fnx, fny, fd, table, trig, n_bev,
              check_scale, limits):
    """draws._draw_rows and _solve_2l in one loop (as _drawn_3l, for pairs: rows
    (P, 2)); draw j has scale scales[j]."""
    total = uniform.shape[0]
    out = np.empty((2 * total, 4), np.float64)
    src = np.empty(2 * total, np.int64)
    cum = np.empty(sizes.shape[1], np.int64)
    kept = 0
    j = 0
    for b in range(starts.shape[0]):
        n = cumulate(sizes, b, cum)
        i0, i1 = p0[b], p1[b]
        for _ in range(counts[b]):
            row = draw_row(starts, sizes, cum, b, n, uniform[j])
            res = _solve_2l_one(i0, i1, rows[row, 0], rows[row, 1], scales[j], bnx, bny, bd, fnx, fny, fd, table, trig, n_bev,
                                check_scale, limits)
            kept = _write_2l(out, src, kept, j, scales[j], res)
            j += 1
    return out[:kept].copy(), src[:kept].copy()


def _limits_2l(settings: SolverSettings) -> tuple:
    sin_par = float(np.sin(np.deg2rad(PARALLEL_ANGLE_DEG)))
    return float(NORMAL_CONSISTENCY), sin_par, float(settings.min_scale), float(settings.max_scale)


def _rotation_2l(bev_angles, fp_angles):
    """theta per pair, and (cos, sin) of theta + 0.0 and theta + pi: the two candidates'
    theta0 + flip, the angles it rotates by."""
    table, trig = _rotation_table(bev_angles, fp_angles, 0.0, np.pi)
    return table, tuple(trig)


def drawn_2l(starts, sizes, fraction: float, rng: np.random.Generator, picks, rows, bev_lines, fp_lines, bev_angles, fp_angles,
             scale_prior: float, settings: SolverSettings, scale_mode: str):
    """draws.draw then solve_2l (prior or fixed scale_mode) on the drawn samples, in one
    compiled loop: BEV pairs picks (B, 2), the floorplan pair table rows (P, 2). Takes
    from rng the draws' uniforms, then at a prior the scale noise (one per draw); returns
    the models and the index of the draw each came from, in draw order."""
    starts, sizes, counts, uniform = draw_uniforms(starts, sizes, fraction, rng)
    total = len(uniform)
    if scale_mode == "fixed":
        scales, check_scale = np.ones(total), False
    else:
        if not (np.isfinite(scale_prior) and scale_prior > 0):
            return no_models()
        with np.errstate(all="ignore"):  # as solve_2l (_quiet)
            scales, check_scale = scale_prior + sample_scale_noise(total, scale_prior, settings, rng), True
    if total == 0:
        return no_models()
    table, trig = _rotation_2l(bev_angles, fp_angles)
    models, source = _drawn_2l(starts, sizes, counts, uniform, *_pick_columns(picks), np.ascontiguousarray(rows), scales, *_lines(bev_lines), *_lines(fp_lines),
                               table, trig, len(bev_angles), check_scale, _limits_2l(settings))
    return _wrapped(models, source)


# --------------------------------------------------------------------------------------
# the line solvers on given samples (the array API; RANSAC draws its samples with
# drawn_3l / drawn_2l above, which run the same per-sample kernels)
# --------------------------------------------------------------------------------------


def _flat(normals: np.ndarray, offsets: np.ndarray) -> tuple:
    """The samples' lines laid end to end (sample i's k-th line at k_lines * i + k): normal
    components and offsets, contiguous float64."""
    return tuple(np.ascontiguousarray(a.ravel(), dtype=np.float64) for a in (normals[..., 0], normals[..., 1], offsets))


def _anchor_table(n: np.ndarray, m: np.ndarray, k_lines: int) -> np.ndarray:
    """The kernels read a sample's anchor rotation from a per-(floorplan line, BEV line)
    table at fp_line * n_bev + bev_line; with n_bev = 0 that is the anchor's BEV index,
    k_lines * i: theta_i = angle(m_i0) - angle(n_i0) repeated over the sample's lines."""
    return np.repeat(normal_angle(m[:, 0]) - normal_angle(n[:, 0]), k_lines)


@_quiet
def solve_3l(bev_normals, bev_offsets, fp_normals, fp_offsets, settings: SolverSettings = SolverSettings(), scale_mode: ScaleMode = "free"):
    """Three line correspondences -> models. Arrays: normals (B, 3, 2), offsets (B, 3);
    line 0 is the anchor fixing the rotation. Normal consistency |(R n_i).m_i| > tau_p is
    checked for lines 1, 2 before the 3x3 system is solved. In fixed mode the third line
    is ignored (rigid two-line solver)."""
    n, d = _as(bev_normals, (3, 2)), _as(bev_offsets, (3,))
    m, e = _as(fp_normals, (3, 2)), _as(fp_offsets, (3,))
    if scale_mode == "fixed":
        return _two_lines(n[:, :2], d[:, :2], m[:, :2], e[:, :2], np.ones(len(n)), settings, check_scale=True)
    if len(n) == 0:
        return no_models()
    table = _anchor_table(n, m, 3)
    i = np.arange(len(n), dtype=np.int64) * 3
    models, source = _solve(*_flat(n, d), *_flat(m, e), i, i + 1, i + 2, i, i + 1, i + 2, table, np.cos(table), np.sin(table), 0,
                            _limits_3l(settings))
    return _wrapped(models, source)


def _two_lines(n, d, m, e, s, settings: SolverSettings, check_scale: bool):
    """Two line correspondences with known scales s (B,): both rotation candidates."""
    if len(n) == 0:
        return no_models()
    table = _anchor_table(n, m, 2)
    trig = (np.cos(table + 0.0), np.sin(table + 0.0), np.cos(table + np.pi), np.sin(table + np.pi))
    i = np.arange(len(n), dtype=np.int64) * 2
    models, source = _solve_2l(*_flat(n, d), *_flat(m, e), i, i + 1, i, i + 1, np.ascontiguousarray(s, dtype=np.float64),
                               table, trig, 0, check_scale, _limits_2l(settings))
    return _wrapped(models, source)


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
    if scale_mode == "fixed":
        return _two_lines(n, d, m, e, np.ones(len(n)), settings, check_scale=False)
    if rng is None:
        raise ValueError("solve_2l needs a Generator for the scale noise")  # programming error
    if not (np.isfinite(scale_prior) and scale_prior > 0):
        return no_models()
    s = scale_prior + sample_scale_noise(len(n), scale_prior, settings, rng)
    return _two_lines(n, d, m, e, s, settings, check_scale=True)


# --------------------------------------------------------------------------------------
# circle solvers
# --------------------------------------------------------------------------------------


def _radius_ok(r_bev, r_fp, s, settings: SolverSettings) -> np.ndarray:
    if r_bev is None or r_fp is None:
        return np.ones(np.shape(s), dtype=bool)
    ratio = np.asarray(r_fp, dtype=float) / (s * np.asarray(r_bev, dtype=float))
    tol = 1.0 + RADIUS_TOLERANCE
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
        return no_models()
    v, vp = c[:, 1] - c[:, 0], cp[:, 1] - cp[:, 0]
    lv, lvp = np.linalg.norm(v, axis=1), np.linalg.norm(vp, axis=1)
    ok = (lv >= MIN_BASELINE) & (lvp > 0)
    implied = lvp / np.where(ok, lv, 1.0)
    ok &= _scale_ok(implied, settings)
    s = np.ones(B) if scale_mode == "fixed" else implied
    theta = normal_angle(vp) - normal_angle(v)
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
        return no_models()
    theta = normal_angle(m) - normal_angle(n)  # R n = m (first candidate)
    lever = np.einsum("ij,ij->i", n, c) + d  # signed distance of the BEV centre to its line
    ok = np.abs(lever) >= MIN_BASELINE
    implied = (np.einsum("ij,ij->i", m, cp) + e) / np.where(ok, lever, 1.0)
    flip = implied < 0  # the other candidate (R n = -m) makes the scale positive
    theta = np.where(flip, theta + np.pi, theta)
    implied = np.abs(implied)
    ok &= _scale_ok(implied, settings)
    s = np.ones(B) if scale_mode == "fixed" else implied
    t = cp - s[:, None] * _rotate(theta, c)
    ok &= _radius_ok(bev_radius, fp_radius, s, settings)
    return _pack(t[:, 0], t[:, 1], theta, s, ok, np.arange(B))
