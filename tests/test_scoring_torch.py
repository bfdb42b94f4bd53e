"""scoring.backend torch: the same scores as the compiled kernels (bit for bit on CPU, within one
point per hypothesis on a GPU), the same localization, and one clear error without torch."""

import sys

import numpy as np
import pytest

from plan_helpers import building, observe  # synthetic floorplan + BEV helpers

from zfloc_stream.settings.loading import ScoringSettings, load_settings
from zfloc_stream.errors import BackboneError
from zfloc_stream.estimation.scoring import BevView, floorplan_scorer, scoring_kernels, sparse_line_points
from zfloc_stream.geometry.sim2 import Sim2

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def world():
    fp = building()
    truth = Sim2(1.1, 0.7, (3.0, -2.0))
    obs = observe(fp, truth, centre=np.array([8.5, 3.0]), radius=5.0)
    rng = np.random.default_rng(3)
    near = np.column_stack([3.0 + rng.normal(0, 0.3, 300), -2.0 + rng.normal(0, 0.3, 300),
                            0.7 + rng.normal(0, 0.05, 300), 1.1 * np.exp(rng.normal(0, 0.05, 300))])
    # anywhere, at any scale: most land partly or wholly outside the map
    anywhere = np.column_stack([rng.uniform(-20, 20, 700), rng.uniform(-20, 20, 700),
                                rng.uniform(-np.pi, np.pi, 700), rng.uniform(0.4, 2.5, 700)])
    return fp, obs, np.vstack([[3.0, -2.0, 0.7, 1.1], near, anywhere])


def _agree(a, b, n_points, device, exact_on_cpu=True):
    if device.type == "cpu" and exact_on_cpu:
        assert np.array_equal(a, b)  # same float operations in the same order
    else:  # fused multiply-adds may move a point across a cell boundary
        assert np.abs(a - b).max() <= 1.0 / n_points + 1e-12


@pytest.mark.parametrize("per", ["free", "observed"])
def test_torch_kernels_equal_numpy(world, per):
    fp, obs, models = world
    cfg = ScoringSettings(violation_per=per)
    numpy_kernels = floorplan_scorer(fp, cfg)
    torch_kernels = scoring_kernels(fp, cfg.model_copy(update={"backend": "torch", "device": "auto"}))
    device = torch_kernels.device
    view = BevView.of(obs, cfg.tau_v)
    sparse = sparse_line_points(obs.lines, cfg.sparse_spacing, cfg.max_sparse_points) if len(obs.lines) else obs.wall_points[::7]
    # small chunks on one side: the chunking must not matter either
    for chunk in (cfg.chunk_size, 5_000):
        # the compiled coarse kernel takes its cos and sin from the C library, torch's terms
        # from numpy (vector routines on some CPUs, an ulp apart): a point may change cell
        _agree(torch_kernels.coarse_consistency(models, sparse, chunk), numpy_kernels.coarse_consistency(models, sparse, cfg.chunk_size),
               len(sparse), device, exact_on_cpu=False)
        _agree(torch_kernels.consistency(models, obs.wall_points, cfg.tau_c, chunk),
               numpy_kernels.consistency(models, obs.wall_points, cfg.tau_c, cfg.chunk_size), len(obs.wall_points), device)
        cv_numpy = numpy_kernels.violation(models, view, cfg.tau_v, cfg.chunk_size, per)
        cv_torch = torch_kernels.violation(models, view, cfg.tau_v, chunk, per)
        if device.type == "cpu":
            assert np.array_equal(cv_torch, cv_numpy)
        else:
            assert np.abs(cv_torch - cv_numpy).max() < 0.02
    # the test means something: the truth scores high, and many models see violations
    assert numpy_kernels.consistency(models[:1], obs.wall_points, cfg.tau_c, cfg.chunk_size)[0] > 0.95
    assert (cv_numpy > 0).sum() > 50


def test_localizer_with_torch_scoring_gives_the_same_estimates():
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.sim import build_scene
    from zfloc_stream.sim.simulator import SimSettings, simulate

    scene = build_scene("rooms", seed=1)
    frames = list(simulate(scene, SimSettings(), seed=1, n_frames=15))
    runs = []
    for backend in ("numpy", "torch"):
        settings = load_settings(overrides=[f"estimator.scoring.backend={backend}", "estimator.scoring.device=cpu"])
        loc = Localizer(scene.floorplan, settings)
        runs.append([loc.push(f) for f in frames])
    assert any(e.pose is not None for e in runs[0])
    for a, b in zip(*runs):
        assert a.status == b.status
        assert (a.pose is None) == (b.pose is None)
        if a.pose is not None:
            assert np.array_equal(a.pose, b.pose)


def test_torch_backend_without_torch_is_one_clear_error(world, monkeypatch):
    fp, _, _ = world
    scorer = floorplan_scorer(fp, ScoringSettings())
    monkeypatch.setattr(scorer, "_torch_kernels", {})
    monkeypatch.setitem(sys.modules, "torch", None)  # import torch now raises ImportError
    with pytest.raises(BackboneError, match=r"estimator.scoring.backend: torch needs the optional \[torch\] extra"):
        scoring_kernels(fp, ScoringSettings(backend="torch"))


def test_a_bad_scoring_device_is_one_clear_error(world):
    fp, _, _ = world
    with pytest.raises(BackboneError, match="scoring.device 'gpu0' is not a device"):
        scoring_kernels(fp, ScoringSettings(backend="torch", device="gpu0"))


def test_the_scorer_backend_is_chosen_when_the_localizer_is_built(world, monkeypatch):
    from zfloc_stream.stream.localizer import Localizer

    fp, _, _ = world
    monkeypatch.setattr(floorplan_scorer(fp, ScoringSettings()), "_torch_kernels", {})
    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(BackboneError, match=r"estimator.scoring.backend: torch needs the optional \[torch\] extra"):
        Localizer(fp, load_settings(overrides=["estimator.scoring.backend=torch"]))
