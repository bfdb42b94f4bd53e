"""The compiled circle extraction (kernels="numba") gives the numpy path's circles.

Circles are compared by count and order, centres and radii to 1e-9 m, and the random
numbers consumed must be the same. The pieces are compared with their numpy counterparts
bit for bit where they use only IEEE arithmetic (sums, coverage, two-line fit); the
Gauss-Newton refit to 1e-12 (LAPACK's gelsd through numba and through numpy; identical on
the machines checked)."""

import numpy as np
import pytest

pytest.importorskip("numba")

from zfloc_stream import circles_numba as cn  # noqa: E402
from zfloc_stream import primitives  # noqa: E402
from zfloc_stream.config import CircleSettings  # noqa: E402
from zfloc_stream.geometry import CircleSet  # noqa: E402

SETTINGS = CircleSettings()


def arc(gen, centre, radius, start, span, spacing=0.05, noise=0.01):
    n = max(int(radius * span / spacing), 3)
    a = start + np.linspace(0, span, n)
    return np.asarray(centre) + radius * np.stack([np.cos(a), np.sin(a)], axis=1) + gen.normal(0, noise, (n, 2))


def segment(gen, a, b, spacing=0.05, noise=0.01):
    a, b = np.asarray(a, float), np.asarray(b, float)
    n = max(int(np.linalg.norm(b - a) / spacing), 2)
    return a + np.linspace(0, 1, n)[:, None] * (b - a) + gen.normal(0, noise, (n, 2))


def scene(seed: int, snap: bool) -> np.ndarray:
    """Pillars (arcs of any span, some too small or too large), corners and short walls
    (the shapes the tests reject), a long wall and clutter; snap: on 5 cm cell centres
    like BEV wall points (many distances at exact multiples of the link distance)."""
    gen = np.random.default_rng(seed)
    parts = [segment(gen, (-8, -8), (8, -8)), gen.uniform(-8, 8, (int(gen.integers(0, 60)), 2))]
    for _ in range(int(gen.integers(0, 5))):
        parts.append(arc(gen, gen.uniform(-6, 6, 2), gen.uniform(0.08, 1.1), gen.uniform(0, 7),
                         gen.uniform(0.5, 2 * np.pi), noise=gen.uniform(0.002, 0.02)))
    for _ in range(int(gen.integers(0, 5))):
        o, a = gen.uniform(-6, 6, 2), gen.uniform(0, np.pi)
        d = np.array([np.cos(a), np.sin(a)])
        parts.append(segment(gen, o, o + d * gen.uniform(0.3, 1.2)))
        if gen.random() < 0.6:
            parts.append(segment(gen, o, o + np.array([-d[1], d[0]]) * gen.uniform(0.3, 1.2)))
    p = np.concatenate(parts)
    if snap:
        p = (np.unique(np.floor(p / 0.05).astype(np.int64), axis=0) + 0.5) * 0.05
    return p


def both(points, seed, settings=SETTINGS):
    out = []
    for kernels in ("numpy", "numba"):
        rng = np.random.default_rng(seed)
        circles = primitives.extract_circles(points, settings, rng, kernels=kernels)
        out.append((circles, rng.random()))  # the same random numbers consumed
    (a, ra), (b, rb) = out
    assert ra == rb
    assert isinstance(b, CircleSet) and len(a) == len(b)
    np.testing.assert_allclose(b.centers, a.centers, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.radii, a.radii, rtol=0, atol=1e-9)
    return a, b


def test_scenes_equal_numpy():
    found = 0
    for seed in range(80):
        a, _ = both(scene(seed, snap=seed % 2 == 0), seed)
        found += len(a)
    assert found > 40  # the scenes hold pillars that are found, not only rejections


@pytest.mark.parametrize(
    "update",
    [
        {"refit_rounds": 0},
        {"ransac_iterations": 1},
        {"ransac_iterations": 7, "refit_iterations": 1},
        {"min_coverage_deg": 0.0, "min_span_deg": 0.0, "min_inlier_ratio": 0.0},
        {"max_gap_deg": 360.0},
        {"min_cluster_size": 2, "hdbscan_min_samples": 1},
        {"group_link_distance": 1.0, "max_radius": 3.0},
    ],
)
def test_other_settings_equal_numpy(update):
    settings = SETTINGS.model_copy(update=update)
    for seed in range(12):
        both(scene(100 + seed, snap=seed % 2 == 1), seed, settings)


def test_empty_degenerate_and_too_wide():
    for pts in (np.zeros((0, 2)), np.zeros((5, 2)), np.zeros((30, 2)), np.ones((12, 2))):
        a, b = both(pts, 0)
        assert len(b) == 0
    gen = np.random.default_rng(3)
    long_wall = segment(gen, (0, 0), (5, 0))  # one group, wider than a pillar
    assert len(both(long_wall, 1)[1]) == 0
    collinear = np.stack([np.arange(20) * 0.05, np.zeros(20)], axis=1)  # every triplet degenerate
    assert len(both(collinear, 2)[1]) == 0


def test_groups_are_scipys_partition():
    for seed in range(20):
        pts = scene(seed, snap=True)
        keep, group = primitives._candidate_groups(pts, SETTINGS)
        pairs = primitives.cKDTree(pts).query_pairs(SETTINGS.group_link_distance, output_type="ndarray")
        width = 2 * SETTINGS.max_radius + 2 * SETTINGS.inlier_distance
        k2, g2 = cn._groups(pts, pairs.astype(np.int64).reshape(-1, 2), width, SETTINGS.min_cluster_size)
        assert np.array_equal(keep, k2)
        # the same partition under other labels: a one-to-one map between the labels
        pairs_of_labels = set(zip(group.tolist(), g2.tolist()))
        assert len(pairs_of_labels) == len(set(group.tolist())) == len(set(g2.tolist()))


def test_pairwise_sum_is_numpys():
    gen = np.random.default_rng(0)
    for n in [*range(0, 300), 1000, 1023, 4097, 40001]:
        a = gen.normal(size=n) * 10 ** gen.uniform(-6, 6, n)
        assert cn._pairwise_sum(a) == np.sum(a), n


def test_coverage_and_span_bit_for_bit():
    gen = np.random.default_rng(1)
    cases = [np.zeros(0), np.zeros(1), np.array([0.0, 0.0]), np.deg2rad(np.arange(0, 181, 10)),
             np.deg2rad(np.r_[np.arange(300, 360, 10), np.arange(0, 41, 10)]), np.array([-np.pi, np.pi, 0.0])]
    for _ in range(300):
        n = int(gen.integers(2, 80))
        start, span = gen.uniform(-np.pi, np.pi), gen.uniform(0, 2 * np.pi)
        a = start + gen.uniform(0, span, n)
        cases.append(np.arctan2(np.sin(a), np.cos(a)))
    for angles in cases:
        for max_gap in (np.deg2rad(30.0), 0.01, 7.0):
            assert cn._coverage_and_span(angles, max_gap) == primitives.angular_coverage_and_span(angles, max_gap)


def test_two_line_sse_bit_for_bit():
    gen = np.random.default_rng(2)
    for n in [0, 5, 6, 7, 30, 200]:
        for _ in range(5):
            p = gen.normal(size=(n, 2)) + gen.uniform(-50, 50, 2)
            assert cn._best_two_line_sse(p, 3) == primitives._best_two_line_sse(p)


def test_fit_circle_equals_numpy():
    gen = np.random.default_rng(4)
    for _ in range(200):
        p = arc(gen, gen.uniform(-5, 5, 2), gen.uniform(0.1, 1.0), gen.uniform(0, 7), gen.uniform(0.3, 6.3), noise=0.01)
        start, r0 = p.mean(axis=0) + gen.normal(0, 0.05, 2), gen.uniform(0.1, 1.0)
        c, r = primitives._fit_circle(p, start, r0, 10)
        got = cn._fit_circle(p, np.ones(len(p), np.bool_), start[0], start[1], r0, 10)
        np.testing.assert_allclose(got, [c[0], c[1], r], rtol=0, atol=1e-12)


def test_circle_in_cluster_equals_numpy_on_accepts_and_rejects():
    """The per-cluster decision on clusters built to fail at each test in turn (no valid
    triplet, too few inliers, outside the radius range, low coverage, short span, a
    corner that two lines explain) and on pillars that pass."""
    s = SETTINGS
    deg = [float(np.deg2rad(v)) for v in (s.max_gap_deg, s.min_coverage_deg, s.min_span_deg)]
    gen = np.random.default_rng(5)
    outcomes = {True: 0, False: 0}
    for trial in range(400):
        kind = trial % 5
        if kind == 0:  # a pillar, any span
            p = arc(gen, gen.uniform(-3, 3, 2), gen.uniform(0.05, 1.2), gen.uniform(0, 7), gen.uniform(0.5, 6.3))
        elif kind == 1:  # a corner
            o = gen.uniform(-3, 3, 2)
            p = np.concatenate([segment(gen, o + (gen.uniform(0.3, 1), 0), o), segment(gen, o, o + (0, gen.uniform(0.3, 1)))])
        elif kind == 2:  # two arcs of one pillar with a hole between them
            c, r = gen.uniform(-3, 3, 2), gen.uniform(0.2, 0.8)
            p = np.concatenate([arc(gen, c, r, 0, 1.0), arc(gen, c, r, 1.0 + gen.uniform(0.3, 2.5), 1.2)])
        elif kind == 3:  # a pillar with clutter around it
            p = np.concatenate([arc(gen, (0, 0), 0.4, 0, 4.0), gen.uniform(-0.6, 0.6, (int(gen.integers(1, 20)), 2))])
        else:  # noise
            p = gen.uniform(-0.5, 0.5, (int(gen.integers(3, 40)), 2))
        context = np.concatenate([p, gen.uniform(-1, 1, (int(gen.integers(0, 4)), 2)) + p.mean(axis=0)])
        seed = int(gen.integers(1 << 30))
        expected = primitives._circle_in_cluster(p, context, s, np.random.default_rng(seed))
        idx = np.random.default_rng(seed).integers(0, len(p), size=(s.ransac_iterations, 3))
        ok, cx, cy, r = cn._circle_in_cluster(
            p, context, idx, s.inlier_distance, s.min_radius, s.max_radius, s.refit_rounds, s.refit_iterations,
            s.min_cluster_size, s.min_inlier_ratio, *deg)
        assert ok == (expected is not None), trial
        if ok:
            np.testing.assert_allclose([cx, cy, r], [*expected[0], expected[1]], rtol=0, atol=1e-9)
        outcomes[ok] += 1
    assert outcomes[True] > 40 and outcomes[False] > 200


def test_kernels_keyword_defaults_to_numpy():
    pts = scene(7, snap=True)
    a = primitives.extract_circles(pts, SETTINGS, np.random.default_rng(0))
    b = primitives.extract_circles(pts, SETTINGS, np.random.default_rng(0), kernels="numpy")
    assert len(a) > 0 and np.array_equal(a.centers, b.centers) and np.array_equal(a.radii, b.radii)
