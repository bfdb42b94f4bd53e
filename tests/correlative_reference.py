"""The correlative search the plain way, for the tests only: one float64 FFT per angle,
every placement counted (zfloc_stream/estimation/angle_search.py's exact pass on every
angle), then correlative.py's selection. correlative_models must return exactly this."""

import numpy as np

from zfloc_stream.estimation import angle_search as A
from zfloc_stream.estimation import correlative as C
from zfloc_stream.geometry.sim2 import wrap_angle


def correlative_models_reference(
    floorplan,
    points: np.ndarray,
    scale: float = 1.0,
    *,
    cell: float = 0.1,
    angle_step_deg: float = 2.0,
    tolerance: float = 0.15,
    peaks: int = 8,
    distinct_distance: float = 1.0,
    distinct_angle_deg: float = 10.0,
) -> np.ndarray:
    """correlative_models the plain way (one float64 FFT per angle, every placement counted):
    what the fast version must reproduce exactly (test_correlative.py)."""
    frame = C.search_frame(floorplan, points, scale, cell, tolerance)  # the points and mask, as the fast search's
    if frame is None:
        return np.zeros((0, 4))
    centre, local, half, spectrum, mask_origin, n_i, n_j = frame
    per_angle = max(1, peaks)
    thetas_grid = np.deg2rad(np.arange(0.0, 360.0, angle_step_deg))
    found = [A._exact_peaks(spectrum, A._angle_template(local, th, cell, half), n_i, n_j, per_angle) for th in thetas_grid]
    (t, thetas), _ = C._select(found, thetas_grid, centre, mask_origin, half, cell, n_j, peaks, distinct_distance, distinct_angle_deg)
    return np.column_stack([t, wrap_angle(thetas), np.full(len(thetas), float(scale))])
