"""The consistency monitor (monitor.py): each localizer.monitor_* setting at its boundary,
just below and just above, on a floorplan whose wall distances are exact."""

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.estimation.local_refinement import explained_share
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.stream.monitor import REFERENCE_MIN_FRAMES, ConsistencyMonitor
from zfloc_stream.geometry.sim2 import Sim2

RES = 0.1  # m per cell
IDENTITY = Sim2(1.0, 0.0, np.zeros(2))


@pytest.fixture(scope="module")
def plan():
    """A 6 x 6 m room, walls one cell thick: a point at a cell centre k cells inside the
    wall's face is k * RES from the nearest wall cell centre, exactly."""
    occ = np.zeros((60, 60), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return Floorplan.from_occupancy(occ, RES, (0.0, 0.0))


def at_depth(plan, cells: int, n: int) -> np.ndarray:
    """n points at cell centres `cells` cells from the bottom wall (spread along it)."""
    cols = np.linspace(10, 49, n).round().astype(int)
    return plan.cell_to_world(np.full(n, cells), cols)


def monitor(plan, **settings) -> ConsistencyMonitor:
    return ConsistencyMonitor(plan, Settings().localizer.model_copy(update=settings))


def test_monitor_distance_is_the_reach_of_a_wall(plan):
    hits = at_depth(plan, 3, 40)  # 0.3 m from the wall (cell centres: exactly 3 * RES)
    d = float(plan.distance(hits)[0])
    assert np.allclose(plan.distance(hits), d)
    assert explained_share(plan, IDENTITY, hits, d) == 0.0  # "within": strictly closer
    assert explained_share(plan, IDENTITY, hits, np.nextafter(d, 1.0)) == 1.0
    base = dict(monitor_min_points=10, monitor_min_consistency=0.5)
    assert monitor(plan, monitor_distance=d, **base).frame_consistent(IDENTITY, hits) is False
    assert monitor(plan, monitor_distance=np.nextafter(d, 1.0), **base).frame_consistent(IDENTITY, hits) is True


def test_monitor_min_consistency_is_the_share_a_frame_needs(plan):
    hits = np.concatenate([at_depth(plan, 1, 30), at_depth(plan, 20, 10)])  # 75% near a wall
    base = dict(monitor_min_points=10, monitor_distance=0.15)
    assert monitor(plan, monitor_min_consistency=0.75, **base).frame_consistent(IDENTITY, hits) is True
    assert monitor(plan, monitor_min_consistency=np.nextafter(0.75, 1.0), **base).frame_consistent(IDENTITY, hits) is False


def test_monitor_min_points_is_the_fewest_hits_judged(plan):
    hits = at_depth(plan, 20, 30)  # far from every wall: inconsistent when judged
    assert monitor(plan, monitor_min_points=30).frame_consistent(IDENTITY, hits) is False
    assert monitor(plan, monitor_min_points=31).frame_consistent(IDENTITY, hits) is None  # too few to judge


def test_monitor_max_points_subsamples_evenly(plan):
    near, far = at_depth(plan, 1, 2), at_depth(plan, 20, 2)
    hits = np.stack([near[0], far[0], near[1], far[1]])  # every other hit explained
    base = dict(monitor_min_points=1, monitor_distance=0.15, monitor_min_consistency=0.75)
    # 3 or more: every hit checked (stride 4 // 3 = 1), half explained; 2: every second hit, all explained
    assert monitor(plan, monitor_max_points=3, **base).frame_consistent(IDENTITY, hits) is False
    assert monitor(plan, monitor_max_points=2, **base).frame_consistent(IDENTITY, hits) is True


def test_monitor_frames_inconsistent_frames_in_a_row_ask_for_a_global_search(plan):
    good, bad = at_depth(plan, 1, 40), at_depth(plan, 20, 40)
    m = monitor(plan, monitor_frames=3, monitor_distance=0.15)
    asks = [m.wants_global_search(0, IDENTITY, hits) for hits in (bad, bad, good, bad, bad, bad, bad)]
    # a consistent frame restarts the run; the third in a row asks, and the run restarts
    assert asks == [False, False, False, False, False, True, False]
    m = monitor(plan, monitor_frames=4, monitor_distance=0.15)
    assert not any(m.wants_global_search(0, IDENTITY, bad) for _ in range(3))
    assert m.wants_global_search(0, IDENTITY, bad)


def test_only_a_tracked_alignment_is_judged(plan):
    bad = at_depth(plan, 20, 40)
    m = monitor(plan, monitor_frames=1, monitor_distance=0.15)
    assert not m.wants_global_search(None, None, bad)  # initializing, lost, ambiguous: nothing to check
    assert m.inconsistent_frames == 0
    assert m.wants_global_search(0, IDENTITY, bad)


def test_the_same_frame_and_alignment_are_judged_once(plan, monkeypatch):
    hits = at_depth(plan, 1, 40)
    m = monitor(plan, monitor_distance=0.15)
    calls = []
    real = plan.distance
    monkeypatch.setattr(plan, "distance", lambda p: calls.append(1) or real(p))
    assert m.frame_consistent(IDENTITY, hits) is True
    assert m.frame_consistent(IDENTITY, hits) is True  # the estimate asks after the monitor
    assert len(calls) == 1
    assert m.frame_consistent(IDENTITY, hits.copy()) is True  # another frame: judged again
    assert len(calls) == 2


def mixed(plan, explained: int, total: int = 40) -> np.ndarray:
    """total hits of which `explained` lie one cell from a wall, the rest far from every wall."""
    return np.concatenate([at_depth(plan, 1, explained), at_depth(plan, 20, total - explained)])


def test_monitor_relative_share_is_the_drop_from_the_mode_usual_share(plan):
    """A frame explaining less than monitor_relative_share of the tracked mode's usual share
    is inconsistent, though well above monitor_min_consistency (a wrong place on a dense map)."""
    base = dict(monitor_distance=0.15, monitor_min_consistency=0.05, monitor_min_points=10)
    for ratio, expected in ((0.5, True), (np.nextafter(0.5, 1.0), False)):
        m = monitor(plan, monitor_relative_share=ratio, **base)
        for _ in range(6):  # the mode's frames: every hit explained (usual share 1.0)
            assert not m.wants_global_search(7, IDENTITY, mixed(plan, 40))
        half = mixed(plan, 20)  # half of the hits: exactly 0.5 of the usual share
        assert m.frame_consistent(IDENTITY, half, mode_id=7) is expected
        assert m.frame_consistent(IDENTITY, half) is True  # no mode named: the absolute test alone
        assert m.frame_consistent(IDENTITY, half, mode_id=8) is True  # another mode has no usual share yet


def test_monitor_reference_frames_is_how_far_back_the_usual_share_looks(plan):
    base = dict(monitor_distance=0.15, monitor_min_consistency=0.05, monitor_min_points=10, monitor_relative_share=0.5)
    for frames, usual in ((5, 1.0), (10, 0.75)):
        m = monitor(plan, monitor_reference_frames=frames, **base)
        for explained in [20] * 5 + [40] * 5:  # five frames at 0.5, then five at 1.0
            m.wants_global_search(3, IDENTITY, mixed(plan, explained))
        assert m.usual_share(3) == usual
    m = monitor(plan, **base)
    for _ in range(REFERENCE_MIN_FRAMES - 1):
        m.wants_global_search(3, IDENTITY, mixed(plan, 40))
    assert m.usual_share(3) is None  # too few frames for a usual share
    m.wants_global_search(3, IDENTITY, mixed(plan, 40))
    assert m.usual_share(3) == 1.0
    m.wants_global_search(4, IDENTITY, mixed(plan, 40))  # another mode tracked: its own usual share
    assert m.usual_share(3) is None and m.usual_share(4) is None


def test_monitor_recovery_share_is_the_bar_after_an_inconsistent_frame(plan):
    """After a frame below monitor_relative_share of the usual share, a frame is reported
    consistent again only from monitor_recovery_share of it (a turned sensor in a dense
    building keeps half its hits near some wall); reaching it ends the doubt. The run of
    inconsistent frames that starts a kidnap test still counts at the normal bar. Another
    tracked mode starts without doubt."""
    base = dict(monitor_distance=0.15, monitor_min_consistency=0.05, monitor_min_points=10, monitor_relative_share=0.5,
                monitor_frames=2)
    for bar, expected in ((0.7, True), (np.nextafter(0.7, 1.0), False)):
        m = monitor(plan, monitor_recovery_share=bar, **base)
        for _ in range(6):  # usual share 1.0
            assert not m.wants_global_search(7, IDENTITY, mixed(plan, 40))
        assert m.frame_consistent(IDENTITY, mixed(plan, 24), mode_id=7) is True  # 0.6: above the normal bar
        assert not m.wants_global_search(7, IDENTITY, mixed(plan, 10))  # 0.25: inconsistent, one of a run of 2
        assert m.frame_consistent(IDENTITY, mixed(plan, 10), mode_id=7) is False
        assert not m.wants_global_search(7, IDENTITY, mixed(plan, 24))  # 0.6: the run ends at the normal bar ...
        assert m.inconsistent_frames == 0
        assert m.frame_consistent(IDENTITY, mixed(plan, 24), mode_id=7) is False  # ... but it is not reported consistent
        assert m.frame_consistent(IDENTITY, mixed(plan, 28), mode_id=7) is expected  # exactly 0.7 of the usual share
        m.wants_global_search(7, IDENTITY, mixed(plan, 28))
        assert m.frame_consistent(IDENTITY, mixed(plan, 24), mode_id=7) is expected  # the doubt ended (or not)
    m = monitor(plan, **base)
    for _ in range(6):
        m.wants_global_search(7, IDENTITY, mixed(plan, 40))
    m.wants_global_search(7, IDENTITY, mixed(plan, 10))
    for _ in range(6):  # another mode tracked: no doubt carried over
        m.wants_global_search(8, IDENTITY, mixed(plan, 40))
    assert m.frame_consistent(IDENTITY, mixed(plan, 24), mode_id=8) is True


def test_audit_margin_and_audit_min_violation_are_the_audit_boundaries():
    """kidnap_recovery.outscored (the audit): another place beyond the pose-jump gate must
    score at least audit_margin above the tracked one, and the recent frames must see open
    space through at least audit_min_violation of the tracked place's walls (its Cv)."""
    from types import SimpleNamespace

    from zfloc_stream.stream.recovery import outscored

    old, far = IDENTITY, Sim2(1.0, 0.0, np.array([17.0, 0.0]))
    tracker = SimpleNamespace(pose_jumped=lambda a, b, xy, mode: bool(np.hypot(*np.subtract(a.t, b.t)) > 1.0))
    mode = SimpleNamespace(id=1)
    lc = Settings().localizer
    gap, violation = lc.audit_margin, lc.audit_min_violation

    def audit(there_score, here_score, here_cv, margin=gap, min_violation=violation):
        hyps = [SimpleNamespace(alignment=far, score=there_score, cv=0.0), SimpleNamespace(alignment=old, score=here_score, cv=here_cv)]
        return outscored(hyps, old, mode, tracker, np.zeros(2), margin, min_violation)

    assert audit(0.5 + gap, 0.5, violation)  # exactly the margin and the violation
    assert not audit(np.nextafter(0.5 + gap, 0.0), 0.5, violation)  # just under the margin
    assert not audit(0.9, 0.5, np.nextafter(violation, 0.0))  # a clear gap, but the old walls were not seen through
    assert not audit(0.9, 0.5, violation, min_violation=np.nextafter(violation, 1.0))
    near = [SimpleNamespace(alignment=Sim2(1.0, 0.0, np.array([0.5, 0.0])), score=0.9, cv=0.0)]
    assert not outscored(near, old, mode, tracker, np.zeros(2), gap, violation)  # within the gate: the same place
    elsewhere_only = [SimpleNamespace(alignment=far, score=0.3, cv=0.0)]
    assert outscored(elsewhere_only, old, mode, tracker, np.zeros(2), gap, violation)  # the round kept nothing at the old place
