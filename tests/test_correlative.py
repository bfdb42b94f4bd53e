"""The fast correlative search (float32 FFT, pruned transforms) returns exactly what the
plain per-angle float64 FFT returns, ties spread evenly over the tied placements."""

import numpy as np
import pytest

from zfloc_stream.estimation import angle_search as A
from zfloc_stream.estimation import correlative as C
from zfloc_stream.sim import LaserSimSettings, build_scene, simulate_laser
from zfloc_stream.geometry.sim2 import Sim2, wrap_angle

from correlative_reference import correlative_models_reference

LASER = LaserSimSettings(fov_deg=180.0, n_beams=180, max_range=10.0)


def _points(scene, n_frames, seed):
    seq = simulate_laser(scene, LASER, seed=seed, n_frames=n_frames)
    return np.concatenate([
        np.column_stack([f.ranges[f.valid] * np.cos(f.angles[f.valid]), f.ranges[f.valid] * np.sin(f.angles[f.valid])])
        @ f.T_odom_sensor[:2, :2].T + f.T_odom_sensor[:2, 3]
        for f in seq.frames
    ])


@pytest.mark.parametrize("scene_name,seed,n_frames", [("office", 0, 8), ("office", 3, 20), ("hall", 1, 10), ("symmetric", 2, 6)])
@pytest.mark.parametrize("cell,step,peaks", [(0.25, 4.0, 10), (0.1, 2.0, 8)])
def test_fast_search_is_the_reference_bit_for_bit(scene_name, seed, n_frames, cell, step, peaks):
    scene = build_scene(scene_name, seed=seed)
    points = _points(scene, n_frames, seed)
    kw = dict(cell=cell, angle_step_deg=step, tolerance=0.3, peaks=peaks)
    for scale in (1.0, 0.93):
        fast = C.correlative_models(scene.floorplan, points, scale, **kw)
        ref = correlative_models_reference(scene.floorplan, points, scale, **kw)
        assert fast.shape == ref.shape and np.array_equal(fast, ref)


def test_float32_counts_round_to_the_exact_counts_everywhere():
    scene = build_scene("office", seed=0)
    points = C.thin_to_grid(_points(scene, 15, 0), 0.25)
    local = points - points.mean(axis=0)
    half = int(np.ceil((np.linalg.norm(local, axis=1).max() + 0.25) / 0.25)) + 1
    side = 2 * half
    spectrum, shape, _ = C._mask_spectrum(scene.floorplan, 0.25, 0.3 + 0.125, half)
    n_i, n_j = shape[0] - side + 1, shape[1] - side + 1
    H, W, M = A._fast_grid(spectrum, side, n_i, n_j)
    for theta in np.deg2rad([0.0, 37.0, 180.0, 271.0]):
        ij = np.ascontiguousarray(A._angle_template(local, theta, 0.25, half))
        exact = A._exact_scores(spectrum, ij, n_i, n_j)
        spec = A._forward(ij, side, H, W)
        A._pair_products(spec, M, M, np.zeros((0, 0), np.complex64))
        fast = A._peaks(spec, n_i, n_j, W, 10)
        assert fast is not None
        best, counts = fast
        assert np.array_equal(exact[best], counts) and len(best) == 10
        boundary = counts.min()
        assert (exact > boundary).sum() == (counts > boundary).sum()  # nothing above the boundary missed
        ties = np.flatnonzero(exact == boundary)
        picked = np.sort(best[counts == boundary])
        if len(ties) > len(picked):  # spread evenly over the tied placements, in index order
            spread = ties[np.round(np.linspace(0, len(ties) - 1, len(picked))).astype(int)]
            assert np.array_equal(picked, spread)


@pytest.mark.parametrize("H, W", [(64, 48), (63, 50)])
def test_a_templates_180_degree_turn_has_the_mirrored_spectrum(H, W):
    rng = np.random.default_rng(5)
    side = 20
    ij = rng.integers(0, side, size=(60, 2))
    turned = (side - 1) - ij
    M = (rng.normal(size=(H, W // 2 + 1)) + 1j * rng.normal(size=(H, W // 2 + 1))).astype(np.complex64)
    empty = np.zeros((0, 0), np.complex64)
    direct = A._forward(turned, side, H, W)
    A._pair_products(direct, M, M, empty)  # the turned template's correlation spectrum
    spec = A._forward(ij, side, H, W)
    mirrored = np.empty_like(spec)
    A._pair_products(spec, M, M * A._mirror_phase(side, H, W), mirrored)
    assert mirrored.shape == direct.shape
    assert np.abs(mirrored - direct).max() < 1e-3 * len(ij) * np.abs(M).max()
    # and it is not trivially so: the unturned template's spectrum is far from it
    assert np.abs(spec - direct).max() > 1.0


def _segments(angles_deg, length=3.0, spacing=2.0):
    """Parallel segments, one per angle, side by side (a LineSet)."""
    from zfloc_stream.geometry.shapes import LineSet
    ends = []
    for k, a in enumerate(np.deg2rad(angles_deg)):
        d = np.array([np.cos(a), np.sin(a)])
        base = np.array([0.0, k * spacing])
        ends.append([base, base + length * d])
    return LineSet.from_endpoints(np.array(ends))


def test_plausible_angles_keep_the_rotations_that_put_walls_on_walls():
    floorplan = _segments([0, 90, 0, 90, 0])
    bev = _segments([10, 100, 10])  # the BEV's walls are the floorplan's turned by -10 (or 80, 170, 260)
    kept = C.plausible_angles(bev, floorplan, 4.0, 0.3)
    grid = np.arange(0.0, 360.0, 4.0)
    assert kept.shape == grid.shape
    for truth in (350.0, 80.0, 170.0, 260.0):
        nearest = np.argmin(np.abs((grid - truth + 180) % 360 - 180))
        assert kept[nearest]
    assert not kept[np.argmin(np.abs(grid - 35.0))]  # 45 degrees off every wall direction
    assert kept.sum() < 0.3 * len(grid)
    assert np.array_equal(kept[:45], kept[45:])  # a 180-degree turn agrees just as well
    assert C.plausible_angles(bev, floorplan, 4.0, 0.0) is None
    assert C.plausible_angles(_segments([]), floorplan, 4.0, 0.3) is None


def test_a_masked_search_returns_only_searched_angles_and_all_angles_is_the_reference():
    scene = build_scene("office", seed=0)
    points = _points(scene, 10, 0)
    kw = dict(cell=0.25, angle_step_deg=4.0, tolerance=0.3, peaks=10)
    grid = np.deg2rad(np.arange(0.0, 360.0, 4.0))
    everything = C.correlative_models(scene.floorplan, points, angles=np.ones(len(grid), dtype=bool), **kw)
    assert np.array_equal(everything, correlative_models_reference(scene.floorplan, points, **kw))
    mask = np.zeros(len(grid), dtype=bool)
    mask[[0, 1, 22, 23, 45, 46, 67, 68]] = True  # 0, 4, 88, 92 degrees and their turns
    models = C.correlative_models(scene.floorplan, points, angles=mask, **kw)
    assert len(models) > 0
    on_grid = np.argmin(np.abs((models[:, 2][:, None] - grid[None, :] + np.pi) % (2 * np.pi) - np.pi), axis=1)
    assert mask[on_grid].all()


def test_direction_histogram_is_continuous_across_bin_edges():
    """A wall at 90 degrees must not jump a bin with the last bit of arctan2 (SIMD kernels
    differ by CPU), or the searched rotations would differ from machine to machine."""
    below = C._direction_histogram(_segments([90.0 - 1e-9]))
    above = C._direction_histogram(_segments([90.0 + 1e-9]))
    assert np.abs(below - above).max() < 1e-6
    assert np.isclose(below.sum(), 3.0)  # the length, shared between neighbouring bins


# ---- the compiled per-angle search ---------------------------------------------------


@pytest.mark.parametrize("scene_name,seed,n_frames", [("office", 0, 8), ("symmetric", 2, 6)])
def test_a_grid_without_180_degree_turns_is_the_reference_too(scene_name, seed, n_frames):
    """step 7: 360 / 7 is no whole number, so no angle has its 180-degree turn on the grid
    (no mirrored spectra); the other tests' steps pair every angle with its turn."""
    scene = build_scene(scene_name, seed=seed)
    points = _points(scene, n_frames, seed)
    kw = dict(cell=0.25, angle_step_deg=7.0, tolerance=0.3, peaks=6)
    fast = C.correlative_models(scene.floorplan, points, **kw)
    assert len(fast) > 0 and np.array_equal(fast, correlative_models_reference(scene.floorplan, points, **kw))


def test_the_search_falls_back_to_the_exact_pass(monkeypatch):
    """No float32 count vouched for (slack < 0): every angle takes the float64 pass, and
    the models are still the reference's; so is a map too small to prune, and too few points."""
    scene = build_scene("office", seed=0)
    points = _points(scene, 8, 0)
    kw = dict(cell=0.25, angle_step_deg=8.0, tolerance=0.3, peaks=10)
    ref = correlative_models_reference(scene.floorplan, points, **kw)
    calls = []
    exact = A._exact_peaks
    monkeypatch.setattr(A, "_exact_peaks", lambda *a: calls.append(1) or exact(*a))
    monkeypatch.setattr(A, "ROUNDING_SLACK", -1.0)
    assert np.array_equal(C.correlative_models(scene.floorplan, points, **kw), ref)
    assert len(calls) == 45  # every angle
    monkeypatch.undo()
    assert C.correlative_models(scene.floorplan, points[:2], **kw).shape == (0, 4)
    # a small room and many peaks: fewer rows of placements than peaks, the exact pass
    from zfloc_stream.plans.floorplan import Floorplan

    occupied = np.zeros((16, 16), dtype=bool)
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    room = Floorplan.from_occupancy(occupied, 0.1, (0.0, 0.0))
    pts = np.array([[0.1, 0.1], [1.4, 0.1], [1.4, 1.4], [0.1, 1.4], [0.7, 0.1], [0.1, 0.8]])
    kw = dict(cell=0.25, angle_step_deg=30.0, tolerance=0.3, peaks=400)
    found = C.correlative_models(room, pts, **kw)
    assert len(found) > 0 and np.array_equal(found, correlative_models_reference(room, pts, **kw))


def test_peak_picking_spreads_ties_like_linspace():
    for n_tied in (2, 3, 5, 17, 100, 1001):
        for per_angle in (1, 2, 3, 4, 9, 16):
            score = np.zeros((n_tied + 3, 1), np.float32)
            score[:3, 0] = 5.0  # three above the boundary
            score[3:, 0] = 2.0
            if per_angle > n_tied + 3 or per_angle <= 3:
                continue
            best, counts, ok = A._pick(score, 1, per_angle, 0.25)
            spread = 3 + np.round(np.linspace(0, n_tied - 1, per_angle - 3)).astype(np.int64)
            assert ok and np.array_equal(best, np.concatenate([[0, 1, 2], spread]))
            assert np.array_equal(counts, np.where(best < 3, 5.0, 2.0))


def test_peak_picking_refuses_what_it_cannot_vouch_for():
    score = np.zeros((20, 30), np.float32)
    score[4, 7] = 9.0
    score[11, 2] = 8.0
    score[15, 29] = 8.0
    assert A._pick(score, 30, 3, 0.25)[2]
    assert np.array_equal(A._pick(score, 30, 3, 0.25)[0], [4 * 30 + 7, 11 * 30 + 2, 15 * 30 + 29])
    off = score.copy()
    off[11, 2] = 8.3  # a candidate 0.3 off its integer
    assert not A._pick(off, 30, 3, 0.25)[2]
    for bad in (np.nan, np.inf, -np.inf):
        broken = score.copy()
        broken[17, 5] = bad  # not a candidate, but the pass cannot be trusted
        assert not A._pick(broken, 30, 3, 0.25)[2]
    best, counts, ok = A._pick(score, 8, 2, 0.25)  # the columns past n_j are ignored, not read as placements
    assert ok and np.array_equal(best, [4 * 8 + 7, 11 * 8 + 2]) and np.array_equal(counts, [9.0, 8.0])


def test_chosen_placements_are_pairwise_distinct_by_the_settings():
    """estimator.correlative.distinct_distance / distinct_angle_deg: every two chosen models
    differ by more than one of them; at the measured gap of the closest pair the pair
    is no longer distinct."""
    scene = build_scene("office", seed=0)
    points = _points(scene, 8, 0)
    kw = dict(cell=0.25, angle_step_deg=8.0, tolerance=0.3, peaks=10)
    models = C.correlative_models(scene.floorplan, points, **kw)
    centre = C.thin_to_grid(points, 0.25).mean(axis=0)
    assert len(models) == 10
    near = min(
        (float(np.hypot(*(Sim2(1.0, a[2], a[:2]).apply(centre) - Sim2(1.0, b[2], b[:2]).apply(centre)))), i, j)
        for i, a in enumerate(models) for j, b in enumerate(models) if i < j
        and abs(wrap_angle(a[2] - b[2])) <= np.deg2rad(10.0)
    )
    assert near[0] > 1.0
    closer = C.correlative_models(scene.floorplan, points, **kw, distinct_distance=near[0] * (1 + 1e-6))
    assert not np.array_equal(closer, models)  # that pair is one placement now
    lone = C.correlative_models(scene.floorplan, points, **kw, distinct_distance=1e3, distinct_angle_deg=180.0)
    assert len(lone) == 1 and np.array_equal(lone[0], models[0])
