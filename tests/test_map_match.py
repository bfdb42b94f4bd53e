"""Issue 43: a map that does not explain the frames is said. `tracking` needs the map to
explain the latest BEV (tracking_policy.MAP_UNEXPLAINED at tracking.min_explained_share),
and a run that never tracked ends with map_match's verdict (the CLI's `warning:` line)."""

import numpy as np
import pytest

from zfloc_stream.tracking import policy
from zfloc_stream.settings.loading import Settings, TrackingSettings
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.stream.map_match import MIN_JUDGED_FRAMES, MapMatch
from zfloc_stream.sim import SimSettings, build_scene, simulate


def test_map_unexplained_boundary_is_weight_times_fit_at_dominance_weight():
    """MAP_UNEXPLAINED: weight * map_fit(share) at most dominance_weight (0.9); with
    min_explained_share 0.55 and confidence_share_band 0.15 the fit is (share - 0.4) / 0.3."""
    s = TrackingSettings()
    assert (s.min_explained_share, s.confidence_share_band, s.dominance_weight) == (0.55, 0.15, 0.9)
    at = {1.0: 0.67, 0.95: 0.4 + 0.3 * 0.9 / 0.95}  # the share where weight * fit = 0.9
    for weight, share in at.items():
        assert policy.map_vouches(share + 1e-9, weight, s)
        assert not policy.map_vouches(share - 1e-9, weight, s)
    assert not policy.map_vouches(1.0, 0.9, s)  # a mode at dominance_weight is never enough
    assert policy.map_vouches(None, 0.95, s)  # nothing to judge yet: the other rules decide
    step = s.model_copy(update={"confidence_share_band": 0.0})  # the band off: the share alone, at min_explained_share
    assert policy.map_vouches(0.55, 0.95, step) and not policy.map_vouches(float(np.nextafter(0.55, 0.0)), 0.95, step)


def test_min_explained_share_boundary():
    s = TrackingSettings()
    assert policy.map_explains(0.55, s) and not policy.map_explains(float(np.nextafter(0.55, 0.0)), s)
    assert policy.map_explains(None, s)


def test_verdict_only_for_a_run_that_never_tracked():
    settings = Settings()
    match = MapMatch(None, settings.localizer, settings.tracking)
    for k in range(MIN_JUDGED_FRAMES - 1):
        match.note(0.2 if k % 3 else 0.9, "ambiguous")
    assert match.verdict() is None  # too short to say
    match.note(0.2, "initializing")
    text = match.verdict()
    assert text is not None and "does not match" in text and f"3 of {MIN_JUDGED_FRAMES} frames, 30%" in text
    match.note(0.9, "tracking")
    assert match.verdict() is None
    fits = MapMatch(None, settings.localizer, settings.tracking)  # most frames fit, no place stood out
    for k in range(MIN_JUDGED_FRAMES):
        fits.note(0.2 if k % 2 else 0.9, "ambiguous")
    text = fits.verdict()
    assert "does not match" in text and f"5 of {MIN_JUDGED_FRAMES} frames, 50%" in text and "single out one place" in text
    assert "no place in it explained" not in text


def run(scene_of_map, frames):
    loc = Localizer(build_scene(scene_of_map, seed=0).floorplan, Settings())
    with loc:
        estimates = [loc.push(f) for f in frames]
    return estimates, loc.map_match.verdict()


@pytest.fixture(scope="module")
def office_frames():
    return list(simulate(build_scene("office", seed=0), SimSettings(), seed=0, n_frames=40))


def test_wrong_map_never_tracks_and_is_said(office_frames):
    estimates, verdict = run("apartment", office_frames)
    assert sum(e.pose is not None for e in estimates) >= MIN_JUDGED_FRAMES
    assert not any(e.status == "tracking" for e in estimates)
    assert verdict is not None and "does not match" in verdict
    # no pose here is right, and the confidence says so (tracking/confidence.py: the map's fit)
    assert max(e.confidence for e in estimates if e.pose is not None) < 0.1


def test_right_map_tracks_without_a_verdict(office_frames):
    estimates, verdict = run("office", office_frames)
    assert estimates[-1].status == "tracking" and verdict is None
    assert estimates[-1].confidence > 0.9


@pytest.mark.slow
def test_aces_camera_session_on_the_fhw_map_is_never_tracking():
    """The issue's case: frames 10-11 were `tracking` (confidence 0.95) 44-46 m off."""
    from benchmarks.shared_data import SHARED_DATA
    from zfloc_stream.io.datasets.mcap import session_sequence
    from zfloc_stream.plans.loading import load_floorplan

    sessions = SHARED_DATA / "sessions"
    if not (sessions / "aces-camera-50" / "session.mcap").is_file():
        pytest.skip("no shared camera sessions here")
    settings = Settings()
    seq = session_sequence(sessions / "aces-camera-50" / "session.mcap", settings)
    loc = Localizer(load_floorplan(sessions / "fhw-camera-50" / "map.yaml", settings=settings), settings)
    with loc:
        estimates = [loc.push(f) for f in seq.frames(0, seq.n_frames)]
    assert not any(e.status == "tracking" for e in estimates)
    assert max(e.confidence for e in estimates if e.pose is not None) <= settings.tracking.dominance_weight
    assert loc.map_match.verdict() is not None
