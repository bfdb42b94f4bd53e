"""estimator.kernels numba for the 3L solver at free / prior scale: solve_3l_indexed gives
the numpy path's models and source indices bit for bit (same order, same -0.0 / +0.0),
on random line sets with degenerate lines mixed in (parallel, zero and huge offsets,
exactly axis-aligned normals: singular systems, overflowing determinants), on samples
consistent with one transform (most give a model), on the edge cases, and on the samples
of a real camera session's first round."""

from pathlib import Path

import numpy as np
import pytest

from zfloc_stream.config import SolverSettings
from zfloc_stream.estimation import ransac
from zfloc_stream.estimation.solvers import _angle, solve_3l_indexed
from zfloc_stream.geometry import LineSet

pytest.importorskip("numba")

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
CAMERA_SESSION = Path(__file__).resolve().parents[2] / "shared" / "data" / "sessions" / "intel-camera-30" / "session.mcap"

FREE = SolverSettings(min_scale=0.5, max_scale=2.0)
PRIOR = SolverSettings(min_scale=1 / 1.15, max_scale=1.15)  # the camera-prior case's bounds


def _lines(normals, offsets) -> LineSet:
    normals = np.asarray(normals, dtype=float)
    return LineSet(normals, np.asarray(offsets, dtype=float), np.zeros((len(normals), 2, 2)))


def _random_lines(rng, n) -> LineSet:
    """Random and near-Manhattan lines, then degenerate ones: exact axis normals (cosines
    of exactly +-1 and 0, vanishing minors), repeats of one normal (parallel triplets),
    zero, subnormal and huge offsets (non-finite scale tests, overflowing row norms)."""
    a = rng.uniform(-np.pi, np.pi, n)
    a[n // 2 :] = np.round(a[n // 2 :] / (np.pi / 2)) * (np.pi / 2) + rng.normal(0, 0.02, n - n // 2)
    normals = np.column_stack([np.cos(a), np.sin(a)])
    offsets = rng.normal(0, 8, n)
    axes = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [1.0, 0.0], [1.0, 0.0]])
    special = np.array([0.0, 0.0, 3.0, -2.0, 1.7e308, -1.7e308])
    repeated = np.repeat(normals[:1], 4, axis=0)
    return _lines(np.vstack([normals, axes, repeated]), np.concatenate([offsets, special, [0.0, 5e-324, 4.0, -4.0]]))


def _assert_identical(bev, fp, b, f, settings):
    args = (bev, fp, b, f, _angle(bev.normals), _angle(fp.normals), settings)
    ref = solve_3l_indexed(*args, kernels="numpy")
    got = solve_3l_indexed(*args, kernels="numba")
    assert got[0].shape == ref[0].shape and got[0].dtype == ref[0].dtype and got[1].dtype == ref[1].dtype
    # bit patterns, so a -0.0 for a +0.0 would fail too
    assert np.array_equal(got[0].view(np.int64), ref[0].view(np.int64))
    assert np.array_equal(got[1], ref[1])
    return ref


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("settings", [FREE, PRIOR], ids=["free", "prior"])
def test_random_and_degenerate_samples(seed, settings):
    rng = np.random.default_rng(seed)
    bev, fp = _random_lines(rng, 25), _random_lines(rng, 200)
    k = 40_000
    b = [rng.integers(0, len(bev.offsets), k).astype(np.int32) for _ in range(3)]
    f = [rng.integers(0, len(fp.offsets), k).astype(np.int32) for _ in range(3)]
    # a share of the samples on the degenerate lines only (the last ten of each set)
    tail = rng.random(k) < 0.2
    for idx, n in ((b, len(bev.offsets)), (f, len(fp.offsets))):
        for col in idx:
            col[tail] = rng.integers(n - 10, n, tail.sum())
    models, _ = _assert_identical(bev, fp, b, f, settings)
    assert len(models) > 50


@pytest.mark.parametrize("settings", [FREE, PRIOR], ids=["free", "prior"])
def test_samples_of_one_transform(settings):
    """Floorplan lines = the BEV lines moved by one Sim(2) (plus clutter): matched
    triplets give the transform, so most survive and the write path is exercised."""
    rng = np.random.default_rng(7)
    bev = _random_lines(rng, 30)
    theta, s, t = 0.7, 1.1, np.array([3.0, -2.0])
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    moved = bev.normals @ rot.T
    flipped = np.where(rng.random(len(moved)) < 0.5, -1.0, 1.0)  # either sign of the normal
    fp_normals = np.vstack([moved * flipped[:, None], _random_lines(rng, 50).normals])
    with np.errstate(over="ignore"):  # the huge BEV offsets move to infinite ones: dropped alike
        fp_offsets = np.concatenate([(s * bev.offsets - moved @ t) * flipped, rng.normal(0, 8, 50 + 10)])
    fp = _lines(fp_normals, fp_offsets)
    k = 20_000
    b = rng.integers(0, 30, (k, 3))  # one (B, 3) int64 array, as the fixed-scale path builds them
    f = np.where(rng.random((k, 3)) < 0.9, b, rng.integers(0, len(fp.offsets), (k, 3)))
    models, _ = _assert_identical(bev, fp, b, f, settings)
    assert len(models) > k // 4
    assert np.isclose(models[:, 3], s).mean() > 0.5


def test_edge_cases():
    rng = np.random.default_rng(1)
    bev, fp = _random_lines(rng, 12), _random_lines(rng, 40)
    empty = [np.zeros(0, np.int32)] * 3
    models, source = _assert_identical(bev, fp, empty, empty, FREE)
    assert models.shape == (0, 4) and source.dtype == np.int64
    # one sample giving one model: three lines and themselves (identity transform)
    three = _lines([[1.0, 0.0], [0.0, 1.0], [np.sqrt(0.5), np.sqrt(0.5)]], [1.0, -2.0, 0.5])
    models, source = _assert_identical(three, three, [[0], [1], [2]], [[0], [1], [2]], FREE)
    assert len(models) == 1 and source.tolist() == [0] and np.allclose(models[0], [0, 0, 0, 1])
    # all BEV normals parallel, or a scale outside the bounds: no model
    _assert_identical(three, three, [[0], [0], [0]], [[0], [0], [0]], FREE)
    far = _lines(three.normals, three.offsets * 5.0)
    models, _ = _assert_identical(three, far, [[0], [1], [2]], [[0], [1], [2]], FREE)
    assert len(models) == 0


@pytest.mark.skipif(not CAMERA_SESSION.is_file(), reason="shared real sessions not available")
def test_real_session_samples(monkeypatch):
    """The 3L samples of the camera-prior case's first round (benchmarks/profile_round.py),
    solved with that case's scale bounds and with the free mode's."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from profile_round import build_case

    from zfloc_stream.localizer import Localizer

    fp, frames, settings = build_case("camera-prior")
    seen = []

    def capture(bev_lines, fp_lines, b, f, bev_angles, fp_angles, cfg, kernels="numpy"):
        seen.append((bev_lines, fp_lines, b, f, cfg))
        return solve_3l_indexed(bev_lines, fp_lines, b, f, bev_angles, fp_angles, cfg, kernels=kernels)

    monkeypatch.setattr(ransac, "solve_3l_indexed", capture)
    with Localizer(fp, settings) as loc:
        for frame in frames:
            loc.push(frame)
            if seen:
                break
    assert seen, "no 3L samples were drawn"
    bev_lines, fp_lines, b, f, cfg = seen[0]
    assert len(b[0]) > 100_000
    for bounds in (cfg, cfg.model_copy(update={"min_scale": FREE.min_scale, "max_scale": FREE.max_scale})):
        models, _ = _assert_identical(bev_lines, fp_lines, b, f, bounds)
        assert len(models) > 1000


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("fixed", [False, True], ids=["prior", "fixed"])
def test_two_lines_random_and_degenerate(seed, fixed):
    """solvers_numba.solve_two_lines_indexed against solvers._solve_two_lines (2L at a
    prior, 2L / 3L at fixed scale) on the gathered samples: random and degenerate lines,
    samples of one rigid transform, scales in and out of bounds and non-finite."""
    from zfloc_stream.estimation.solvers import _solve_two_lines
    from zfloc_stream.estimation.solvers_numba import solve_two_lines_indexed

    rng = np.random.default_rng(seed)
    bev = _random_lines(rng, 25)
    theta, t = rng.uniform(-np.pi, np.pi), rng.normal(0, 4, 2)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    moved = bev.normals @ rot.T
    clutter = _random_lines(rng, 150)
    with np.errstate(over="ignore", invalid="ignore"):
        fp = _lines(np.vstack([moved, clutter.normals]), np.concatenate([bev.offsets - moved @ t, clutter.offsets]))
    k = 30_000
    b = [rng.integers(0, len(bev.offsets), k) for _ in range(2)]
    f = [np.where(rng.random(k) < 0.5, b[i], rng.integers(0, len(fp.offsets), k)) for i in range(2)]
    settings = PRIOR
    if fixed:
        scales = np.ones(k)
    else:
        scales = rng.uniform(0.8, 1.2, k)
        scales[rng.random(k) < 0.02] = np.nan
        scales[rng.random(k) < 0.02] = np.inf
    n = np.stack([bev.normals[b[0]], bev.normals[b[1]]], axis=1)
    d = np.stack([bev.offsets[b[0]], bev.offsets[b[1]]], axis=1)
    m = np.stack([fp.normals[f[0]], fp.normals[f[1]]], axis=1)
    e = np.stack([fp.offsets[f[0]], fp.offsets[f[1]]], axis=1)
    with np.errstate(all="ignore"):
        ref = _solve_two_lines(n, d, m, e, scales, settings, skip_scale_check=fixed)
    got = solve_two_lines_indexed(bev, fp, b, f, scales, _angle(bev.normals), _angle(fp.normals), settings, skip_scale_check=fixed)
    assert got[0].shape == ref[0].shape and got[1].dtype == ref[1].dtype
    assert np.array_equal(got[0].view(np.int64), ref[0].view(np.int64))
    assert np.array_equal(got[1], ref[1])
    assert len(ref[0]) > k // 10
    empty = solve_two_lines_indexed(bev, fp, [b[0][:0]] * 2, [f[0][:0]] * 2, np.zeros(0), _angle(bev.normals), _angle(fp.normals), settings)
    assert empty[0].shape == (0, 4) and empty[1].dtype == np.int64
