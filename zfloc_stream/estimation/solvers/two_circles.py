"""The two-circle (2C) solver (paper 3.2): two BEV circle centres <-> floorplan circle
centres give the Sim(2): the scale from the ratio of the centre distances, the rotation
from the direction between the centres, the translation from the centroids."""

from __future__ import annotations

import numpy as np

from ...settings.loading import ScaleMode, SolverSettings
from .models import MIN_BASELINE, as_batch, no_models, normal_angle, pack, quiet, radius_ok, rotate, scale_ok


@quiet
def solve_2c(
    bev_centers,
    fp_centers,
    settings: SolverSettings = SolverSettings(),
    scale_mode: ScaleMode = "free",
    bev_radii=None,
    fp_radii=None,
):
    """Two circle-centre correspondences -> models. centers (B, 2, 2); optional radii
    (B, 2) prune pairs whose radius ratio disagrees with the scale. At a fixed scale s = 1,
    and the scale the distances imply must still lie within the bounds."""
    c, cp = as_batch(bev_centers, (2, 2)), as_batch(fp_centers, (2, 2))
    B = len(c)
    if B == 0:
        return no_models()
    v, vp = c[:, 1] - c[:, 0], cp[:, 1] - cp[:, 0]
    lv, lvp = np.linalg.norm(v, axis=1), np.linalg.norm(vp, axis=1)
    ok = (lv >= MIN_BASELINE) & (lvp > 0)
    implied = lvp / np.where(ok, lv, 1.0)
    ok &= scale_ok(implied, settings)
    s = np.ones(B) if scale_mode == "fixed" else implied
    theta = normal_angle(vp) - normal_angle(v)
    # centroid alignment: exact for noise-free data, least squares for noisy pairs
    t = cp.mean(axis=1) - s[:, None] * rotate(theta, c.mean(axis=1))
    ok &= radius_ok(None if bev_radii is None else as_batch(bev_radii, (2,)), None if fp_radii is None else as_batch(fp_radii, (2,)),
                    s[:, None], settings).all(axis=1)
    return pack(t[:, 0], t[:, 1], theta, s, ok, np.arange(B))
