"""The fast correlative search (float32 FFT, pruned transforms, ties resolved the reference
way) returns exactly what the plain per-angle float64 FFT + np.argpartition returns."""

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
        best, counts, boundary, tied, _ = fast
        assert np.array_equal(exact[best], counts)
        assert (exact > boundary).sum() == (counts > boundary).sum()  # nothing above the boundary missed
        if not tied:
            assert len(best) == 10 and (exact >= boundary).sum() == 10


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
