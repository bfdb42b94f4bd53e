"""The ranking's choice of hypotheses to re-score (scoring.rank_coarse_to_fine): a partial
sort (descending_prefix) and the compiled greedy suppression (top_distinct) pick exactly
descending's order and distinct's survivors, also with many ties and deep runs of near
duplicates."""

import numpy as np

from zfloc_stream.settings.loading import ScoringSettings
from zfloc_stream.estimation.distinct_poses import descending_prefix, distinct, top_distinct
from zfloc_stream.runtime.ties import descending


def test_descending_prefix_is_a_prefix_of_descending():
    """Exactly descending's first entries (at least the asked number), ties at 1e-9
    included: values quantised to a few levels, values equal up to last bits (tie_keys
    makes them ties), signed zeros, NaN, and lengths from 1 to past the end."""
    rng = np.random.default_rng(11)
    cases = [rng.integers(0, 7, 5000) / 7.0,  # seven levels: huge ties at every cut
             rng.random(5000),
             np.where(rng.random(5000) < 0.5, 0.3, 0.3 + 1e-13),  # equal at TIE_DECIMALS
             np.where(rng.random(5000) < 0.5, 0.0, -0.0),
             np.where(rng.random(5000) < 0.1, np.nan, rng.integers(0, 4, 5000) / 4.0),
             np.full(5000, np.nan),
             np.full(5000, 0.25)]
    for values in cases:
        full = descending(values)
        for length in (1, 2, 50, 256, 800, 4999, 5000, 6000):
            prefix = descending_prefix(values, length)
            assert len(prefix) >= min(length, len(values))
            assert np.array_equal(prefix, full[: len(prefix)])
    assert descending_prefix(np.zeros(0), 10).shape == (0,)


def test_top_distinct_matches_distinct():
    """top_distinct = order[distinct(models[order])] for random coarse scores with many
    ties and models in a few tight clusters (so the greedy pass has to go deep)."""
    rng = np.random.default_rng(4)
    cfg = ScoringSettings()
    anchor = np.array([0.7, -1.2])
    for n, levels, clusters in ((10, 3, 2), (1000, 5, 3), (5000, 50, 8), (20000, 2, 40), (3000, 1, 1)):
        centres = rng.normal(0, 5, (clusters, 4)) * [1, 1, 1, 0] + [0, 0, 0, 1]
        models = centres[rng.integers(0, clusters, n)] + rng.normal(0, 0.05, (n, 4)) * [1, 1, 0.1, 0.01]
        coarse = rng.integers(0, levels, n) / levels
        for top_k in (1, 50, 500):
            settings = cfg.model_copy(update={"top_k": top_k})
            order = descending(coarse)
            expect = order[distinct(models[order], anchor, settings, top_k)]
            got = top_distinct(models, coarse, anchor, settings)
            assert np.array_equal(got, expect) and got.dtype == expect.dtype
    assert top_distinct(np.zeros((0, 4)), np.zeros(0), anchor, cfg).shape == (0,)
