"""The line-circle (LC) solver (paper 3.2): one BEV line and one circle centre <->
a floorplan line and centre give the Sim(2): the rotation from the line (R n = m, or
R n = -m where that makes the scale positive), the scale from the centre's signed
distance to its line, the translation from the centre."""

from __future__ import annotations

import numpy as np

from ...settings.loading import ScaleMode, SolverSettings
from .models import MIN_BASELINE, as_batch, no_models, normal_angle, pack, quiet, radius_ok, rotate, scale_ok


@quiet
def solve_lc(
    bev_normal,
    bev_offset,
    bev_center,
    fp_normal,
    fp_offset,
    fp_center,
    settings: SolverSettings = SolverSettings(),
    scale_mode: ScaleMode = "free",
    bev_radius=None,
    fp_radius=None,
):
    """One line + one circle-centre correspondence -> models. normal (B, 2), offset (B,),
    center (B, 2). Rotation from the line; scale from the centre's signed distance to the
    line, s = (u.c' + sigma e) / (n.c + d); translation t = c' - s R c. At a fixed scale
    s = 1, and the scale the offsets imply must still lie within the bounds."""
    n, d, c = as_batch(bev_normal, (2,)), as_batch(bev_offset, ()), as_batch(bev_center, (2,))
    m, e, cp = as_batch(fp_normal, (2,)), as_batch(fp_offset, ()), as_batch(fp_center, (2,))
    B = len(n)
    if B == 0:
        return no_models()
    theta = normal_angle(m) - normal_angle(n)  # R n = m (first candidate)
    lever = np.einsum("ij,ij->i", n, c) + d  # signed distance of the BEV centre to its line
    ok = np.abs(lever) >= MIN_BASELINE
    implied = (np.einsum("ij,ij->i", m, cp) + e) / np.where(ok, lever, 1.0)
    flip = implied < 0  # the other candidate (R n = -m) makes the scale positive
    theta = np.where(flip, theta + np.pi, theta)
    implied = np.abs(implied)
    ok &= scale_ok(implied, settings)
    s = np.ones(B) if scale_mode == "fixed" else implied
    t = cp - s[:, None] * rotate(theta, c)
    ok &= radius_ok(bev_radius, fp_radius, s, settings)
    return pack(t[:, 0], t[:, 1], theta, s, ok, np.arange(B))
