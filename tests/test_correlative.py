"""The fast correlative search (float32 FFT, pruned transforms) returns exactly what the
plain per-angle float64 FFT returns, ties spread evenly over the tied placements."""

import numpy as np
import pytest

from zfloc_stream.estimation import correlative as C
from zfloc_stream.sim import LaserSimSettings, build_scene, simulate_laser

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
        ref = C.correlative_models_reference(scene.floorplan, points, scale, **kw)
        assert fast.shape == ref.shape and np.array_equal(fast, ref)


def test_float32_counts_round_to_the_exact_counts_everywhere():
    scene = build_scene("office", seed=0)
    points = C.thin_to_grid(_points(scene, 15, 0), 0.25)
    local = points - points.mean(axis=0)
    half = int(np.ceil((np.linalg.norm(local, axis=1).max() + 0.25) / 0.25)) + 1
    side = 2 * half
    spectrum, shape, _ = C._mask_spectrum(scene.floorplan, 0.25, 0.3 + 0.125, half)
    n_i, n_j = shape[0] - side + 1, shape[1] - side + 1
    for theta in np.deg2rad([0.0, 37.0, 180.0, 271.0]):
        ij = C._angle_template(local, theta, 0.25, half)
        exact = C._exact_scores(spectrum, ij, n_i, n_j)
        fast = C._fast_peaks(spectrum, ij, side, n_i, n_j, 10)
        assert fast is not None
        best, counts, _ = fast
        assert np.array_equal(exact[best], counts) and len(best) == 10
        boundary = counts.min()
        assert (exact > boundary).sum() == (counts > boundary).sum()  # nothing above the boundary missed
        ties = np.flatnonzero(exact == boundary)
        picked = np.sort(best[counts == boundary])
        if len(ties) > len(picked):  # spread evenly over the tied placements, in index order
            spread = ties[np.round(np.linspace(0, len(ties) - 1, len(picked))).astype(int)]
            assert np.array_equal(picked, spread)


@pytest.mark.parametrize("H, W", [(64, 48), (63, 50)])
def test_a_templates_180_degree_turn_has_the_mirrored_transform(H, W):
    rng = np.random.default_rng(5)
    side = 20
    ij = rng.integers(0, side, size=(60, 2))
    turned = (side - 1) - ij
    direct = C._template_spectrum(turned, side, H, W)
    mirrored = C._mirrored_spectrum(C._template_spectrum(ij, side, H, W), C._mirror_phase(side, H, W))
    assert mirrored.shape == direct.shape
    assert np.abs(mirrored - direct).max() < 1e-3 * len(ij)
    # and it is not trivially so: the unturned template's transform is far from it
    assert np.abs(C._template_spectrum(ij, side, H, W) - direct).max() > 1.0


def _segments(angles_deg, length=3.0, spacing=2.0):
    """Parallel segments, one per angle, side by side (a LineSet)."""
    from zfloc_stream.geometry import LineSet
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
    assert np.array_equal(everything, C.correlative_models_reference(scene.floorplan, points, **kw))
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


# ---- the compiled path (estimator.kernels: numba) -------------------------------------


def _numba():
    pytest.importorskip("numba")
    from zfloc_stream.estimation import correlative_numba

    return correlative_numba


@pytest.mark.parametrize("scene_name,seed,n_frames", [("office", 0, 8), ("hall", 1, 10), ("symmetric", 2, 6)])
@pytest.mark.parametrize("cell,step,peaks", [(0.25, 4.0, 10), (0.1, 2.0, 8), (0.25, 7.0, 6)])
def test_numba_search_is_the_numpy_search_and_the_reference_bit_for_bit(scene_name, seed, n_frames, cell, step, peaks):
    """step 7: 360 / 7 is no whole number, so no angle has its 180-degree turn on the grid
    (no mirrored spectra); the other steps pair every angle with its turn."""
    _numba()
    scene = build_scene(scene_name, seed=seed)
    points = _points(scene, n_frames, seed)
    kw = dict(cell=cell, angle_step_deg=step, tolerance=0.3, peaks=peaks)
    for scale in (1.0, 0.93):
        compiled = C.correlative_models(scene.floorplan, points, scale, kernels="numba", **kw)
        assert len(compiled) > 0
        assert np.array_equal(compiled, C.correlative_models(scene.floorplan, points, scale, **kw))
        assert np.array_equal(compiled, C.correlative_models_reference(scene.floorplan, points, scale, **kw))


def test_numba_search_with_angle_masks_is_the_numpy_search():
    """Masks that keep an angle without its turn, a turn without its angle, both, or none."""
    _numba()
    scene = build_scene("symmetric", seed=2)
    points = _points(scene, 6, 2)
    kw = dict(cell=0.25, angle_step_deg=4.0, tolerance=0.3, peaks=10)
    rng = np.random.default_rng(0)
    masks = [np.zeros(90, dtype=bool), np.ones(90, dtype=bool)] + [rng.random(90) < p for p in (0.1, 0.3, 0.6)]
    masks[0][[3, 50]] = True  # 12 degrees without 192, 200 without 20
    for mask in masks:
        compiled = C.correlative_models(scene.floorplan, points, angles=mask, kernels="numba", **kw)
        assert np.array_equal(compiled, C.correlative_models(scene.floorplan, points, angles=mask, **kw))


def test_numba_search_falls_back_to_the_exact_pass(monkeypatch):
    """No float32 count vouched for (slack < 0): every angle takes the float64 pass, and
    the models are still the reference's; so is a map too small to prune, and too few points."""
    _numba()
    scene = build_scene("office", seed=0)
    points = _points(scene, 8, 0)
    kw = dict(cell=0.25, angle_step_deg=8.0, tolerance=0.3, peaks=10)
    ref = C.correlative_models_reference(scene.floorplan, points, **kw)
    calls = []
    exact = C._exact_peaks
    monkeypatch.setattr(C, "_exact_peaks", lambda *a: calls.append(1) or exact(*a))
    monkeypatch.setattr(C, "_ROUNDING_SLACK", -1.0)
    assert np.array_equal(C.correlative_models(scene.floorplan, points, kernels="numba", **kw), ref)
    assert len(calls) == 45  # every angle
    monkeypatch.undo()
    assert C.correlative_models(scene.floorplan, points[:2], kernels="numba", **kw).shape == (0, 4)
    # a small room and many peaks: fewer rows of placements than peaks, the exact pass
    from zfloc_stream.floorplan import Floorplan

    occupied = np.zeros((16, 16), dtype=bool)
    occupied[[0, -1], :] = occupied[:, [0, -1]] = True
    room = Floorplan.from_occupancy(occupied, 0.1, (0.0, 0.0))
    pts = np.array([[0.1, 0.1], [1.4, 0.1], [1.4, 1.4], [0.1, 1.4], [0.7, 0.1], [0.1, 0.8]])
    kw = dict(cell=0.25, angle_step_deg=30.0, tolerance=0.3, peaks=400)
    compiled = C.correlative_models(room, pts, kernels="numba", **kw)
    assert len(compiled) > 0 and np.array_equal(compiled, C.correlative_models_reference(room, pts, **kw))


def _tied_score(rng, n_i, width, n_j, levels, noise):
    """A float32 correlation-like score: small integer counts with many ties, plus noise."""
    score = rng.integers(0, levels, size=(n_i, width)).astype(np.float64)
    score[:, n_j:] = levels + 5  # columns past n_j are not placements: never picked
    return (score + rng.uniform(-noise, noise, size=score.shape)).astype(np.float32)


@pytest.mark.parametrize("seed", range(40))
def test_compiled_peak_picking_is_the_numpy_picking(seed):
    """Ties by the dozen at the boundary count (spread evenly), few candidates, one
    placement per row, a rounding check that passes or fails, per_angle 1 and many."""
    CN = _numba()
    rng = np.random.default_rng(seed)
    n_i, n_j = int(rng.integers(1, 60)), int(rng.integers(1, 70))
    width = n_j + int(rng.integers(0, 9))
    levels = int(rng.choice([2, 3, 8, 50]))
    noise = float(rng.choice([0.0, 1e-4, 0.2, 0.3]))
    score = _tied_score(rng, n_i, width, n_j, levels, noise)
    for per_angle in sorted({1, 2, 7, int(rng.integers(1, 40))}):
        if n_i < per_angle or n_i * n_j <= per_angle:
            continue  # the caller takes the exact pass
        want = C._pick_peaks(score[:, :n_j], per_angle)
        best, counts, ok = CN._pick(score, n_j, per_angle, C._ROUNDING_SLACK)
        assert ok == (want is not None)
        if ok:
            assert best.dtype == want[0].dtype and counts.dtype == want[1].dtype
            assert np.array_equal(best, want[0]) and np.array_equal(counts, want[1])


def test_compiled_peak_picking_spreads_ties_like_linspace():
    CN = _numba()
    for n_tied in (2, 3, 5, 17, 100, 1001):
        for per_angle in (1, 2, 3, 4, 9, 16):
            score = np.zeros((n_tied + 3, 1), np.float32)
            score[:3, 0] = 5.0  # three above the boundary
            score[3:, 0] = 2.0
            if per_angle > n_tied + 3 or per_angle <= 3:
                continue
            best, counts, ok = CN._pick(score, 1, per_angle, 0.25)
            want = C._pick_peaks(score, per_angle)
            assert ok and np.array_equal(best, want[0]) and np.array_equal(counts, want[1])
            spread = 3 + np.round(np.linspace(0, n_tied - 1, per_angle - 3)).astype(np.int64)
            assert np.array_equal(best, np.concatenate([[0, 1, 2], spread]))


def test_compiled_peak_picking_refuses_what_it_cannot_vouch_for():
    CN = _numba()
    score = np.zeros((20, 30), np.float32)
    score[4, 7] = 9.0
    score[11, 2] = 8.0
    score[15, 29] = 8.0
    assert CN._pick(score, 30, 3, 0.25)[2]
    assert np.array_equal(CN._pick(score, 30, 3, 0.25)[0], [4 * 30 + 7, 11 * 30 + 2, 15 * 30 + 29])
    off = score.copy()
    off[11, 2] = 8.3  # a candidate 0.3 off its integer
    assert not CN._pick(off, 30, 3, 0.25)[2] and C._pick_peaks(off, 3) is None
    for bad in (np.nan, np.inf, -np.inf):
        broken = score.copy()
        broken[17, 5] = bad  # not a candidate, but the pass cannot be trusted
        assert not CN._pick(broken, 30, 3, 0.25)[2]
    assert CN._pick(score, 30, 3, 0.25)[2]
    narrow = score[:, :8]  # the columns past n_j are ignored, not read as placements
    best, counts, ok = CN._pick(score, 8, 2, 0.25)
    want = C._pick_peaks(np.ascontiguousarray(narrow), 2)
    assert ok and np.array_equal(best, want[0]) and np.array_equal(counts, want[1])
