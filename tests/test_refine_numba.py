"""The compiled LM refinement (estimator.kernels: numba) against the numpy refine_batch:
the same refined models on synthetic and real-building inputs, in every scale mode, with
and without the truncated loss, and the same rows left alone (too few points, non-finite
or out-of-bounds models)."""

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("numba")

from test_scoring import building, observe  # synthetic floorplan + BEV helpers

from zfloc_stream.config import RefineSettings
from zfloc_stream.estimation import ransac
from zfloc_stream.estimation.refine import refine_batch
from zfloc_stream.estimation.refine_numba import refine_batch_numba
from zfloc_stream.estimation.scoring import FaceField
from zfloc_stream.sim2 import Sim2

# The two paths differ only in summation order (numpy: pairwise cost, BLAS J^T W J; the
# kernel: sequential) and in libm's exp/cos/sin against numpy's, so a converged fit agrees
# to ~1e-12 (measured on real-building calls). 1e-7 (m, rad, scale) is far below anything
# that matters on a 5 cm grid and five orders above that noise: a wrong weight, clamp or
# acceptance test fails it.
TOL = 1e-7
TRUTH = Sim2(1.1, 0.7, (3.0, -2.0))
PROFILE_ROUND = Path(__file__).resolve().parents[1] / "benchmarks" / "profile_round.py"
ACES_LOG = Path(__file__).resolve().parents[2] / "shared" / "data" / "carmen" / "aces-corrected.log.gz"


def difference(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-column max |a - b| of model rows (over finite entries), the angle compared on the circle."""
    finite = np.isfinite(a) & np.isfinite(b)
    d = np.abs(np.where(finite, a, 0.0) - np.where(finite, b, 0.0))
    d[:, 2] = np.minimum(d[:, 2], 2 * np.pi - d[:, 2])
    return d.max(axis=0)


def assert_same(field, points, models, settings, scale_mode, scale_bounds=(0.5, 2.0)):
    expected = refine_batch(field, points, models, settings, scale_mode, scale_bounds)
    got = refine_batch(field, points, models, settings, scale_mode, scale_bounds, kernels="numba")
    assert got.shape == expected.shape
    assert np.array_equal(got[~np.isfinite(got)], expected[~np.isfinite(expected)], equal_nan=True)
    assert difference(got, expected).max() < TOL, difference(got, expected)
    return expected, got


@pytest.fixture(scope="module")
def scene():
    fp = building()
    obs = observe(fp, TRUTH, centre=np.array([8.5, 3.0]), radius=5.0)
    return fp, FaceField.of(fp), obs.wall_points


def starts(n: int, seed: int = 0, scale_sigma: float = 0.03) -> np.ndarray:
    """n models scattered around the true alignment (a few decimetres, a few degrees)."""
    rng = np.random.default_rng(seed)
    truth = np.array([TRUTH.t[0], TRUTH.t[1], TRUTH.theta, TRUTH.s])
    return truth + rng.normal(size=(n, 4)) * [0.25, 0.25, 0.05, scale_sigma]


@pytest.mark.parametrize("scale_mode", ["fixed", "prior", "free"])
@pytest.mark.parametrize("outlier_distance", [0.0, 0.3])
def test_synthetic_scene_matches_numpy(scene, scale_mode, outlier_distance):
    fp, face, points = scene
    settings = RefineSettings(outlier_distance=outlier_distance)
    models = starts(20, scale_sigma=0.0 if scale_mode == "fixed" else 0.03)
    for field in (face, fp):  # the estimator's face field and the floorplan's own f^c
        expected, got = assert_same(field, points, models, settings, scale_mode)
        assert not np.array_equal(expected, models)  # the fits moved: the comparison is not vacuous


@pytest.mark.parametrize("damping", [1e-11, 1e6])
def test_damping_extremes_and_a_tiny_tolerance(scene, damping):
    # lambda starting at its floor or high, and a tolerance that lets the fit run on past
    # convergence until rejected steps push lambda over its 1e12 stop or the budget ends
    _, face, points = scene
    settings = RefineSettings(initial_damping=damping, damping_factor=100.0, tolerance=1e-12)
    assert_same(face, points, starts(20, seed=5), settings, "free")


def test_float32_field_and_points_outside_the_grid(scene):
    # a float32 field keeps numpy's float32 differences; shifted starts put part of the
    # BEV beyond the grid (the edge value plus the distance to the grid)
    _, face, points = scene
    field = SimpleNamespace(distance_field=face.distance_field.astype(np.float32), origin=face.origin, resolution=face.resolution)
    models = starts(10, seed=1)
    models[:, 0] += 4.0
    assert_same(field, points, models, RefineSettings(), "free")


def test_rows_that_cannot_be_refined_come_back_unchanged(scene):
    _, face, points = scene
    models = starts(6, seed=2)
    models[1, 0] = np.nan
    models[2, 2] = np.inf
    models[3, 3] = -1.0
    models[4, 3] = 3.0  # outside the scale bounds (0.5, 2): left alone in free scale, refined in fixed
    expected, got = assert_same(face, points, models, RefineSettings(), "free")
    assert np.array_equal(got[1:5], models[1:5], equal_nan=True)
    assert not np.array_equal(got[[0, 5]], models[[0, 5]])
    _, fixed = assert_same(face, points, models, RefineSettings(), "fixed")
    # the scale is held (written back as exp(log s), as numpy does) and the rest refined
    assert fixed[4, 3] == np.exp(np.log(models[4, 3])) and not np.array_equal(fixed[4, :3], models[4, :3])


def test_too_few_points_no_models_and_a_single_model(scene):
    _, face, points = scene
    models = starts(3, seed=3)
    for few in (np.zeros((0, 2)), points[:3]):
        assert np.array_equal(refine_batch_numba(face, few, models, RefineSettings(), "free"), models)
    assert refine_batch_numba(face, points, np.zeros((0, 4)), RefineSettings(), "free").shape == (0, 4)
    assert_same(face, points, models[0], RefineSettings(), "free")  # one row, given flat
    assert_same(face, points[:4], models, RefineSettings(), "free")  # the fewest points refined


def test_one_evaluation_returns_the_start_as_numpy_writes_it(scene):
    # no step is taken: only the output conversion (angle wrap, exp(log s)), done in numpy
    # by both paths, so the rows are equal bit for bit
    _, face, points = scene
    models = starts(5, seed=4)
    models[0, 2] += 2 * np.pi
    settings = RefineSettings(max_evaluations=1)
    expected = refine_batch(face, points, models, settings, "free")
    assert np.array_equal(refine_batch_numba(face, points, models, settings, "free"), expected)


@pytest.fixture(scope="module")
def real_calls():
    """The refine_batch calls of a Localizer over the first 12 frames of the shared Carmen
    ACES window (benchmarks/profile_round.py's laser-aces case): real BEV wall points on a
    map built from scans, the estimator's face field, RANSAC's top models and the tracked
    mode's local refinement."""
    if not ACES_LOG.is_file():
        pytest.skip("shared real logs not available")
    spec = importlib.util.spec_from_file_location("profile_round", PROFILE_ROUND)
    profile_round = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(profile_round)
    floorplan, frames, settings = profile_round.build_case("laser-aces")
    from zfloc_stream import localizer

    calls = []

    def record(field, points, models, settings, scale_mode, scale_bounds=(0.5, 2.0), kernels="numpy"):
        calls.append((field, np.array(points), np.array(models), settings, scale_mode, scale_bounds))
        return refine_batch(field, points, models, settings, scale_mode, scale_bounds)

    patched = (ransac, localizer)
    try:
        for module in patched:
            module.refine_batch = record
        loc = localizer.Localizer(floorplan, settings)
        for frame in frames[:12]:
            loc.push(frame)
    finally:
        for module in patched:
            module.refine_batch = refine_batch
    assert len(calls) >= 5
    return calls


def test_real_building_calls_match_numpy(real_calls):
    for field, points, models, settings, scale_mode, scale_bounds in real_calls:
        assert_same(field, points, models, settings, scale_mode, scale_bounds)
        # and again in free scale with the truncated loss, on the same real inputs
        free = RefineSettings(**{**settings.model_dump(), "outlier_distance": 0.3})
        assert_same(field, points, models, free, "free", (0.5, 2.0))
