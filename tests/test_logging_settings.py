"""Boundary tests of logging.* settings no other test names: the range limits a LaserScan
from another tool is read with (logging.foreign_scan_range_min / _max) and the replay
summary's success (logging.success_distance / success_last_frames)."""

import numpy as np
import pytest

from benchmarks.inputs.session_frames import laser_frames
from session_helpers import write_fake_session
from benchmarks.inputs.hostile_sessions import frame_messages, write_messages

from zfloc_stream.estimate import Estimate
from zfloc_stream.io.datasets.mcap import session_sequence
from zfloc_stream.io.session import read_session
from zfloc_stream.io.session.replay import summarize_run
from zfloc_stream.settings.loading import load_settings

# beam 0 at 0.5 m, beam 1 at 4 m: the limits below are set on each side of them
RANGES = (0.5, 4.0)
EPS = 1e-6


def foreign_laser_file(path):
    """A LaserScan session as another tool writes it: no zfloc range metadata on /scan."""
    frames = laser_frames(3, seed=2)
    for f in frames:
        f.ranges[:2] = RANGES
    write_messages(path, frame_messages(frames))
    return path


def valid_beams(path, *overrides: str) -> list[tuple[bool, bool]]:
    session = read_session(path, settings=load_settings(overrides=list(overrides)))
    return [tuple(bool(v) for v in f.valid[:2]) for f in session.frames()]


def test_foreign_scan_range_max_ends_the_valid_ranges(tmp_path):
    """logging.foreign_scan_range_max: a reading at the limit is a no-return (range_max is
    exclusive), one a hair under it a return."""
    path = foreign_laser_file(tmp_path / "foreign.mcap")
    assert valid_beams(path, "logging.foreign_scan_range_max=4.0") == [(True, False)] * 3
    assert valid_beams(path, f"logging.foreign_scan_range_max={4.0 + EPS!r}") == [(True, True)] * 3


def test_foreign_scan_range_min_starts_the_valid_ranges(tmp_path):
    """logging.foreign_scan_range_min: a reading at the limit is a return (inclusive), one a
    hair under it a no-return."""
    path = foreign_laser_file(tmp_path / "foreign.mcap")
    assert valid_beams(path, "logging.foreign_scan_range_min=0.5") == [(True, True)] * 3
    assert valid_beams(path, f"logging.foreign_scan_range_min={0.5 + EPS!r}") == [(False, True)] * 3


def test_foreign_scan_ranges_reach_a_dataset_read_and_never_override_logged_limits(tmp_path):
    """The caller's settings reach the frames of a session sequence (run --input, a study
    spec); a zfloc-written file's /scan carries its own limits, which win."""
    path = foreign_laser_file(tmp_path / "foreign.mcap")
    settings = load_settings(overrides=["logging.foreign_scan_range_max=4.0"])
    seq = session_sequence(path, settings)
    frame = next(iter(seq.frames(0, 1)))
    assert frame.range_max == 4.0 and not frame.valid[1]
    ours = tmp_path / "ours.mcap"
    write_fake_session(ours, laser_frames(2, seed=2))
    for f in read_session(ours, settings=settings).frames():
        assert (f.range_min, f.range_max) == (0.05, 10.0)  # laser_frames' own limits


# --- the replay summary's success -------------------------------------------------------
ERRORS = [5.0, 5.0, 0.5, 0.9, 1.0]  # metres off, frame by frame


def summary(*overrides: str):
    truth = [(0.0, 0.0, 0.0)] * len(ERRORS)
    estimates = [Estimate(i, 0.1 * i, "tracking", np.array([e, 0.0, 0.0]), None, None, 1.0) for i, e in enumerate(ERRORS)]
    return summarize_run(estimates, truth, load_settings(overrides=list(overrides)))


@pytest.mark.parametrize("distance, success", [(1.0, True), (1.0 - EPS, False)])
def test_success_distance_bounds_the_last_frames_errors(distance, success):
    """logging.success_distance: the last frames (3 here) all within it (<=) is a success;
    the worst of them is 1.0 m."""
    assert summary(f"logging.success_distance={distance!r}", "logging.success_last_frames=3").success is success


@pytest.mark.parametrize("last, success", [(3, True), (4, False)])
def test_success_last_frames_is_how_many_final_frames_must_be_within(last, success):
    """logging.success_last_frames: the last 3 frames are within 1 m, the last 4 reach back
    to a frame 5 m off."""
    assert summary("logging.success_distance=1.0", f"logging.success_last_frames={last}").success is success
