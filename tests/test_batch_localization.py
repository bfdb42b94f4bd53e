"""Batch localization on the built-in scenes: a BEV fused by RollingBEV from ray-cast laser
scans along a 5 m path (2 cm range noise, 10 % outliers) at an unknown scale, aligned to the
floorplan by localize() with the default settings.

Scenario: benchmarks/inputs/batch_trial.py (also timed by benchmarks/bench_localize.py).
"""

from __future__ import annotations

import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.estimation import localize
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.sim.scenes import build_scene

from benchmarks.inputs.batch_trial import FREE_SCALE, MAX_HEADING_ERROR, MAX_POSITION_ERROR, SCENES, make_trial, pose_errors


def run_trial(scene, seed: int, settings: Settings | None = None) -> tuple[bool, object]:
    settings = settings or FREE_SCALE
    trial = make_trial(scene, seed, settings)
    result = localize(scene.floorplan, trial.obs, settings.estimator, make_rng(seed, "batch-localization", "ransac"))
    if result.best is None:
        return False, result
    position, heading = pose_errors(result.best.alignment, trial)
    return position < MAX_POSITION_ERROR and heading < MAX_HEADING_ERROR, result


@pytest.fixture(scope="module")
def scenes():
    return {name: build_scene(name, 0) for name in SCENES}


@pytest.mark.parametrize("name", SCENES)
def test_batch_localization_fast(scenes, name):
    """CI variant: 10 seeded trials per floorplan, at least 9 succeed."""
    outcomes = [run_trial(scenes[name], seed)[0] for seed in range(10)]
    assert sum(outcomes) >= 9, f"{name}: {sum(outcomes)}/10 trials localized"


@pytest.mark.slow
@pytest.mark.parametrize("name", SCENES)
def test_batch_localization_100_trials(scenes, name):
    """The statistical claim: >= 95 of 100 seeded trials per floorplan succeed."""
    outcomes = [run_trial(scenes[name], seed)[0] for seed in range(100, 200)]
    print(f"\n{name}: {sum(outcomes)}/100 trials localized")
    assert sum(outcomes) >= 95, f"{name}: {sum(outcomes)}/100 trials localized"
