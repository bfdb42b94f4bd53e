"""The LM + Huber refinement (field_fit.py, compiled): fits from scattered starts
land on the true alignment in every scale mode, with and without the truncated loss; rows
that cannot be refined come back unchanged; degenerate inputs are handled."""

from types import SimpleNamespace

import numpy as np
import pytest
from plan_helpers import building, observe  # synthetic floorplan + BEV helpers

from zfloc_stream.settings.loading import RefineSettings
from zfloc_stream.estimation.field_fit import refine_batch
from zfloc_stream.estimation.face_field import FaceField
from zfloc_stream.geometry.sim2 import Sim2

TRUTH = Sim2(1.1, 0.7, (3.0, -2.0))
TRUE_ROW = np.array([TRUTH.t[0], TRUTH.t[1], TRUTH.theta, TRUTH.s])


@pytest.fixture(scope="module")
def scene():
    fp = building()
    obs = observe(fp, TRUTH, centre=np.array([8.5, 3.0]), radius=5.0)
    return fp, FaceField.of(fp), obs.wall_points


def starts(n: int, seed: int = 0, scale_sigma: float = 0.03) -> np.ndarray:
    """n models scattered around the true alignment (a few centimetres, a degree or two)."""
    rng = np.random.default_rng(seed)
    return TRUE_ROW + rng.normal(size=(n, 4)) * [0.08, 0.08, 0.02, scale_sigma]


def error(models: np.ndarray, truth: np.ndarray = TRUE_ROW) -> np.ndarray:
    """Per-row max of |dx|, |dy|, |dtheta| and |ds|."""
    d = np.abs(models - truth)
    d[:, 2] = np.minimum(d[:, 2], 2 * np.pi - d[:, 2])
    return d.max(axis=1)


@pytest.mark.parametrize("scale_mode", ["fixed", "prior", "free"])
@pytest.mark.parametrize("outlier_distance", [0.0, 0.3])
def test_fits_from_scattered_starts_land_on_the_truth(scene, scale_mode, outlier_distance):
    fp, face, points = scene
    models = starts(20, scale_sigma=0.0 if scale_mode == "fixed" else 0.02)
    if scale_mode == "fixed":
        models[:, 3] = TRUTH.s
    for field in (face, fp):  # the estimator's face field and the floorplan's own f^c
        out = refine_batch(field, points, models, RefineSettings(outlier_distance=outlier_distance), scale_mode)
        assert np.median(error(out)) < 0.5 * np.median(error(models))  # the fits moved towards the truth
        assert np.median(error(out)) < 0.03


def test_a_float32_field_gives_the_float64_fit(scene):
    _, face, points = scene
    field = SimpleNamespace(distance_field=face.distance_field.astype(np.float32), origin=face.origin, resolution=face.resolution)
    models = starts(10, seed=1)
    a = refine_batch(field, points, models, RefineSettings(), "free")
    b = refine_batch(face, points, models, RefineSettings(), "free")
    assert np.abs(a - b).max() < 1e-4


def test_rows_that_cannot_be_refined_come_back_unchanged(scene):
    _, face, points = scene
    models = starts(6, seed=2)
    models[1, 0] = np.nan
    models[2, 2] = np.inf
    models[3, 3] = -1.0
    models[4, 3] = 3.0  # outside the scale bounds (0.5, 2): left alone in free scale, refined in fixed
    got = refine_batch(face, points, models, RefineSettings(), "free")
    assert np.array_equal(got[1:5], models[1:5], equal_nan=True)
    assert not np.array_equal(got[[0, 5]], models[[0, 5]])
    fixed = refine_batch(face, points, models, RefineSettings(), "fixed")
    # the scale is held (written back as exp(log s)) and the rest refined
    assert fixed[4, 3] == np.exp(np.log(models[4, 3])) and not np.array_equal(fixed[4, :3], models[4, :3])


def test_too_few_points_no_models_and_a_single_model(scene):
    _, face, points = scene
    models = starts(3, seed=3)
    for few in (np.zeros((0, 2)), points[:3]):
        assert np.array_equal(refine_batch(face, few, models, RefineSettings(), "free"), models)
    assert refine_batch(face, points, np.zeros((0, 4)), RefineSettings(), "free").shape == (0, 4)
    one = refine_batch(face, points, models[0], RefineSettings(), "free")  # one row, given flat
    assert one.shape == (1, 4) and error(one)[0] < error(models[:1])[0]


def test_one_evaluation_returns_the_start_wrapped(scene):
    # no step is taken: only the output conversion (angle wrapped, exp(log s))
    _, face, points = scene
    models = starts(5, seed=4)
    models[0, 2] += 2 * np.pi
    out = refine_batch(face, points, models, RefineSettings(max_evaluations=1), "free")
    assert np.allclose(out[:, [0, 1, 3]], models[:, [0, 1, 3]], rtol=0, atol=1e-12)
    assert np.allclose(out[:, 2], (models[:, 2] + np.pi) % (2 * np.pi) - np.pi, rtol=0, atol=1e-12)


def test_clutter_the_plan_lacks_pulls_a_plain_huber_fit_off_the_truth_but_not_the_default_one(scene):
    """A plan draws walls only: BEV points of furniture 0.6-1.5 m from any wall have nothing
    to match. With the plain Huber loss (outlier_distance 0) each still pulls, and the fit
    started at the truth walks off it; with the default truncated loss they carry no
    weight and the truth stays put (docs/plans.md: orebro 0 #15 on a two-face plan)."""
    fp, face, points = scene
    plan_points = TRUTH.apply(points)
    rng = np.random.default_rng(0)
    candidates = rng.uniform(plan_points.min(axis=0), plan_points.max(axis=0), size=(20000, 2))
    d = fp.distance(candidates)
    # furniture on one side of the room, half as many points as the walls give
    furniture = candidates[(d > 0.6) & (d < 1.5) & (candidates[:, 0] > np.median(plan_points[:, 0]))][: len(points) // 2]
    cluttered = np.concatenate([points, TRUTH.inverse().apply(furniture)])
    plain = refine_batch(face, cluttered, TRUE_ROW[None], RefineSettings(outlier_distance=0.0), "fixed")[0]
    default = refine_batch(face, cluttered, TRUE_ROW[None], RefineSettings(), "fixed")[0]
    assert RefineSettings().outlier_distance == 0.5
    assert np.hypot(*(plain[:2] - TRUE_ROW[:2])) > 0.05
    assert np.hypot(*(default[:2] - TRUE_ROW[:2])) < 0.01 and abs(default[2] - TRUE_ROW[2]) < 1e-3
