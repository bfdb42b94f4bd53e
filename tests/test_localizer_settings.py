"""Boundary tests of localizer.* settings no other test names: localizer.local_every_k_frames
(the local refinement between rounds, stream/localizer.py)."""

import pytest

from laser_helpers import laser_run

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.stream.localizer import Localizer

N_FRAMES = 24


@pytest.fixture(scope="module")
def walk():
    scene, seq = laser_run("rooms", N_FRAMES)
    return scene.floorplan, list(seq.frames)


def refined_between_rounds(walk, *overrides: str) -> set[int]:
    """The fused-frame counts at which a push refined the tracked mode locally on its own
    (not as part of a landed round)."""
    floorplan, frames = walk
    seen = set()
    with Localizer(floorplan, load_settings(overrides=list(overrides))) as loc:
        inner = loc._refine_locally

        def spy(timings, outcome=None):
            if outcome is None:
                seen.add(loc.frames_fused)
            return inner(timings, outcome)

        loc._refine_locally = spy
        for frame in frames:
            loc.push(frame)
        assert loc.frames_fused == N_FRAMES
    return seen


@pytest.mark.parametrize("k", [3, 4])
def test_local_every_k_frames_refines_on_every_kth_fused_frame_between_rounds(walk, k):
    """localizer.local_every_k_frames=k: a push refines locally at each fused-frame count that
    is a multiple of k, unless a round starts there (rounds every localizer.every_k_frames = 5
    fused frames, a first-fix preview the frame before); never elsewhere. 0: never between
    rounds."""
    every = load_settings().localizer.every_k_frames
    assert every == 5
    seen = refined_between_rounds(walk, f"localizer.local_every_k_frames={k}")
    multiples = {n for n in range(1, N_FRAMES + 1) if n % k == 0}
    assert seen <= multiples
    assert {n for n in multiples if n % every not in (0, every - 1)} <= seen
    assert seen  # k = 3 and 4 differ: 3, 6, ... against 4, 8, ...


def test_local_every_k_frames_zero_refines_only_after_rounds(walk):
    assert refined_between_rounds(walk, "localizer.local_every_k_frames=0") == set()
