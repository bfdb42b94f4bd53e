"""The model rows every minimal solver returns, and the checks all of them share.

A solver maps a batch of minimal samples to an (M, 4) array of rows (tx, ty, theta, s)
(MODEL_COLUMNS) and an (M,) array naming the sample each row came from. A row that is not
finite, or whose scale lies outside [min_scale, max_scale], never leaves a solver."""

from __future__ import annotations

import functools
from collections import namedtuple

import numpy as np

from ...geometry.sim2 import wrap_angle
from ...runtime.numba_support import njit
from ...settings.loading import SolverSettings

MODEL_COLUMNS = ("tx", "ty", "theta", "s")

# The solvers' degeneracy and consistency tests (were estimator.solvers.*; every recorded
# result used these: the replay samples, eval_real, the benchmark scenes). They reject
# samples that cannot give a model, not models a user might want: what a user sets is the
# scale (scale_mode, min_scale, max_scale, prior_range, the scale prior's window and prob).
NORMAL_CONSISTENCY = 0.95  # the paper's tau_p: |cos(R n_i, n'_i)| required of the non-anchor lines (3L, 2L), ~18 deg
PARALLEL_ANGLE_DEG = 10.0  # lines closer than this in direction count as parallel (their intersection is ill-conditioned)
MIN_BASELINE = 0.3  # m (BEV units): 2C centres, or an LC centre and its line, closer than this are degenerate
SINGULAR_TOLERANCE = 1e-9  # relative determinant below which a linear solve is degenerate (far above rounding)
RADIUS_TOLERANCE = 0.5  # 2C/LC: model rejected when r_floorplan / (s r_bev) leaves [1/(1+x), 1+x] (pillar radii are rough)


def quiet(solver):
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


def as_batch(x, shape_tail: tuple[int, ...]) -> np.ndarray:
    """x as float64 with a leading batch axis: (B, *shape_tail)."""
    a = np.asarray(x, dtype=float)
    return a.reshape((-1, *shape_tail))


def normal_angle(v: np.ndarray) -> np.ndarray:
    """Angle of normal vectors (..., 2), as the solvers compute it for a sample's anchor."""
    return np.arctan2(v[..., 1], v[..., 0])


def rotate(theta: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (..., 2) vectors by per-row angles theta (broadcast over trailing axes)."""
    c, s = np.cos(theta), np.sin(theta)
    while c.ndim < v.ndim - 1:
        c, s = c[..., None], s[..., None]
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], axis=-1)


def pack(tx, ty, theta, s, keep, source) -> tuple[np.ndarray, np.ndarray]:
    """The rows kept (keep and every column finite), theta wrapped, and their samples."""
    theta = wrap_angle(theta)
    keep = keep & np.isfinite(tx) & np.isfinite(ty) & np.isfinite(theta) & np.isfinite(s)
    idx = np.flatnonzero(keep)
    return np.stack([tx[idx], ty[idx], theta[idx], s[idx]], axis=-1), source[idx]


def scale_ok(s: np.ndarray, settings: SolverSettings) -> np.ndarray:
    """s finite and inside [min_scale, max_scale]."""
    return np.isfinite(s) & (s >= settings.min_scale) & (s <= settings.max_scale)


def radius_ok(r_bev, r_fp, s, settings: SolverSettings) -> np.ndarray:
    """The floorplan radius agrees with the BEV radius at scale s within radius_tolerance
    (a ratio, either way); everything passes when either radius is not given."""
    if r_bev is None or r_fp is None:
        return np.ones(np.shape(s), dtype=bool)
    ratio = np.asarray(r_fp, dtype=float) / (s * np.asarray(r_bev, dtype=float))
    tol = 1.0 + RADIUS_TOLERANCE
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.isfinite(ratio) & (ratio <= tol) & (ratio * tol >= 1.0)


# --------------------------------------------------------------------------------------
# the compiled line solvers' shared pieces
# --------------------------------------------------------------------------------------

# A line set as the compiled solvers read it: normal components and offsets, contiguous
# float64 (line k is (nx[k], ny[k]) . x + d[k] = 0).
LineColumns = namedtuple("LineColumns", "nx ny d")


def line_columns(lines) -> LineColumns:
    """A LineSet's normals and offsets as LineColumns."""
    return LineColumns(*(np.ascontiguousarray(a, dtype=np.float64) for a in (lines.normals[:, 0], lines.normals[:, 1], lines.offsets)))


def flat_line_columns(normals: np.ndarray, offsets: np.ndarray) -> LineColumns:
    """The samples' lines laid end to end (sample i's k-th line at k_lines * i + k) as
    LineColumns."""
    return LineColumns(*(np.ascontiguousarray(a.ravel(), dtype=np.float64) for a in (normals[..., 0], normals[..., 1], offsets)))


def rotation_table(bev_angles, fp_angles, *shifts):
    """theta = fp_angle - bev_angle per (floorplan line, BEV line) pair (row-major,
    pair = fp line * n_bev + BEV line), and cos and sin of theta + shift for each shift."""
    table = (fp_angles[:, None] - bev_angles[None, :]).ravel()
    trig = []
    for shift in shifts:
        t = table if shift is None else table + shift
        trig += [np.cos(t), np.sin(t)]
    return table, trig


def anchor_table(n: np.ndarray, m: np.ndarray, k_lines: int) -> np.ndarray:
    """The kernels read a sample's anchor rotation from a per-(floorplan line, BEV line)
    table at fp_line * n_bev + bev_line; with n_bev = 0 that is the anchor's BEV index,
    k_lines * i: theta_i = angle(m_i0) - angle(n_i0) repeated over the sample's lines."""
    return np.repeat(normal_angle(m[:, 0]) - normal_angle(n[:, 0]), k_lines)


def sample_lines(n_samples: int, k_lines: int) -> np.ndarray:
    """(n_samples, k_lines) int64: sample i's lines at k_lines * i + k in the flat columns
    (flat_line_columns), the same rows on the BEV and the floorplan side."""
    return np.arange(n_samples, dtype=np.int64)[:, None] * k_lines + np.arange(k_lines, dtype=np.int64)[None, :]


@njit
def sign_of(cos):
    """np.where(cos < 0, -1.0, 1.0): a NaN or -0.0 cosine gives +1."""
    return -1.0 if cos < 0 else 1.0


@njit
def append_model(out, src, kept, sample, tx, ty, theta, s):
    """Writes one surviving model (and the sample it came from) at row kept; the next row."""
    out[kept, 0] = tx
    out[kept, 1] = ty
    out[kept, 2] = theta
    out[kept, 3] = s
    src[kept] = sample
    return kept + 1


@njit
def _wrap_headings(models):
    """sim2.wrap_angle of column 2, in place: (theta + pi) % (2 pi) - pi, numba's float %
    being numpy's (the remainder with the divisor's sign), so the same bits; one pass over
    a strided column that numpy would walk with three temporaries."""
    two_pi = 2.0 * np.pi
    for i in range(models.shape[0]):
        models[i, 2] = (models[i, 2] + np.pi) % two_pi - np.pi


def wrapped(models, source):
    """The compiled solvers' models (theta not yet wrapped) with theta wrapped, in place."""
    if len(source) == 0:
        return no_models()
    _wrap_headings(models)
    return models, source
