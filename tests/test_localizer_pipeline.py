"""Pipelined rounds (localizer.pipeline): a round started at frame i is applied exactly at
frame i + round_delay, so a worker gives bit for bit what the same round computed inline
and applied at the same frame ("delayed"); inline mode stays today's behaviour."""

from pathlib import Path

import threading

import numpy as np
import pytest
from localizer_helpers import Kidnapped, carried_off, estimate_bits, run_localizer, settings_with

from zfloc_stream.stream import scheduler as round_scheduler_module
from zfloc_stream.settings.loading import load_settings
from zfloc_stream.errors import ConfigError, InputError
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.io.session import read_session, record_session
from zfloc_stream.io.session.replay import replay_session, replay_settings
from zfloc_stream.sim import LaserSimSettings, SimSettings, build_scene, simulate, simulate_laser
from zfloc_stream.tools import cli, replay_cli


@pytest.fixture(scope="module")
def kidnapped_camera():
    """A camera run whose odometry jumps: the monitor asks for a global search mid-stream."""
    scene = build_scene("apartment", seed=2)
    seq = simulate(scene, SimSettings(width=80, height=60), seed=2, n_frames=60)
    return scene.floorplan, list(Kidnapped(seq, 30))


@pytest.fixture(scope="module")
def laser():
    scene = build_scene("office", seed=1)
    return scene.floorplan, list(simulate_laser(scene, LaserSimSettings(), seed=1, n_frames=30).frames)


@pytest.mark.parametrize("delay", ["0", "3", "12"])  # 0 = every_k_frames; 12: rounds overlap
def test_pipelined_equals_delayed_inline_bit_for_bit(kidnapped_camera, delay):
    floorplan, frames = kidnapped_camera
    # the odometry-jump rule would restart at the jump: off, so the monitor's request is what crosses a round
    off = "tracking.odometry_jump_window=0"
    delayed = run_localizer(floorplan, frames, settings_with("localizer.pipeline=delayed", f"localizer.join_delay={delay}", off))
    with Localizer(floorplan, settings_with("localizer.pipeline=pipelined", f"localizer.join_delay={delay}", off)) as loc:
        piped = [loc.push(f) for f in frames]
        assert loc.rounds.global_search_requests >= 1  # the monitor's global-search request crossed a pending round
    assert [estimate_bits(e) for e in piped] == [estimate_bits(e) for e in delayed]
    assert delayed[-1].pose is not None


@pytest.mark.parametrize("delay", ["0", "12"])
def test_an_odometry_jump_on_the_worker_gives_the_same_bits(kidnapped_camera, delay):
    """The odometry jump restarts the map and drops the rounds started before it
    (tracking_policy.ODOMETRY_JUMP): the same bits with the rounds on a worker."""
    floorplan, frames = kidnapped_camera
    delayed = run_localizer(floorplan, frames, settings_with("localizer.pipeline=delayed", f"localizer.join_delay={delay}"))
    with Localizer(floorplan, settings_with("localizer.pipeline=pipelined", f"localizer.join_delay={delay}")) as loc:
        piped = [loc.push(f) for f in frames]
        assert loc.odometry_jumps == 1
    assert [estimate_bits(e) for e in piped] == [estimate_bits(e) for e in delayed]
    assert any(e.round_skipped and "before an odometry jump" in e.round_skipped for e in piped) or delay == "0"


def test_a_kidnap_test_on_the_worker_gives_the_same_bits():
    """Carried off (a later stretch spliced in, odometry standing still): the kidnap test's
    rounds run on the worker beside the tracker's, and the run is the delayed one's, bit for
    bit, adoption included."""
    scene = build_scene("apartment", seed=2)
    spliced = carried_off(list(simulate(scene, SimSettings(), seed=2, n_frames=260)), 50, 150, 30)
    delayed = run_localizer(scene.floorplan, spliced, settings_with("localizer.pipeline=delayed"))
    with Localizer(scene.floorplan, settings_with("localizer.pipeline=pipelined")) as loc:
        piped = [loc.push(f) for f in spliced]
        assert loc.kidnap_tests >= 1 and loc.kidnaps_found == 1
    assert [estimate_bits(e) for e in piped] == [estimate_bits(e) for e in delayed]


def test_a_worker_process_gives_the_same_bits(laser):
    floorplan, frames = laser
    delayed = run_localizer(floorplan, frames, settings_with("localizer.pipeline=delayed"))
    piped = run_localizer(floorplan, frames, settings_with("localizer.pipeline=pipelined", "localizer.worker=process"))
    assert [estimate_bits(e) for e in piped] == [estimate_bits(e) for e in delayed]


def test_a_round_lands_exactly_at_its_join_frame(laser):
    floorplan, frames = laser
    k, delay = 5, 3
    inline = run_localizer(floorplan, frames, settings_with("localizer.pipeline=inline"))
    piped = run_localizer(floorplan, frames, settings_with("localizer.pipeline=pipelined", f"localizer.join_delay={delay}"))
    starts = [i for i in range(len(frames)) if (i + 1) % k == 0]
    assert [i for i, e in enumerate(inline) if "model_estimation" in e.timings] == starts  # inline: in the starting push
    assert [i for i, e in enumerate(piped) if "model_estimation" in e.timings] == [i + delay for i in starts if i + delay < len(frames)]
    assert all("round_start" in piped[i].timings and "round_wait" in piped[i + delay].timings for i in starts[:-1])
    # nothing is known before the first result lands; from then on every frame has a pose
    first = starts[0] + delay
    assert all(e.pose is None for e in piped[:first]) and all(e.pose is not None for e in piped[first:])
    assert inline[starts[0]].pose is not None


def test_inline_ignores_join_delay(laser):
    floorplan, frames = laser
    a = run_localizer(floorplan, frames[:12], settings_with("localizer.pipeline=inline"))
    b = run_localizer(floorplan, frames[:12], settings_with("localizer.pipeline=inline", "localizer.join_delay=3"))
    assert [estimate_bits(e) for e in a] == [estimate_bits(e) for e in b]


def test_a_refused_round_is_skipped_and_a_bug_surfaces_at_the_join(laser, monkeypatch):
    floorplan, frames = laser
    settings = settings_with("localizer.pipeline=pipelined", "localizer.join_delay=5")

    def refuse(*args, **kwargs):
        raise InputError("estimator refused this BEV")

    monkeypatch.setattr(round_scheduler_module, "localize", refuse)
    est = run_localizer(floorplan, frames[:15], settings)
    assert all(e.pose is None and e.status == "initializing" for e in est)
    # the reason lands on the join frame (round started at 4 -> 9, at 9 -> 14), nowhere else
    assert [e.frame for e in est if e.round_skipped] == [9, 14]
    assert all(e.round_skipped == "estimator error: estimator refused this BEV" for e in est if e.round_skipped)

    def bug(*args, **kwargs):
        raise RuntimeError("a bug in the round")

    monkeypatch.setattr(round_scheduler_module, "localize", bug)
    with Localizer(floorplan, settings) as loc:
        for f in frames[:9]:  # round started at frame 4, joined at 9
            loc.push(f)
        with pytest.raises(RuntimeError, match="a bug in the round"):
            loc.push(frames[9])


def test_close_stops_the_worker_and_drops_rounds_no_frame_reached(laser):
    floorplan, frames = laser
    workers = _round_workers()  # other tests' localizers may still hold theirs
    loc = Localizer(floorplan, settings_with("localizer.pipeline=pipelined", "localizer.join_delay=5"))
    for f in frames[:7]:  # round started at frame 4 would land at frame 9
        loc.push(f)
    assert loc.rounds.in_flight == 1 and _round_workers() == workers + 1
    loc.close()
    assert loc.rounds.in_flight == 0 and loc.last_round is None and _round_workers() == workers


def _round_workers() -> int:
    """Live threads of the round worker (ThreadPoolExecutor names them zfloc-round_N)."""
    return sum(t.name.startswith("zfloc-round") and t.is_alive() for t in threading.enumerate())


def test_bad_pipeline_settings_are_one_config_error_line():
    for override, word in (("localizer.pipeline=sideways", "localizer.pipeline"), ("localizer.join_delay=-1", "localizer.join_delay"), ("localizer.worker=gpu", "localizer.worker")):
        with pytest.raises(ConfigError) as err:
            settings_with(override)
        assert word in str(err.value) and "\n" not in str(err.value)


def test_replay_check_of_a_pipelined_session(laser, tmp_path):
    floorplan, frames = laser
    path = tmp_path / "piped.mcap"
    settings = settings_with("localizer.pipeline=pipelined", "localizer.join_delay=2")
    logged = record_session(path, floorplan, frames, settings)
    session = read_session(path)
    again = replay_settings(session)
    assert again.localizer.pipeline == "pipelined" and again.localizer.join_delay == 2  # replay uses the logged mode
    result = replay_session(session, again, session.floorplan, check=True)
    assert result.divergence is None and result.checked == len(frames)
    assert [estimate_bits(e) for e in result.estimates] == [estimate_bits(e) for e in logged]


def test_run_and_replay_cli_agree_on_a_pipelined_session(laser, tmp_path, capsys):
    floorplan, frames = laser
    source = tmp_path / "source.mcap"
    record_session(source, floorplan, frames[:20], settings_with())
    plan = floorplan.write_ros(tmp_path / "plan")
    out = tmp_path / "out"
    args = ["run", "--floorplan", str(plan), "--input", str(source), "--out", str(out), "--set", "localizer.pipeline=pipelined", "--no-progress"]
    assert cli.main(args + ["--set", "estimator.scale_mode=fixed"]) == 0
    assert replay_cli.main([str(Path(out) / "session.mcap"), "--exact"]) == 0


def test_online_reports_a_preview_at_the_inline_first_fix_frame_then_joins_later(laser):
    """online (the default): a preview round started one frame early on the worker gives
    the first pose at the frame where inline gives it; the tracker never sees the preview,
    so from the next frame on the run is the pipelined one, bit for bit. Without the preview
    the first round runs inline, with inline's bits. Every round after the first pose lands
    round_delay frames after its start, on the worker."""
    floorplan, frames = laser
    k = 5
    inline = run_localizer(floorplan, frames, settings_with("localizer.pipeline=inline"))
    online = run_localizer(floorplan, frames, settings_with())
    pipelined = run_localizer(floorplan, frames, settings_with("localizer.pipeline=pipelined"))
    unpreviewed = run_localizer(floorplan, frames, settings_with("localizer.first_fix_preview=false"))
    assert settings_with().localizer.pipeline == "online"
    first = next(i for i, e in enumerate(inline) if e.pose is not None)
    assert next(i for i, e in enumerate(online) if e.pose is not None) == first
    assert online[first].status != "tracking"
    # no push ran a round: each round's stage timings come with a wait for the worker
    assert all("round_wait" in e.timings for e in online if "model_estimation" in e.timings)
    assert "round_start" in online[first - 1].timings and "round_wait" in online[first].timings
    assert [estimate_bits(e) for e in online[first + 1:]] == [estimate_bits(e) for e in pipelined[first + 1:]]
    assert [estimate_bits(e) for e in unpreviewed[: first + 1]] == [estimate_bits(e) for e in inline[: first + 1]]
    later = [i for i in range(first, len(frames)) if (i + 1) % k == 0]
    assert later and all("round_start" in online[i].timings for i in later)
    delay = settings_with().localizer.round_delay
    assert all("round_wait" in online[i + delay].timings for i in later if i + delay < len(frames))
    assert all(e.pose is not None for e in online[first:])


def test_a_preview_with_too_little_evidence_leaves_the_first_round_inline(laser):
    """The preview sees one frame fewer: where that is below localizer.min_wall_points but
    the k-th frame's BEV is not, the k-th frame's round runs inline, and the first fix is
    inline's, at inline's frame, with inline's bits."""
    floorplan, frames = laser
    walls = {}
    for k in (4, 5):  # the wall points of the first round's BEV, one frame fewer and at the k-th frame
        with Localizer(floorplan, settings_with("localizer.pipeline=inline", f"localizer.every_k_frames={k}")) as loc:
            for f in frames[:k]:
                loc.push(f)
            walls[k] = len(loc.last_observation.wall_points)
    assert walls[4] < walls[5]
    needs = f"localizer.min_wall_points={walls[4] + 1}"
    inline = run_localizer(floorplan, frames[:10], settings_with("localizer.pipeline=inline", needs))
    online = run_localizer(floorplan, frames[:10], settings_with(needs))
    assert online[4].pose is not None and "round_start" not in online[4].timings  # the round ran in the push
    assert "min_wall_points" in online[4].round_skipped  # the preview's reason
    assert estimate_bits(online[4])[:-1] == estimate_bits(inline[4])[:-1]  # all but round_skipped


def test_online_replays_bit_for_bit_on_a_thread_or_a_process(laser):
    floorplan, frames = laser
    a = run_localizer(floorplan, frames, settings_with("localizer.pipeline=online"))
    b = run_localizer(floorplan, frames, settings_with("localizer.pipeline=online", "localizer.worker=process"))
    assert [estimate_bits(e) for e in a] == [estimate_bits(e) for e in b]


def test_studies_run_rounds_inline_unless_told_otherwise():
    from zfloc_stream.study import cell_settings

    assert cell_settings({}, seed=3).localizer.pipeline == "inline"
    assert cell_settings({"localizer": {"pipeline": "online"}}, seed=3).localizer.pipeline == "online"
    assert cell_settings({}, 3, {"estimator": {"scale_mode": "fixed"}}).localizer.pipeline == "inline"
