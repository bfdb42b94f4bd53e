"""The compiled line extraction (kernels="numba") gives the numpy path's lines.

Lines are compared exactly (count, order, support) and their coordinates to 1e-12 m: the
numpy path's np.arctan2 (SVML on AVX-512 CPUs) and libm's atan2 may differ in the last
bit. With libm's atan2 in both, the lines are bit-identical wherever numpy's BLAS
rounds as the kernel's emulation of it (checked first; skipped elsewhere)."""

import math
from fractions import Fraction

import numpy as np
import pytest

pytest.importorskip("numba")

from scipy.spatial import cKDTree  # noqa: E402

from zfloc_stream import primitives  # noqa: E402
from zfloc_stream import primitives_numba as pn  # noqa: E402
from zfloc_stream.config import LineSettings  # noqa: E402

SETTINGS = LineSettings()
FIELDS = ("normals", "offsets", "endpoints", "support")


def rooms(seed: int, resolution: float = 0.05, corridor: bool = False) -> np.ndarray:
    """BEV-like wall points: a few rectangular rooms with a door gap, jitter, clutter and
    noise, snapped to cell centres (so many pairs sit at exact multiples of a radius);
    corridor: one more room 50 m long, without doors, whose walls hold over 768 points (the scatter
    matrix then sums in several blocks)."""
    gen = np.random.default_rng(seed)
    parts = []
    for r in range(int(gen.integers(1, 4)) + corridor):
        x0, y0 = gen.uniform(-10, 10, 2)
        long = r == 0 and corridor
        w, h = (50.0, 2.5) if long else gen.uniform(2, 9, 2)
        angle = gen.uniform(0, np.pi)
        corners = np.array([[0, 0], [w, 0], [w, h], [0, h], [0, 0]])
        for a, b in zip(corners[:-1], corners[1:]):
            t = np.arange(0, 1, resolution / np.linalg.norm(b - a))
            t = t[(t < 0.4) | (t > 0.55)] if gen.random() < 0.5 and not long else t  # a door
            wall = a + t[:, None] * (b - a) + gen.normal(0, 0.015, (len(t), 2))
            rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
            parts.append(wall @ rot.T + [x0, y0])
        parts.append(gen.uniform([x0, y0], [x0 + w, y0 + h], (int(gen.integers(20, 120)), 2)))  # clutter
    cells = np.unique(np.floor(np.concatenate(parts) / resolution).astype(np.int64), axis=0)
    return (cells + 0.5) * resolution


def both(points, seed, settings=SETTINGS):
    out = []
    for kernels in ("numpy", "numba"):
        rng = np.random.default_rng(seed)
        lines = primitives.extract_lines(points, settings, rng, kernels=kernels)
        out.append((lines, rng.random()))  # the same random numbers consumed
    (a, ra), (b, rb) = out
    assert ra == rb
    return a, b


def assert_same_lines(a, b, atol=1e-12):
    assert len(a) == len(b)
    assert np.array_equal(a.support, b.support)
    for name in ("normals", "offsets", "endpoints"):
        assert getattr(b, name).shape == getattr(a, name).shape
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=0, atol=atol)


@pytest.mark.parametrize("seed", range(6))
def test_rooms_equal_numpy(seed):
    pts = rooms(seed, corridor=seed % 2 == 1)
    a, b = both(pts, seed)
    assert len(a) >= 4  # the walls were found (the test compares something)
    assert_same_lines(a, b)


def test_other_settings_equal_numpy():
    # a small window: most lines regrow over the whole pool
    s = LineSettings(local_radius=0.6, gap=0.2, neighbourhood_radius=0.15, min_points=5, max_grow_iterations=3)
    a, b = both(rooms(11), 3, s)
    assert len(a) > 0
    assert_same_lines(a, b)


def _fma(a: float, b: float, c: float) -> float:
    """a * b + c rounded once (exact rational arithmetic; int / int rounds correctly)."""
    r = Fraction(a) * Fraction(b) + Fraction(c)
    return r.numerator / r.denominator


def _numpy_blas_is_emulated() -> bool:
    """numpy's q.T @ q, (m, 2) @ (2,) and 2-vector dot round here as primitives_numba
    assumes (OpenBLAS x86-64), by an independent exact-FMA reference."""
    gen = np.random.default_rng(0)
    for m in (2, 3, 17, 383, 385, 900):
        q = gen.normal(size=(m, 2)) * 7
        cov, total, start = q.T @ q, [0.0, 0.0, 0.0], 0
        while start < m:  # row blocks of 384 (the last <= 768 rows halved, larger first)
            size = 384 if m - start >= 768 else (m - start + 1) // 2 if m - start > 384 else m - start
            part = [0.0, 0.0, 0.0]
            for x, y in q[start : start + size].tolist():
                part = [_fma(x, x, part[0]), _fma(x, y, part[1]), _fma(y, y, part[2])]
            total = [t + p for t, p in zip(total, part)]
            start += size
        if total != [cov[0, 0], cov[0, 1], cov[1, 1]]:
            return False
        v = gen.normal(size=2)
        if (q @ v).tolist() != [_fma(x, v[0], y * v[1]) for x, y in q.tolist()]:
            return False
        if q[0] @ v != _fma(q[0, 1], v[1], q[0, 0] * v[0]):
            return False
    return True


def test_bit_identical_with_libm_atan2(monkeypatch):
    if not _numpy_blas_is_emulated():
        pytest.skip("numpy's BLAS rounds differently on this machine: coordinates agree to 1e-12 only")

    def pca_libm(p):  # the numpy path's _pca_line with libm's atan2, as the kernel uses
        c = p.sum(axis=0) / len(p)
        q = p - c
        cov = q.T @ q
        angle = 0.5 * math.atan2(2.0 * cov[0, 1], cov[0, 0] - cov[1, 1])
        return c, np.array([np.cos(angle), np.sin(angle)])

    monkeypatch.setattr(primitives, "_pca_line", pca_libm)
    for seed in range(4):
        a, b = both(rooms(100 + seed, corridor=seed < 2), seed)
        assert len(a) > 0 and (seed >= 2 or a.support.max() > 768)
        for name in FIELDS:
            assert np.array_equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.parametrize("radius", [0.25, 0.1, 2.0, 0.15])
def test_ball_in_kdtree_order(radius):
    """_free_ball returns cKDTree.query_ball_point's points in its order (grid points at
    exact multiples of the radius included), minus the taken ones."""
    pts = rooms(7)
    tree = cKDTree(pts)
    order = tree.indices.astype(np.int64)
    lo, hi = pn._blocks(pts[order])
    taken = np.random.default_rng(1).random(len(pts)) < 0.2
    out = np.empty(len(pts), np.int64)
    for i in range(0, len(pts), 7):
        expected = np.asarray(tree.query_ball_point(pts[i], radius, return_sorted=False), dtype=np.int64)
        expected = expected[~taken[expected]]
        count = pn._free_ball(pts[order], order, lo, hi, pts[i, 0], pts[i, 1], radius * radius, taken, out)
        assert np.array_equal(out[:count], expected)


@pytest.mark.parametrize("n", [0, 1, 2, 7])
def test_empty_and_too_few_points(n):
    pts = rooms(3)[:n]
    a, b = both(pts, 0)
    assert len(a) == len(b) == 0
    for name in FIELDS:
        assert getattr(b, name).shape == getattr(a, name).shape


def test_collinear_only():
    gen = np.random.default_rng(5)
    x = np.sort(gen.uniform(0, 6, 300))
    line = np.stack([x, 0.5 * x + 1.0], axis=1)  # exactly collinear, with gaps wider than `gap`
    line = line[(x < 2.0) | (x > 2.5)]
    a, b = both(line, 2)
    assert len(a) == 2
    assert_same_lines(a, b)
    axis = np.stack([x, np.zeros_like(x)], axis=1)  # on a coordinate axis: degenerate covariance
    a, b = both(axis, 2)
    assert len(a) == 1
    assert_same_lines(a, b)


def test_no_lines_in_noise():
    pts = np.random.default_rng(9).uniform(0, 30, (200, 2))  # sparse: no seed has neighbours
    a, b = both(pts, 1)
    assert len(a) == len(b) == 0
