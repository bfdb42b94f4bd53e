"""Rank keys robust to last-bit differences (ties.py): values equal but for their last
bits tie, and the tie goes to index order on every machine."""

import numpy as np

from zfloc_stream.runtime.ties import descending, tie_key, tie_keys


def test_last_bit_differences_tie_and_keep_index_order():
    a = 0.7310585786300049
    b = float(np.nextafter(a, 1.0))  # what another CPU might compute for the same score
    assert np.argsort([-a, -b], kind="stable").tolist() == [1, 0]  # a bare sort flips on the last bit
    assert descending([a, b]).tolist() == [0, 1] and descending([b, a]).tolist() == [0, 1]
    assert tie_key(a) == tie_key(b)
    assert (tie_keys([a, b]) >= tie_keys([b, a])).all()  # "not worse" holds both ways


def test_real_differences_still_rank():
    scores = [0.2, 0.9, 0.9 + 1e-6, -0.5, 0.9]
    assert descending(scores).tolist() == [2, 1, 4, 0, 3]
    assert sorted(range(3), key=lambda j: -tie_key([0.1, 0.3, 0.2][j])) == [1, 2, 0]
