"""Where and when rounds run (round_scheduler.py): the mode per start frame, fixed join
frames, the monitor's global-search request, and the evidence a round needs. The rounds
themselves are stand-ins here (their computation is tested in test_localizer*.py)."""

import threading
from types import SimpleNamespace

import numpy as np
import pytest

from zfloc_stream.stream import scheduler as round_scheduler
from zfloc_stream.settings.loading import load_settings
from zfloc_stream.geometry.shapes import CircleSet, LineSet
from zfloc_stream.stream.scheduler import RoundJob, RoundOutcome, RoundScheduler, lacking_evidence


@pytest.fixture
def fake_rounds(monkeypatch):
    """run_round replaced by a stand-in that records the thread it ran on; an outcome
    with an observation unless the job's snapshot says "skip"."""
    ran = []

    def run(floorplan, settings, job):
        ran.append((job.index, threading.current_thread() is threading.main_thread()))
        observation = None if job.snapshot == "skip" else object()
        return RoundOutcome(job.index, observation, None, timings={"primitives": 0.001})

    monkeypatch.setattr(round_scheduler, "run_round", run)
    return ran


def scheduler(*overrides) -> RoundScheduler:
    return RoundScheduler(None, load_settings(overrides=list(overrides)))


def start(s: RoundScheduler, index: int, has_pose: bool, snapshot=None):
    s.start(s.mode(has_pose), RoundJob(index, snapshot, [], False), np.zeros(3))


def landed(s: RoundScheduler, index: int) -> list[int]:
    return [scheduled.job.index for scheduled, _ in s.landed(index, {})]


def test_online_runs_inline_until_a_pose_exists_then_on_the_worker(fake_rounds):
    s = scheduler("localizer.pipeline=online", "localizer.join_delay=2")
    assert s.mode(has_pose=False) == "inline"
    start(s, 4, has_pose=False)
    assert landed(s, 4) == [4]  # the first fix lands in its own push
    assert s.mode(has_pose=True) == "pipelined"
    start(s, 9, has_pose=True)
    # a round in flight: the next start goes to the worker even without a pose (its result may give one)
    assert s.mode(has_pose=False) == "pipelined"
    assert landed(s, 10) == [] and landed(s, 11) == [9]
    assert fake_rounds == [(4, True), (9, False)]
    s.close()


def test_online_previews_the_first_round_one_frame_early_on_the_worker(fake_rounds):
    """No pose: the k-th fused frame's round is previewed from the frame before, on the
    worker, landing in the k-th frame's push; the k-th frame's own round goes to the worker
    too, so no push runs a round."""
    s = scheduler("localizer.pipeline=online", "localizer.every_k_frames=5")
    assert [s.due(fused, has_pose=False) for fused in (1, 2, 3)] == [None] * 3
    assert s.due(4, has_pose=False) == "preview"
    s.start("preview", RoundJob(3, None, [], False), np.zeros(3))
    # nothing in flight, yet not inline: the preview gave this frame a pose
    assert s.due(5, has_pose=False, previewed=True) == "pipelined"
    assert [(d.job.index, d.preview) for d, _ in s.landed(4, {})] == [(3, True)]
    s.start("pipelined", RoundJob(4, None, [], False), np.zeros(3))
    assert landed(s, 4) == [] and landed(s, 5) == [4]
    assert s.due(9, has_pose=True) is None and s.due(10, has_pose=True) == "pipelined"
    assert fake_rounds == [(3, False), (4, False)]
    s.close()


def test_a_preview_without_a_pose_leaves_the_round_inline(fake_rounds):
    """Too little evidence on one frame fewer: the k-th frame's round runs in its push, so
    the first pose comes where inline gives it."""
    s = scheduler("localizer.pipeline=online", "localizer.every_k_frames=5")
    assert s.due(4, has_pose=False) == "preview"
    s.start("preview", RoundJob(3, "skip", [], False), np.zeros(3))
    assert landed(s, 4) == [3]
    assert s.due(5, has_pose=False, previewed=False) == "inline"
    s.close()


def test_the_first_round_runs_inline_without_a_preview(fake_rounds):
    assert scheduler("localizer.first_fix_preview=false").due(4, has_pose=False) is None
    assert scheduler("localizer.first_fix_preview=false").due(5, has_pose=False) == "inline"
    # the frame before was not fused (a skipped frame): the k-th frame's round runs inline
    assert scheduler().due(5, has_pose=False) == "inline"
    # a round every frame: there is no frame in between to preview from
    assert scheduler("localizer.every_k_frames=1").due(1, has_pose=False) == "inline"
    assert scheduler("localizer.pipeline=inline").due(4, has_pose=False) is None


def test_no_preview_while_a_pose_exists_or_a_round_is_in_flight(fake_rounds):
    s = scheduler("localizer.pipeline=online", "localizer.join_delay=3")
    assert s.due(4, has_pose=True) is None
    start(s, 5, has_pose=True)  # pipelined, lands at 8
    assert s.due(9, has_pose=False) is None  # its result may give a pose
    s.close()


@pytest.mark.parametrize("pipeline", ["pipelined", "delayed"])
def test_rounds_land_exactly_at_their_join_frames_oldest_first(fake_rounds, pipeline):
    s = scheduler(f"localizer.pipeline={pipeline}", "localizer.join_delay=12", "localizer.every_k_frames=5")
    for i in (0, 5, 10):
        start(s, i, has_pose=True)  # rounds overlap: each lands 12 frames after it started
    assert s.in_flight == 3
    assert [landed(s, k) for k in (11, 12, 16, 17, 21, 22)] == [[], [0], [], [5], [], [10]]
    assert s.in_flight == 0
    assert [on_main for _, on_main in fake_rounds] == [pipeline == "delayed"] * 3
    s.close()


def test_join_delay_zero_means_every_k_frames(fake_rounds):
    s = scheduler("localizer.pipeline=pipelined", "localizer.join_delay=0", "localizer.every_k_frames=7")
    start(s, 3, has_pose=True)
    assert landed(s, 9) == [] and landed(s, 10) == [3]
    s.close()


def test_inline_mode_lands_every_round_at_once(fake_rounds):
    s = scheduler("localizer.pipeline=inline")
    for i in (0, 5):
        assert s.mode(has_pose=True) == "inline"
        start(s, i, has_pose=True)
        assert landed(s, i) == [i]


def test_a_global_search_request_outlives_a_round_started_before_it(fake_rounds):
    s = scheduler("localizer.pipeline=pipelined", "localizer.join_delay=5")
    start(s, 0, has_pose=True)  # in flight when the monitor asks
    s.request_global_search()
    assert s.global_search_wanted and s.global_search_requests == 1
    landed(s, 5)
    assert s.global_search_wanted  # round 0 started before the request: it did not answer it
    start(s, 5, has_pose=True, snapshot="skip")  # a round with no observation does no search
    landed(s, 10)
    assert s.global_search_wanted
    start(s, 10, has_pose=True)
    landed(s, 15)
    assert not s.global_search_wanted and s.global_search_requests == 1
    s.close()


def test_close_drops_rounds_no_frame_reached(fake_rounds):
    s = scheduler("localizer.pipeline=pipelined", "localizer.join_delay=5")
    start(s, 0, has_pose=True)
    s.close()
    assert s.in_flight == 0 and landed(s, 100) == []


def observation(walls: int, lines: int, circles: int):
    return SimpleNamespace(wall_points=np.zeros((walls, 2)),
                           lines=LineSet.from_endpoints(np.tile([[0.0, 0.0], [1.0, 0.0]], (lines, 1, 1))),
                           circles=CircleSet(np.zeros((circles, 2)), np.ones(circles)))


def test_a_round_needs_min_wall_points_and_min_primitives():
    settings = load_settings(overrides=["localizer.min_wall_points=50", "localizer.min_primitives=3"])
    assert lacking_evidence(observation(50, 2, 1), settings) is None  # circles count as primitives
    assert "min_wall_points" in lacking_evidence(observation(49, 3, 0), settings)
    assert "min_primitives" in lacking_evidence(observation(50, 2, 0), settings)


def test_a_round_from_nothing_draws_at_least_the_first_fix_match_fraction():
    """FIRST_FIX_MATCH_FRACTION: a round with no warm start (outside a kidnap test or an
    audit) draws at least that fraction of each BEV sample's matches; a round warm-started
    from a live mode, a kidnap test's round and a setting already at or above it keep
    estimator.ransac.match_fraction."""
    first = round_scheduler.FIRST_FIX_MATCH_FRACTION
    settings = load_settings()
    default = settings.estimator.ransac.match_fraction
    assert default < first
    fraction = lambda job, s=settings: round_scheduler.round_estimator_settings(s, job).ransac.match_fraction
    from zfloc_stream.geometry.sim2 import Sim2

    assert fraction(RoundJob(4, None, [], False)) == first
    assert fraction(RoundJob(9, None, [Sim2.identity()], False)) == default
    assert fraction(RoundJob(9, None, [], False, since=3)) == default
    assert fraction(RoundJob(9, None, [Sim2.identity()], False, since=3, audit=True)) == default
    for at in (first - 1e-9, first, first + 0.05):
        s = load_settings(overrides=[f"estimator.ransac.match_fraction={at}"])
        assert fraction(RoundJob(4, None, [], False), s) == max(at, first)
