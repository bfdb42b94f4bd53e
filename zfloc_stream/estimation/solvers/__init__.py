"""Minimal solvers for the Sim(2) alignment x' = s R x + t (BEV -> floorplan), paper 3.2:
one module per solver, each with one plain signature from a batch of correspondences to
candidate models.

    three_lines.py  3L  solve_3l(bev_normals, bev_offsets, fp_normals, fp_offsets)
    two_lines.py    2L  solve_2l(..., scale_prior, rng)
    two_circles.py  2C  solve_2c(bev_centers, fp_centers)
    line_circle.py  LC  solve_lc(bev_normal, bev_offset, bev_center, fp_normal, fp_offset, fp_center)
    models.py       the model rows and the checks the solvers share
    scale_prior.py  the 2L scale noise

RANSAC draws its line samples with drawn_3l / drawn_2l (the draws of estimation/draws.py
solved a block at a time by the same compiled per-sample solve as solve_3l / solve_2l).

Every solver is a plain function from a BATCH of minimal samples (arrays with a leading
axis B) to a batch of models: an (M, 4) array of rows (tx, ty, theta, s) and an (M,) array
naming the sample each model came from. A sample may give zero, one or two models.
Degenerate samples (parallel lines, coincident centres, a centre on its line, a scale that
is non-positive, non-finite or outside [min_scale, max_scale]) give no model: never an
exception, never a NaN.

Lines are in normal form n.x + d = 0. Under the transform a BEV line (n, d) becomes
(R n, s d - (R n).t); a floorplan line (m, e) matches it up to the sign of its normal, so
with sigma = sign((R n).m) and u = sigma m (~ R n) every correspondence gives
    u.t = s d - sigma e.
Rotation comes from the first (anchor) line pair: R n_1 = m_1 or R n_1 = -m_1. For the
free-scale solvers the second candidate gives exactly the first transform with s and R
negated (the linear systems are odd in R), i.e. one of the two always has s < 0; solving
once and flipping (theta + pi, -s) when s < 0 is therefore the same as trying both and
discarding the negative one. With a known scale (2L, fixed mode) both candidates are
genuinely different transforms and both are returned.

Scale modes ("free" | "prior" | "fixed"):
  free   3L, 2C, LC estimate s (2L needs a prior: it is not used in this mode).
  prior  as free, plus 2L with s = prior + GGD noise.
  fixed  s = 1 exactly: 3L and 2L both reduce to one rigid two-line solver (the third
         line is not needed), 2C to a rigid two-point fit, LC to rotation from the line
         and translation from the centre. The scale the sample implies (distance ratio for
         2C, offset ratio for LC) must still be positive and inside [min_scale, max_scale],
         which rejects samples that cannot be metric-consistent.
"""

from .line_circle import solve_lc
from .models import MODEL_COLUMNS, no_models, normal_angle
from .scale_prior import sample_scale_noise, scale_prior_sigma
from .three_lines import drawn_3l, solve_3l
from .two_circles import solve_2c
from .two_lines import drawn_2l, solve_2l

__all__ = ["MODEL_COLUMNS", "drawn_2l", "drawn_3l", "no_models", "normal_angle", "sample_scale_noise", "scale_prior_sigma", "solve_2c",
           "solve_2l", "solve_3l", "solve_lc"]
