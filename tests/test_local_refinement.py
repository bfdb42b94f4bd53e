"""Local refinement of the tracked mode (estimation/local_refinement.py): the chain, and
each localizer.local_* setting at its boundary."""

from types import SimpleNamespace

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.estimation.local_refinement import LocalRefinement
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.geometry.sim2 import Sim2

RES = 0.05
TRUE = Sim2(1.0, 0.0, np.zeros(2))
OFF = Sim2(1.0, 0.02, np.array([0.08, -0.06]))  # where the mode's alignment is: 10 cm, 1 deg off


@pytest.fixture(scope="module")
def plan():
    """An L-shaped set of rooms (so the fit is constrained in x, y and angle)."""
    occ = np.zeros((160, 200), dtype=bool)
    occ[:3, :] = occ[-3:, :] = occ[:, :3] = occ[:, -3:] = True
    occ[80:83, :120] = True  # an interior wall
    occ[:80, 120:123] = True
    return Floorplan.from_occupancy(occ, RES, (0.0, 0.0))


@pytest.fixture(scope="module")
def hits(plan):
    """Wall faces seen from inside the lower-left room, in the plane frame (= floorplan: TRUE)."""
    face = plan.face_points
    inside = (face[:, 0] < 6.0) & (face[:, 1] < 4.0)
    return [face[inside][k::5] for k in range(5)]  # five frames' worth


def chain(plan, **localizer) -> LocalRefinement:
    s = Settings()
    return LocalRefinement(plan, s.localizer.model_copy(update=localizer), s.estimator.model_copy(update={"scale_mode": "fixed"}))


def mode(alignment, id=1):
    return SimpleNamespace(id=id, alignment=alignment)


def centre_error(alignment: Sim2, hits) -> float:
    pts = np.concatenate(hits)
    return float(np.linalg.norm(alignment.apply(pts) - TRUE.apply(pts), axis=1).max())


def test_the_chain_pulls_a_drifted_mode_onto_the_walls_and_continues(plan, hits):
    local = chain(plan)
    best = mode(OFF)
    local.update(best, hits, frames_fused=10)
    assert local.mode_id == 1 and centre_error(local.alignment, hits) < 0.02 < centre_error(OFF, hits)
    assert local.alignment_of_mode(best) is local.alignment
    assert local.alignment_of_mode(mode(OFF, id=2)) is OFF  # another mode: its own alignment
    first = local.alignment
    local.update(best, hits, frames_fused=15)  # continues from its own last alignment
    assert local.mode_id == 1 and centre_error(local.alignment, hits) <= centre_error(first, hits) + 1e-9


def test_a_chain_that_explains_less_than_the_mode_starts_again_from_the_mode(plan, hits):
    """Each step is judged against where it started only: on frames a plan explains little
    of, a chain of accepted steps could walk away from the mode the rounds keep right (intel
    810 #100 on the one-face plan: 35 deg turned, 1.5-4.8 m off). A chain the mode's own
    alignment explains the recent hits better than goes back to the mode."""
    local = chain(plan)
    best = mode(OFF)
    local.update(best, hits, frames_fused=10)
    walked = Sim2(1.0, 0.3, np.array([1.5, -1.0]))  # where such a chain had got to
    local.alignment = walked
    local.update(best, hits, frames_fused=15)  # 5 frames: a step of at most 1 m, too short to walk back
    assert local.mode_id == 1 and centre_error(local.alignment, hits) < 0.02 < centre_error(walked, hits)


def gate(metres: float):
    """A pose-jump gate (HypothesisTracker.pose_jumped's signature): the alignment moved the
    sensor more than `metres`."""
    return lambda previous, current, sensor, mode: bool(np.linalg.norm(current.apply(sensor) - previous.apply(sensor)) > metres)


def test_the_chain_stays_within_the_modes_pose_jump_gate(plan, hits):
    """The recent frames alone can fit a wrong place near the mode (a plan that leaves out
    what they saw): a step beyond the tracker's pose-jump gate of the mode is refused; a
    chain that explains the recent hits less than the mode starts again from it."""
    sensor = [np.array([2.0, 1.5])]
    wide, narrow = chain(plan), chain(plan)
    wide.update(mode(OFF), hits, 10, sensor * len(hits), gate(1.0))
    narrow.update(mode(OFF), hits, 10, sensor * len(hits), gate(0.01))  # OFF is 10 cm from where the hits fit
    assert wide.mode_id == 1 and centre_error(wide.alignment, hits) < 0.02
    assert narrow.mode_id is None and narrow.alignment_of_mode(mode(OFF)) is OFF
    walked = Sim2(1.0, 0.05, np.array([0.3, 0.2]))  # within the step bound, beyond a 0.2 m gate
    wide.alignment = walked
    wide.update(mode(OFF), hits, 15, sensor * len(hits), gate(0.2))
    assert wide.mode_id == 1 and centre_error(wide.alignment, hits) < 0.02


def test_local_frames_zero_turns_it_off(plan, hits):
    local = chain(plan, local_frames=0)
    local.update(mode(OFF), hits, frames_fused=10)
    assert local.mode_id is None and local.alignment_of_mode(mode(OFF)) is OFF


def test_nothing_tracked_or_no_hits_ends_the_chain(plan, hits):
    local = chain(plan)
    local.update(mode(OFF), hits, frames_fused=10)
    local.update(None, hits, frames_fused=11)
    assert local.mode_id is None
    local.update(mode(OFF), hits, frames_fused=12)
    local.update(mode(OFF), [np.zeros((0, 2))], frames_fused=13)
    assert local.mode_id is None


def test_local_max_step_bounds_the_step_per_fused_frame(plan, hits):
    free = chain(plan, local_max_step=1000.0)
    free.update(mode(OFF), hits, frames_fused=4)  # 4 frames since the chain's start (frame 0)
    pts = np.concatenate(hits)
    centre = pts.mean(axis=0)
    step = float(np.linalg.norm(free.alignment.apply(centre) - OFF.apply(centre)))
    assert step > 0.05
    at = chain(plan, local_max_step=step / 4)
    at.update(mode(OFF), hits, frames_fused=4)
    assert at.mode_id == 1  # exactly the limit: accepted
    below = chain(plan, local_max_step=np.nextafter(step / 4, 0.0))
    below.update(mode(OFF), hits, frames_fused=4)
    assert below.mode_id is None  # a jump: only a round may propose another place


def test_local_max_points_subsamples_the_recent_hits(plan, hits):
    n = sum(len(h) for h in hits)
    many, few = chain(plan, local_max_points=n), chain(plan, local_max_points=n // 4)
    many.update(mode(OFF), hits, frames_fused=10)
    few.update(mode(OFF), hits, frames_fused=10)
    assert many.alignment is not None and few.alignment is not None
    assert not np.array_equal(many.alignment.params(), few.alignment.params())  # another subset, another fit
    same = chain(plan, local_max_points=n)
    same.update(mode(OFF), hits, frames_fused=10)
    assert np.array_equal(same.alignment.params(), many.alignment.params())


def test_local_outlier_distance_is_the_local_fits_outlier_rule(plan, hits):
    clutter = [np.concatenate([h, h[:40] + np.array([0.0, 0.5])]) for h in hits]  # furniture 0.5 m off a wall
    plain, robust = chain(plan, local_outlier_distance=0.0), chain(plan, local_outlier_distance=0.2)
    plain.update(mode(OFF), clutter, frames_fused=10)
    robust.update(mode(OFF), clutter, frames_fused=10)
    assert centre_error(robust.alignment, hits) < centre_error(plain.alignment, hits)
