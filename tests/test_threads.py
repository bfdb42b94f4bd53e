"""estimator.threads: a round's independent pieces on several threads (zfloc_stream/runtime/threads.py)
give the single-threaded bits, whatever the thread count."""

import threading

import numpy as np
import pytest
from draw_helpers import assert_same_bits, draw_scene, estimator_for
from localizer_helpers import estimate_bits, run_localizer, settings_with

from zfloc_stream.runtime import threads
from zfloc_stream.errors import ConfigError
from zfloc_stream.estimation import field_fit
from zfloc_stream.estimation import angle_search, draws, model_generation, scoring
from zfloc_stream.sim import LaserSimSettings, SimSettings, build_scene, simulate, simulate_laser



def test_run_keeps_the_order_and_uses_several_threads():
    seen = set()

    def piece(k):
        seen.add(threading.get_ident())
        assert threads.current() == 1  # a piece never asks the pool again
        return k * k

    assert threads.run(piece, list(range(50))) == [k * k for k in range(50)]  # outside a limit: serial
    assert seen == {threading.get_ident()}
    with threads.limit(3):
        assert threads.current() == 3
        assert threads.run(piece, list(range(200))) == [k * k for k in range(200)]
    assert threads.current() == 1


def test_a_failing_piece_raises_after_every_piece_stopped():
    done = []

    def piece(k):
        if k == 3:
            raise ValueError("piece 3")
        done.append(k)
        return k

    with threads.limit(2), pytest.raises(ValueError, match="piece 3"):
        threads.run(piece, list(range(8)))
    assert sorted(done) == [0, 1, 2, 4, 5, 6, 7]


def test_limit_unless_set_keeps_the_enclosing_limit():
    with threads.limit(2):
        with threads.limit(4, unless_set=True):
            assert threads.current() == 2
        with threads.limit(4):
            assert threads.current() == 4
    with threads.limit(4, unless_set=True):
        assert threads.current() == 4


def test_ranges_and_resolve():
    with threads.limit(3):
        assert threads.ranges(10) == [(0, 3), (3, 6), (6, 10)]
        assert threads.ranges(10, min_size=6) == [(0, 10)]
        assert threads.ranges(0) == [(0, 0)]
    assert threads.ranges(10) == [(0, 10)]
    assert threads.resolve(5) == 5
    cores = threads.available_cores()
    assert threads.resolve(0) == max(1, min(threads.AUTO_MAX, cores))


def test_bad_thread_count_is_a_config_error():
    with pytest.raises(ConfigError):
        settings_with("estimator.threads=-1")


@pytest.fixture
def split_everything(monkeypatch):
    """Every kernel call splits, however small (the real minima keep tests' small inputs whole)."""
    monkeypatch.setattr(scoring, "_MIN_LOOKUPS_PER_THREAD", 1)
    monkeypatch.setattr(scoring, "_MIN_VIOLATION_MODELS_PER_THREAD", 1)
    monkeypatch.setattr(field_fit, "_MIN_MODELS_PER_THREAD", 1)
    monkeypatch.setattr(draws, "MIN_DRAWS_PER_THREAD", 1)
    split = []
    run = threads.run

    def spy(fn, pieces):
        if threads.current() > 1 and len(pieces) > 1:
            split.append(fn.__name__)
        return run(fn, pieces)

    for module in (scoring, field_fit, draws, angle_search):
        monkeypatch.setattr(module.threads, "run", spy)
    return split


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("mode", ["free", "prior"])
def test_3l_draws_in_pieces_are_the_whole(split_everything, seed, mode):
    bev, fp = draw_scene(seed)
    cfg = estimator_for(mode, 0.5)
    a, b = np.random.default_rng(seed), np.random.default_rng(seed)
    whole = model_generation.models_3l(bev, fp, 700, cfg, a)
    with threads.limit(7):  # pieces start in the middle of a query's draws
        pieces = model_generation.models_3l(bev, fp, 700, cfg, b)
    assert_same_bits(pieces, whole)
    assert split_everything and a.random() == b.random()


@pytest.mark.parametrize("case", ["laser", "camera"])
def test_localizer_gives_the_same_bits_with_any_thread_count(split_everything, case):
    """Every split kernel (correlative angles, 3L draws, coarse / full scores, violation,
    refinement) runs in pieces on 3 threads: every estimate equals the 1-thread run's."""
    if case == "laser":
        scene = build_scene("office", seed=1)
        frames = list(simulate_laser(scene, LaserSimSettings(), seed=1, n_frames=30).frames)
    else:
        scene = build_scene("apartment", seed=2)
        frames = list(simulate(scene, SimSettings(width=80, height=60), seed=2, n_frames=30))
    one = run_localizer(scene.floorplan, frames, settings_with("estimator.threads=1"))
    assert not split_everything
    three = run_localizer(scene.floorplan, frames, settings_with("estimator.threads=3"))
    assert [estimate_bits(e) for e in three] == [estimate_bits(e) for e in one]
    assert one[-1].pose is not None
    wanted = {"piece", "search_pair", "<lambda>"}
    assert wanted <= set(split_everything)


def office_snapshot():
    """A BEV snapshot of 20 laser scans through the office scene, passing a pillar."""
    from zfloc_stream.settings.loading import load_settings
    from zfloc_stream.frontend.bev import RollingBEV

    scene = build_scene("office", seed=0)
    bev = RollingBEV(load_settings())
    for frame in list(simulate_laser(scene, LaserSimSettings(), seed=0, n_frames=80).frames)[:20]:
        bev.add(frame)
    return bev.snapshot()


def assert_same_observations(a, b, circles=True):
    for name in ("wall_points", "free", "clearance"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    for x, y in ((a.lines, b.lines),) + (((a.circles, b.circles),) if circles else ()):
        for u, v in zip(x.__dict__.values(), y.__dict__.values()):
            assert np.array_equal(u, v)


def test_observation_jobs_on_threads_give_the_serial_observation():
    """The BEV observation's clustering, line extraction and clearance run side by side;
    the circle fits draw after the lines: the same observation (a pillar included)."""
    from zfloc_stream.runtime.rng import make_rng

    snapshot = office_snapshot()
    serial = snapshot.observation(make_rng(0, "obs"))
    with threads.limit(3):
        side_by_side = snapshot.observation(make_rng(0, "obs"))
    assert len(serial.circles) >= 1 and len(serial.lines) > 5
    assert_same_observations(side_by_side, serial)


def test_an_observation_without_circles_keeps_everything_else():
    """A floorplan without pillars cannot match a BEV circle, so rounds ask for none
    (circles=False): no circles, and the same lines, walls, free mask and clearance."""
    from zfloc_stream.runtime.rng import make_rng

    snapshot = office_snapshot()
    full = snapshot.observation(make_rng(0, "obs"))
    lean = snapshot.observation(make_rng(0, "obs"), circles=False)
    assert len(full.circles) >= 1 and len(lean.circles) == 0
    assert_same_observations(lean, full, circles=False)
