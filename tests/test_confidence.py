"""Estimate.confidence (tracking/confidence.py, issue 43): the map's fit at its boundaries
(tracking.confidence_share_band around tracking.min_explained_share), 0 on `lost` and
contradicted frames, strictly below dominance_weight unless the status vouches for the pose."""

import math

import numpy as np
import pytest

from zfloc_stream.estimate import Status
from zfloc_stream.settings.loading import TrackingSettings
from zfloc_stream.tracking.confidence import frame_confidence
from zfloc_stream.tracking.policy import map_fit
from zfloc_stream.tracking.status import Decision, Rule

S = TrackingSettings()
TRACKED = Decision(Status.TRACKING, Rule.TRACKING)


def test_confidence_share_band_is_the_ramp_around_min_explained_share():
    m, band = S.min_explained_share, S.confidence_share_band
    assert (m, band) == (0.55, 0.15)
    assert map_fit(m - band, S) == 0.0 and map_fit(float(np.nextafter(m - band, 1.0)), S) > 0.0
    assert map_fit(m, S) == pytest.approx(0.5)
    assert map_fit(float(np.nextafter(m + band, 0.0)), S) < 1.0 and map_fit(m + band, S) == pytest.approx(1.0)
    assert map_fit(1.0, S) == 1.0 and map_fit(0.0, S) == 0.0
    assert map_fit(None, S) == 1.0  # nothing judged yet: no evidence against the pose
    step = S.model_copy(update={"confidence_share_band": 0.0})
    assert map_fit(m, step) == 1.0 and map_fit(float(np.nextafter(m, 0.0)), step) == 0.0


def test_confidence_is_weight_times_confirmation_times_the_maps_fit():
    assert frame_confidence(0.95, 1.0, None, TRACKED, False, S) == pytest.approx(0.95)
    assert frame_confidence(0.95, 0.5, 1.0, TRACKED, False, S) == pytest.approx(0.475)
    assert frame_confidence(1.0, 2.0, 1.0, TRACKED, False, S) == 1.0  # confirmation at most 1
    # a wrong map's `tracking` frame (the shared data: explained 0.575-0.618, weight 0.95-1)
    # falls below 0.9; a right map's usual share (median 0.93) leaves the confidence as it was
    assert frame_confidence(1.0, 1.0, 0.6, TRACKED, False, S) < 0.9
    assert frame_confidence(1.0, 1.0, 0.75, TRACKED, False, S) == 1.0


def test_a_lost_or_contradicted_frame_has_no_confidence():
    assert frame_confidence(1.0, 1.0, 1.0, TRACKED, True, S) == 0.0
    for rule in (Rule.COLLAPSED, Rule.OVERTAKEN, Rule.PRUNED, Rule.WAITING_FOR_CONFIRMATION):
        assert frame_confidence(1.0, 1.0, 1.0, Decision(Status.LOST, rule), False, S) == 0.0


def test_confidence_above_dominance_weight_only_when_the_status_vouches():
    cap = math.nextafter(S.dominance_weight, 0.0)  # strictly below: ">= dominance_weight" takes only vouched frames
    assert frame_confidence(1.0, 1.0, 1.0, Decision(Status.AMBIGUOUS, Rule.AMBIGUITY), False, S) == cap
    assert frame_confidence(1.0, 1.0, 1.0, Decision(Status.INITIALIZING, Rule.THIN_EVIDENCE), False, S) == cap
    assert frame_confidence(1.0, 1.0, 1.0, Decision(Status.INITIALIZING, Rule.PREVIEW), False, S) == 1.0
    assert frame_confidence(0.8, 1.0, 1.0, Decision(Status.AMBIGUOUS, Rule.AMBIGUITY), False, S) == pytest.approx(0.8)
