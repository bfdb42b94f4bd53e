"""Minimal solvers: exact recovery on exact correspondences, no model (and no NaN, no
exception) on degenerate samples, and the 2L scale-noise calibration."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings as hyp_settings
from hypothesis import strategies as st

from zfloc_stream.settings.loading import SolverSettings
from zfloc_stream.estimation.solvers import (
    sample_scale_noise,
    scale_prior_sigma,
    solve_2c,
    solve_2l,
    solve_3l,
    solve_lc,
)
from zfloc_stream.geometry.sim2 import Sim2, wrap_angle

EXACT = SolverSettings(scale_prior_window=0.0)  # GGD sigma = 0: 2L uses the prior exactly


def random_sim2(rng, fixed=False):
    s = 1.0 if fixed else rng.uniform(0.6, 1.9)
    return Sim2(s, rng.uniform(-np.pi, np.pi), rng.uniform(-20, 20, size=2))


def random_lines(rng, k, min_angle_deg=25.0):
    """k BEV lines in normal form with pairwise direction differences >= min_angle_deg
    (when k <= 3) so samples are well conditioned."""
    while True:
        ang = rng.uniform(-np.pi, np.pi, size=k)
        diffs = np.abs(wrap_angle(2 * (ang[:, None] - ang[None, :]))) / 2  # mod pi
        off = ~np.eye(k, dtype=bool)
        if k == 1 or diffs[off].min() > np.deg2rad(min_angle_deg):
            break
    n = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    d = rng.uniform(-8, 8, size=k)
    return n, d


def map_lines(T: Sim2, n, d, rng):
    """Floorplan lines matching BEV lines under T, each with a random normal sign."""
    m = n @ T.R.T
    e = T.s * d - m @ T.translation
    sign = np.where(rng.random(len(d)) < 0.5, -1.0, 1.0)
    return sign[:, None] * m, sign * e


def close_to(models, T: Sim2, tol=1e-9):
    if len(models) == 0:
        return False
    err_t = np.abs(models[:, :2] - T.translation).max(axis=1)
    err_a = np.abs(wrap_angle(models[:, 2] - T.theta))
    err_s = np.abs(models[:, 3] - T.s)
    return bool(((err_t < tol) & (err_a < tol) & (err_s < tol)).any())


def assert_clean(models, source):
    assert np.isfinite(models).all()
    assert models.shape[1] == 4 and len(models) == len(source)
    assert (models[:, 3] > 0).all()


# ---------------------------------------------------------------------------------------
# exact recovery, every solver and every scale mode
# ---------------------------------------------------------------------------------------


@hyp_settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(["free", "prior", "fixed"]))
def test_3l_recovers_transform(seed, mode):
    rng = np.random.default_rng(seed)
    T = random_sim2(rng, fixed=mode == "fixed")
    n, d = random_lines(rng, 3)
    m, e = map_lines(T, n, d, rng)
    models, source = solve_3l(n[None], d[None], m[None], e[None], EXACT, mode)
    assert_clean(models, source)
    assert close_to(models, T)
    if mode != "fixed":
        assert len(models) == 1  # the pi-flipped candidate has s < 0 and is dropped


@hyp_settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(["prior", "fixed"]))
def test_2l_recovers_transform(seed, mode):
    rng = np.random.default_rng(seed)
    T = random_sim2(rng, fixed=mode == "fixed")
    n, d = random_lines(rng, 2)
    m, e = map_lines(T, n, d, rng)
    models, source = solve_2l(n[None], d[None], m[None], e[None], T.s, rng, EXACT, mode)
    assert_clean(models, source)
    assert len(models) == 2  # both rotation candidates are real transforms at known scale
    assert close_to(models, T)


@hyp_settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(["free", "prior", "fixed"]))
def test_2c_recovers_transform(seed, mode):
    rng = np.random.default_rng(seed)
    T = random_sim2(rng, fixed=mode == "fixed")
    c = rng.uniform(-10, 10, size=(2, 2))
    if np.linalg.norm(c[1] - c[0]) < 1.0:
        c[1] = c[0] + [1.5, 0.3]
    r = rng.uniform(0.1, 0.8, size=2)
    models, source = solve_2c(c[None], T.apply(c)[None], EXACT, mode, r[None], (T.s * r)[None])
    assert_clean(models, source)
    assert len(models) == 1 and close_to(models, T)


@hyp_settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), mode=st.sampled_from(["free", "prior", "fixed"]))
def test_lc_recovers_transform(seed, mode):
    rng = np.random.default_rng(seed)
    T = random_sim2(rng, fixed=mode == "fixed")
    n, d = random_lines(rng, 1)
    c = rng.uniform(-10, 10, size=2)
    lever = n[0] @ c + d[0]
    if abs(lever) < 1.0:  # keep the centre off its line
        c = c + (1.5 - lever) * n[0]
    m, e = map_lines(T, n, d, rng)
    models, source = solve_lc(n, d, c[None], m, e, T.apply(c)[None], EXACT, mode, [0.3], [0.3 * T.s])
    assert_clean(models, source)
    assert len(models) == 1 and close_to(models, T)


def test_batches_keep_sample_indices():
    rng = np.random.default_rng(3)
    B = 200
    Ts = [random_sim2(rng) for _ in range(B)]
    n = np.zeros((B, 3, 2))
    d = np.zeros((B, 3))
    m = np.zeros((B, 3, 2))
    e = np.zeros((B, 3))
    for b, T in enumerate(Ts):
        n[b], d[b] = random_lines(rng, 3)
        m[b], e[b] = map_lines(T, n[b], d[b], rng)
    # every 4th sample made degenerate (all three lines parallel)
    n[::4] = n[::4, :1]
    models, source = solve_3l(n, d, m, e)
    assert_clean(models, source)
    expected = [b for b in range(B) if b % 4 and 0.5 <= Ts[b].s <= 2.0]
    assert sorted(set(source.tolist())) == expected
    for model, b in zip(models, source):
        assert close_to(model[None], Ts[b])


# ---------------------------------------------------------------------------------------
# degenerate samples: no model, no exception, no NaN
# ---------------------------------------------------------------------------------------


def no_model(out):
    models, source = out
    assert models.shape == (0, 4) and source.shape == (0,)


def test_degenerate_samples_give_no_model():
    warnings.simplefilter("error")  # a RuntimeWarning (0/0, nan compare) is a failure too
    try:
        rng = np.random.default_rng(0)
        T = random_sim2(rng)
        n = np.array([[1.0, 0.0], [1.0, 0.0], [-1.0, 0.0]])  # all parallel
        d = np.array([0.0, 1.0, 2.0])
        m, e = map_lines(T, n, d, rng)
        no_model(solve_3l(n[None], d[None], m[None], e[None]))
        no_model(solve_3l(n[None], d[None], m[None], e[None], scale_mode="fixed"))
        no_model(solve_2l(n[None, :2], d[None, :2], m[None, :2], e[None, :2], 1.0, rng))
        # three concurrent lines: scale is undetermined
        ang = np.array([0.1, 1.2, 2.3])
        n3 = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        d3 = np.zeros(3)
        m3, e3 = map_lines(T, n3, d3, rng)
        models, _ = solve_3l(n3[None], d3[None], m3[None], e3[None])
        assert np.isfinite(models).all() and len(models) <= 1
        # scale outside [min_scale, max_scale]
        big = Sim2(5.0, 0.3, (1.0, 2.0))
        n2, d2 = random_lines(rng, 3)
        m2, e2 = map_lines(big, n2, d2, rng)
        no_model(solve_3l(n2[None], d2[None], m2[None], e2[None]))
        no_model(solve_2l(n2[None, :2], d2[None, :2], m2[None, :2], e2[None, :2], 5.0, rng, EXACT))
        no_model(solve_2l(n2[None, :2], d2[None, :2], m2[None, :2], e2[None, :2], -1.0, rng))
        # normal-inconsistent triplet (line 2 rotated 90 degrees in the floorplan)
        m4, e4 = map_lines(T, n2, d2, rng)
        m4[1] = [-m4[1, 1], m4[1, 0]]
        no_model(solve_3l(n2[None], d2[None], m4[None], e4[None]))
        # coincident centres, centre on its line
        c = np.array([[1.0, 2.0], [1.0, 2.0]])
        no_model(solve_2c(c[None], T.apply(c)[None]))
        no_model(solve_2c(c[None], T.apply(c)[None], scale_mode="fixed"))
        cl = np.array([[3.0, 0.0]])
        no_model(solve_lc(np.array([[0.0, 1.0]]), [0.0], cl, np.array([[0.0, 1.0]]), [0.0], cl))
        # radius ratio disagreeing with the scale
        c2 = np.array([[0.0, 0.0], [3.0, 0.0]])
        no_model(solve_2c(c2[None], c2[None], bev_radii=[[0.2, 0.2]], fp_radii=[[0.8, 0.8]]))
        # NaN / inf anywhere
        nan_n = n2.copy()
        nan_n[0, 0] = np.nan
        no_model(solve_3l(nan_n[None], d2[None], m2[None], e2[None]))
        no_model(solve_2c(np.array([[[np.inf, 0.0], [1.0, 1.0]]]), c2[None]))
        no_model(solve_lc(np.array([[0.0, 1.0]]), [np.nan], [[0.0, 2.0]], np.array([[0.0, 1.0]]), [0.0], [[0.0, 2.0]]))
        # empty batches
        no_model(solve_3l(np.zeros((0, 3, 2)), np.zeros((0, 3)), np.zeros((0, 3, 2)), np.zeros((0, 3))))
        no_model(solve_2c(np.zeros((0, 2, 2)), np.zeros((0, 2, 2))))
    finally:
        warnings.resetwarnings()


# ---------------------------------------------------------------------------------------
# 2L scale prior noise
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("prior", [0.7, 1.0, 1.6])
def test_scale_noise_matches_its_calibration(prior):
    cfg = SolverSettings()
    eps = sample_scale_noise(200_000, prior, cfg, np.random.default_rng(1))
    inside = np.mean(np.abs(eps) <= cfg.scale_prior_window * prior)
    assert abs(inside - cfg.scale_prior_prob) < 0.005
    assert abs(eps.mean()) < 0.002 * prior
    # sigma is derived from the settings (window, probability, shape), not fixed
    wider = cfg.model_copy(update={"scale_prior_prob": 0.5})
    assert scale_prior_sigma(prior, wider) > scale_prior_sigma(prior, cfg)


def test_2l_is_deterministic_given_the_generator():
    rng = np.random.default_rng(5)
    n, d = random_lines(rng, 2)
    m, e = map_lines(Sim2(1.1, 0.4, (2, 3)), n, d, rng)
    a = solve_2l(np.repeat(n[None], 50, 0), np.repeat(d[None], 50, 0), np.repeat(m[None], 50, 0), np.repeat(e[None], 50, 0), 1.0, np.random.default_rng(9))
    b = solve_2l(np.repeat(n[None], 50, 0), np.repeat(d[None], 50, 0), np.repeat(m[None], 50, 0), np.repeat(e[None], 50, 0), 1.0, np.random.default_rng(9))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert np.unique(a[0][:, 3]).size > 10  # the scale really is perturbed per sample
