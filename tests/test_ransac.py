"""Hybrid RANSAC localize(): recovers a known alignment on a synthetic BEV in every scale
mode, with circles, from warm starts; deterministic; distinct ranked output; bad input."""

import dataclasses

import numpy as np
import pytest

from plan_helpers import RES, building, observe  # synthetic floorplan + BEV helpers

from zfloc_stream.settings.loading import Settings
from zfloc_stream.errors import InputError
from zfloc_stream.estimation import Hypothesis, LocalizationResult, localize
from zfloc_stream.estimation.correspondences import BevSamples, floorplan_matches
from zfloc_stream.estimation.model_generation import guided_models, solver_pool
from zfloc_stream.estimation.views import implied_poses
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.geometry.shapes import CircleSet, LineSet
from zfloc_stream.observation import BevObservation
from zfloc_stream.primitives.extract import extract_circles, extract_lines
from zfloc_stream.runtime.rng import make_rng
from zfloc_stream.geometry.sim2 import Sim2, wrap_angle

# The solver tests exercise the minimal solvers alone, at the paper's free scale: the
# correlative seeding is off here
# (it has its own tests in test_real_buildings.py).
CFG = Settings(estimator={"scale_mode": "free", "correlative": {"enabled": False}})
CENTRE = np.array([8.5, 3.0])


def with_primitives(obs: BevObservation, seed: int = 0) -> BevObservation:
    rng = make_rng(seed, "test-primitives")
    lines = extract_lines(obs.wall_points, CFG.primitives.lines, rng)
    circles = extract_circles(obs.wall_points, CFG.primitives.circles, rng)
    return dataclasses.replace(obs, lines=lines, circles=circles)


def pillared_building() -> Floorplan:
    fp = building()
    occ = fp.occupied.copy()
    rows, cols = np.mgrid[0 : occ.shape[0], 0 : occ.shape[1]]
    x, y = (cols + 0.5) * RES, (rows + 0.5) * RES
    for cx, cy in ((7.0, 2.2), (10.5, 3.9), (8.0, 4.6)):
        occ |= (x - cx) ** 2 + (y - cy) ** 2 <= 0.3**2
    return Floorplan.from_occupancy(occ, RES, (0.0, 0.0), Settings())


def pose_error(alignment: Sim2, truth: Sim2, point=CENTRE) -> tuple[float, float]:
    bev_point = truth.inverse().apply(point)
    return float(np.linalg.norm(alignment.apply(bev_point) - point)), float(abs(np.rad2deg(wrap_angle(alignment.theta - truth.theta))))


@pytest.fixture(scope="module")
def plain():
    fp = building()
    truth = Sim2(1.15, 2.1, (-4.0, 7.0))
    return fp, truth, with_primitives(observe(fp, truth, CENTRE, 6.0))


@pytest.fixture(scope="module")
def pillars():
    fp = pillared_building()
    truth = Sim2(0.9, -1.2, (5.0, 1.0))
    return fp, truth, with_primitives(observe(fp, truth, CENTRE, 5.0))


def test_localize_recovers_alignment(plain):
    fp, truth, obs = plain
    result = localize(fp, obs, CFG.estimator, make_rng(0, "t"))
    assert isinstance(result, LocalizationResult) and isinstance(result.best, Hypothesis)
    position, heading = pose_error(result.best.alignment, truth)
    assert position < 0.1 and heading < 1.0
    assert abs(result.best.alignment.s / truth.s - 1) < 0.02
    assert result.best.score > 0.9 and result.best.cc >= result.best.score
    assert result.n_models > 0
    assert set(result.timings) == {"model_estimation", "scoring", "refinement"}
    assert all(v >= 0 for v in result.timings.values())
    scores = [h.score for h in result.hypotheses]
    assert scores == sorted(scores, reverse=True)
    assert len(result.hypotheses) <= CFG.estimator.ransac.max_hypotheses


def test_hypotheses_are_distinct(plain):
    fp, _, obs = plain
    result = localize(fp, obs, CFG.estimator, make_rng(1, "t"))
    models = np.array([[h.alignment.t[0], h.alignment.t[1], h.alignment.theta, h.alignment.s] for h in result.hypotheses])
    pos, ang = implied_poses(models, obs.wall_points.mean(axis=0))
    cfg = CFG.estimator.scoring
    for i in range(len(models)):
        for j in range(i):
            same_place = np.linalg.norm(pos[i] - pos[j]) < cfg.distinct_translation
            same_heading = abs(wrap_angle(ang[i] - ang[j])) < np.deg2rad(cfg.distinct_angle_deg)
            assert not (same_place and same_heading)


def test_same_seed_same_result(plain):
    fp, _, obs = plain
    a = localize(fp, obs, CFG.estimator, make_rng(5, "t"))
    b = localize(fp, obs, CFG.estimator, make_rng(5, "t"))
    assert [h.alignment for h in a.hypotheses] == [h.alignment for h in b.hypotheses]
    assert [h.score for h in a.hypotheses] == [h.score for h in b.hypotheses]
    assert a.n_models == b.n_models


@pytest.mark.parametrize("mode", ["prior", "fixed"])
def test_scale_modes(mode):
    fp = building()
    s = 1.0 if mode == "fixed" else 1.07
    truth = Sim2(s, 0.4, (2.0, -1.0))
    obs = with_primitives(observe(fp, truth, CENTRE, 6.0))
    cfg = CFG.estimator.model_copy(update={"scale_mode": mode})
    result = localize(fp, obs, cfg, make_rng(2, "t"), scale_prior=1.0)
    position, heading = pose_error(result.best.alignment, truth)
    assert position < 0.1 and heading < 1.0
    if mode == "fixed":
        assert all(h.alignment.s == 1.0 for h in result.hypotheses)


def test_solver_pool_follows_mode_and_primitives(plain, pillars):
    for fp, obs, has_circles in ((plain[0], plain[2], False), (pillars[0], pillars[2], True)):
        fpm = floorplan_matches(fp, CFG.estimator.solvers)
        bev = BevSamples(obs, CFG.primitives.lines, CFG.estimator.solvers, 6.0)
        pools = {m: solver_pool(CFG.estimator.model_copy(update={"scale_mode": m}), bev, fpm) for m in ("free", "prior", "fixed")}
        assert "2L" not in pools["free"] and "3L" in pools["free"]
        assert {"3L", "2L"} <= set(pools["prior"])
        assert "3L" not in pools["fixed"] and "2L" in pools["fixed"]
        for pool in pools.values():
            assert ("2C" in pool) == has_circles and ("LC" in pool) == has_circles


def test_circles_alone_localize(pillars):
    """With only the pillars (no lines), 2C localizes the BEV."""
    fp, truth, obs = pillars
    assert len(obs.circles) >= 2
    circles_only = dataclasses.replace(obs, lines=LineSet.empty())
    result = localize(fp, circles_only, CFG.estimator, make_rng(3, "t"))
    assert result.best.solver in ("2C", "warm")
    position, heading = pose_error(result.best.alignment, truth)
    assert position < 0.15 and heading < 2.0


def test_line_circle_pool(pillars):
    fp, truth, obs = pillars
    cfg = CFG.estimator.model_copy(update={"solvers": CFG.estimator.solvers.model_copy(update={"pool": ["LC"]})})
    result = localize(fp, obs, cfg, make_rng(4, "t"))
    assert {h.solver for h in result.hypotheses} == {"LC"}
    position, heading = pose_error(result.best.alignment, truth)
    assert position < 0.15 and heading < 2.0


def test_warm_start_is_scored_and_refined(plain):
    fp, truth, obs = plain
    start = Sim2(truth.s * 1.02, truth.theta + 0.02, (truth.t[0] + 0.15, truth.t[1] - 0.1))
    unguided = CFG.estimator.model_copy(update={"ransac": CFG.estimator.ransac.model_copy(update={"guided_iterations": 0})})
    result = localize(fp, obs, unguided, make_rng(6, "t"), warm_start=[start], iterations=0)
    assert result.n_models == 1 and len(result.hypotheses) == 1
    best = result.best
    assert best.solver == "warm"
    assert pose_error(best.alignment, truth)[0] < pose_error(start, truth)[0]
    assert pose_error(best.alignment, truth)[0] < 0.1



def test_a_revisited_alignment_comes_back_refined_and_scored_without_samples_around_it(plain):
    """revisit (a previous round's runner-up): refined and scored like a warm start, even
    when the round's own draws find something else, but no guided models are drawn about it."""
    fp, truth, obs = plain
    start = Sim2(truth.s * 1.02, truth.theta + 0.02, (truth.t[0] + 0.15, truth.t[1] - 0.1))
    far = Sim2(truth.s, truth.theta + 1.0, (truth.t[0] + 5.0, truth.t[1]))
    result = localize(fp, obs, CFG.estimator, make_rng(6, "t"), warm_start=[far], iterations=0, revisit=[start])
    guided = localize(fp, obs, CFG.estimator, make_rng(6, "t"), warm_start=[far], iterations=0)
    assert result.n_models == guided.n_models  # nothing sampled about the revisited one
    near = [h for h in result.hypotheses if pose_error(h.alignment, truth)[0] < 0.1]
    assert near and near[0].solver == "warm"
    assert not any(pose_error(h.alignment, truth)[0] < 0.1 for h in guided.hypotheses)


@pytest.mark.parametrize("mode", ["free", "prior"])
def test_guided_samples_stay_near_the_mode_and_correct_it(plain, mode):
    fp, truth, obs = plain
    cfg = CFG.estimator.model_copy(update={"scale_mode": mode})
    prior = truth.s if mode == "prior" else 1.0
    start = Sim2(truth.s, truth.theta + 0.03, (truth.t[0] + 0.25, truth.t[1] - 0.2))  # drifted mode
    bev = BevSamples(obs, CFG.primitives.lines, cfg.solvers, CFG.floorplan.neighbour_distance)
    models = guided_models(bev, floorplan_matches(fp, cfg.solvers), start, 200, cfg, make_rng(3, "t"), prior)
    assert len(models) > 50  # nearly every sample meets its own walls
    errors = [pose_error(Sim2(m[3], m[2], (m[0], m[1])), truth) for m in models]
    assert max(e[0] for e in errors) < CFG.estimator.ransac.guided_shift + pose_error(start, truth)[0]
    assert min(e[0] for e in errors) < 0.05 and min(e[1] for e in errors) < 0.5  # the exact correction is among them
    result = localize(fp, obs, cfg, make_rng(6, "t"), scale_prior=prior, warm_start=[start], iterations=0)
    assert any(h.solver == "guided" for h in result.hypotheses)
    assert pose_error(result.best.alignment, truth)[0] < 0.1


def test_no_solver_applicable_gives_empty_result(plain):
    fp, _, obs = plain
    two_lines = dataclasses.replace(obs, lines=obs.lines.subset(np.arange(min(2, len(obs.lines)))))
    result = localize(fp, two_lines, CFG.estimator, make_rng(0, "t"))  # free scale needs 3 lines
    assert result.hypotheses == [] and result.n_models == 0


def test_bad_input_raises_input_error(plain):
    fp, _, obs = plain
    no_primitives = dataclasses.replace(obs, lines=LineSet.empty(), circles=CircleSet.empty())
    with pytest.raises(InputError, match="no lines and no circles"):
        localize(fp, no_primitives, CFG.estimator, make_rng(0, "t"))
    with pytest.raises(InputError, match="no wall points"):
        BevObservation(np.zeros((0, 2)), np.zeros(2), 0.05, np.zeros((3, 3), bool), np.zeros((3, 3)))
    with pytest.raises(InputError, match="BevObservation"):
        localize(fp, obs.wall_points, CFG.estimator, make_rng(0, "t"))
    with pytest.raises(InputError, match="scale_prior"):
        localize(fp, obs, CFG.estimator, make_rng(0, "t"), scale_prior=0.0)
    with pytest.raises(InputError, match="iterations"):
        localize(fp, obs, CFG.estimator, make_rng(0, "t"), iterations=-1)


def test_bev_neighbourhood_is_lifted_when_it_leaves_no_sample():
    """Three walls of a big hall seen in parts: the observed segments are farther apart
    than the neighbour distance, yet a 3L sample must still be drawn."""
    lines = LineSet.from_endpoints(
        [
            [[0.0, 0.0], [8.0, 0.0]],  # bottom
            [[20.0, 10.0], [20.0, 18.0]],  # right, 10 m from the bottom segment
            [[-12.0, 14.0], [-12.0, 20.0]],  # left
        ]
    )
    free = np.ones((4, 4), dtype=bool)
    obs = BevObservation(lines.endpoints.reshape(-1, 2), np.zeros(2), 0.05, free, np.ones((4, 4)), lines=lines)
    near = BevSamples(obs, CFG.primitives.lines, CFG.estimator.solvers, 6.0)
    assert len(near.triplets) > 0  # fallback: every line is a neighbour
    assert {tuple(sorted(t)) for t in near.triplets.tolist()} == {(0, 1, 2)}
    assert np.isclose(near.triplet_p.sum(), 1.0)


def test_refinement_converges_without_scale_bias(plain):
    """From a perturbed start the LM + Huber refinement (on the wall-surface field) lands on
    the true alignment; with the plain f^c (0 inside thick walls) BEV walls could slide
    into the walls and inflate the scale."""
    from zfloc_stream.estimation.field_fit import refine
    from zfloc_stream.estimation.scoring import floorplan_scorer

    fp, truth, obs = plain
    field = floorplan_scorer(fp, CFG.estimator.scoring).face_field
    start = np.array([truth.t[0] + 0.2, truth.t[1] - 0.15, truth.theta + 0.03, truth.s * 1.03])
    out = refine(field, obs.wall_points, start, CFG.estimator.refine)
    fitted = Sim2(out[3], out[2], out[:2])
    assert pose_error(fitted, truth)[0] < 0.03
    assert abs(fitted.s / truth.s - 1) < 0.005
    assert abs(np.rad2deg(wrap_angle(fitted.theta - truth.theta))) < 0.3
    fixed = refine(field, obs.wall_points, start, CFG.estimator.refine, scale_mode="fixed")
    assert fixed[3] == start[3]  # fixed scale is not touched


def test_truncated_loss_ignores_walls_the_map_lacks():
    # A map with one room; the scan also sees a wall 0.5 m beyond the room's right wall
    # that the map lacks. Plain Huber lets those points pull the fit; with
    # refine.outlier_distance they carry no weight and the true alignment stays put.
    from zfloc_stream.settings.loading import RefineSettings
    from zfloc_stream.estimation.field_fit import refine_batch
    from zfloc_stream.plans.floorplan import Floorplan

    res = 0.05
    grid = np.zeros((140, 200), dtype=bool)  # 10 m x 7 m: the bottom, left and right walls of a 9 x 6 m room
    grid[10, 10:191] = True  # cell centres at 0.525 m: the points below lie on them
    grid[10:131, 10] = grid[10:131, 190] = True
    fp = Floorplan(grid, res, (0.0, 0.0))
    t = np.linspace(0.6, 9.4, 200)
    walls = np.concatenate([np.column_stack([t, np.full_like(t, 0.525)]), np.column_stack([np.full_like(t[:120], 0.525), np.linspace(0.6, 6.4, 120)]),
                            np.column_stack([np.full_like(t[:120], 9.525), np.linspace(0.6, 6.4, 120)])])
    lacking = np.column_stack([np.full(240, 9.925), np.linspace(0.6, 6.4, 240)])  # a wall the map does not have
    points = np.concatenate([walls, lacking])
    truth = np.array([[0.0, 0.0, 0.0, 1.0]])
    plain = refine_batch(fp, points, truth, RefineSettings(), "fixed")[0]
    robust = refine_batch(fp, points, truth, RefineSettings(outlier_distance=0.3), "fixed")[0]
    assert abs(plain[0]) > 0.05  # pulled toward the unmapped wall
    assert np.abs(robust[:3]).max() < 0.02


def test_a_noisy_map_gets_a_bounded_triplet_table_and_still_localizes(plain):
    """A map of pure noise (every line near hundreds of others) used to grow its 3L table
    with the cube of its clutter (200 x 200 cells: 7.3 GB). Past floorplan.max_triplets each
    line keeps its nearest neighbours, with a warning; the plan builds and a round runs in a
    bounded amount of memory."""
    import tracemalloc

    occ = make_rng(5, "noise-map").random((150, 150)) < 0.5
    settings = Settings(floorplan={"max_triplets": 100_000}, estimator=CFG.estimator)
    tracemalloc.start()
    try:
        noisy = Floorplan.from_occupancy(occ, RES, (0.0, 0.0), settings)
        counts = np.array([len(nb) for nb in noisy.line_neighbours])
        assert int((counts * (counts - 1)).sum()) > 10 * 100_000  # the full table would be far larger
        with pytest.warns(UserWarning, match="max_triplets"):
            matches = floorplan_matches(noisy, settings.estimator.solvers)
        result = localize(noisy, plain[2], settings.estimator, make_rng(0, "noisy"), iterations=200)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert 0 < len(matches.triplets.rows) <= 100_000
    assert 0 < len(matches.pairs.rows) <= 100_000  # the 2L table from the same thinned lists
    assert len(matches.pairs.rows) < counts.sum() // 4  # far fewer than all neighbour pairs
    assert isinstance(result, LocalizationResult)
    assert peak < 400 * 2**20, f"peak {peak / 2**20:.0f} MiB"
    # deterministic: the same plan gives the same thinned table
    again = Floorplan.from_occupancy(occ, RES, (0.0, 0.0), settings)
    with pytest.warns(UserWarning, match="max_triplets"):
        assert np.array_equal(floorplan_matches(again, settings.estimator.solvers).triplets.rows, matches.triplets.rows)



def test_a_round_without_live_modes_searches_across_the_scale_prior(plain, monkeypatch):
    """At a scale prior, the exhaustive search of a round that follows no mode runs at
    correlative.scales scales spread over the prior's range, strictly inside it and
    geometrically even about the prior; a round with a live mode searches at the prior
    only (a depth network's scale error would otherwise leave the first round's seeds
    off the walls: docs/robustness.md)."""
    from zfloc_stream.estimation import model_generation

    fp, truth, obs = plain
    searched = []
    search = model_generation.correlative_models
    monkeypatch.setattr(model_generation, "correlative_models", lambda fp_, pts, scale, **k: searched.append(scale) or search(fp_, pts, scale, **k))
    cfg = Settings(estimator={"scale_mode": "prior"}).estimator
    r = cfg.solvers.prior_range
    localize(fp, obs, cfg, make_rng(0, "t"), scale_prior=1.1, iterations=50)
    assert len(searched) == cfg.correlative.scales == 3
    assert 1.1 / (1 + r) < searched[0] < searched[1] < searched[2] < 1.1 * (1 + r)
    assert searched[1] == pytest.approx(1.1) and searched[2] / searched[1] == pytest.approx(searched[1] / searched[0])
    searched.clear()
    localize(fp, obs, cfg, make_rng(0, "t"), scale_prior=1.1, iterations=50, warm_start=[truth])
    assert searched == [1.1]
    searched.clear()
    one = cfg.model_copy(update={"correlative": cfg.correlative.model_copy(update={"scales": 1})})
    localize(fp, obs, one, make_rng(0, "t"), scale_prior=1.1, iterations=50)
    assert searched == [1.1]
