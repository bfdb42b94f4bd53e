"""The compiled RANSAC draw (estimator.kernels: numba) equals the numpy path exactly."""

import numpy as np
import pytest

pytest.importorskip("numba")

from zfloc_stream.estimation import ransac  # noqa: E402
from zfloc_stream.estimation.ransac_numba import draw  # noqa: E402


@pytest.mark.parametrize("seed", range(12))
def test_draw_equals_numpy(seed):
    gen = np.random.default_rng(seed)
    queries, ranges = int(gen.integers(0, 300)), int(gen.choice([1, 3, 9]))
    # empty ranges and whole empty queries included
    sizes = gen.integers(0, 50, (queries, ranges)) * (gen.random((queries, ranges)) < 0.7)
    starts = gen.integers(0, 10_000, (queries, ranges))
    fraction = float(gen.choice([0.03, 0.5, 1.0]))
    expected = ransac._draw(starts, sizes, fraction, np.random.default_rng(seed))
    got = ransac._draw(starts, sizes, fraction, np.random.default_rng(seed), kernels="numba")
    assert len(got[0]) == len(expected[0])
    assert np.array_equal(got[0], expected[0]) and np.array_equal(got[1], expected[1])
    # every row lies in one of its query's ranges
    q, row = got
    inside = (row[:, None] >= starts[q]) & (row[:, None] < starts[q] + sizes[q])
    assert inside.any(axis=1).all()


def test_draw_consumes_the_same_random_numbers():
    sizes, starts = np.array([[3, 0, 5]]), np.array([[10, 20, 30]])
    a, b = np.random.default_rng(4), np.random.default_rng(4)
    ransac._draw(starts, sizes, 1.0, a)
    draw(starts, sizes, 1.0, b)
    assert a.random() == b.random()


def test_draw_with_no_candidates():
    q, row = draw(np.zeros((4, 9), np.int64), np.zeros((4, 9), np.int64), 0.03, np.random.default_rng(0))
    assert len(q) == 0 and len(row) == 0
