"""The bilinear lookup of a field sampled at cell centres (grid.py's convention), compiled.

One scalar implementation, called by every kernel that reads a field: Floorplan.distance
and Grid.bilinear (bilinear_lookup, over arrays), the full consistency score Cc
(estimation/scoring.py) and the LM refinement's residuals (estimation/field_fit.py, with
the gradient). Outside the hull of the cell centres a point reads the value at the nearest
point of the hull plus its distance to it, so a distance field stays a distance (finite,
growing outward).

Two forms of the interpolant, because the gradient's needs and bit-exact history differ
and the estimator's decisions depend on the last bits (a reordered product moves a refined
pose by an ulp and can flip a tie): bilinear_at weights the corners,
top * (1 - fv) + bottom * fv with top = f00 (1 - fu) + f01 fu (the scores and
Floorplan.distance); bilinear_and_gradient_at takes differences, bottom + (top - bottom) fv
with bottom = f00 + (f01 - f00) fu, which shares (f01 - f00) and (top - bottom) with the
gradient (the LM, and the laser scan matcher's residuals). Both are exact at the cell
centres and agree to a few ulps elsewhere; each caller keeps the form it has always had.

Compiled without fastmath (runtime/numba_support.py): element-wise, each is numpy's
arithmetic on the same expressions, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from ..runtime.numba_support import njit


@njit
def centre_coordinates(x, y, ox, oy, res):
    """(u, v): a metric point in cell units from the centre of cell (0, 0)."""
    return (x - ox) / res - 0.5, (y - oy) / res - 0.5


@njit
def _clamped(u, top):
    """np.clip(u, 0, top) for a non-NaN u."""
    return min(max(u, 0.0), top)


@njit
def bilinear_at(field, h, w, res, u, v):
    """The field (raveled, h rows of w cells) at cell coordinates (u, v) (centre_coordinates;
    not NaN): corner weights, plus the distance to the grid outside it."""
    uc = _clamped(u, w - 1.0)
    vc = _clamped(v, h - 1.0)
    c0 = min(np.int64(uc), w - 2)  # truncation of a non-negative value, as astype(int64)
    r0 = min(np.int64(vc), h - 2)
    fu = uc - c0
    fv = vc - r0
    k = r0 * w + c0
    top = field[k] * (1.0 - fu) + field[k + 1] * fu
    bottom = field[k + w] * (1.0 - fu) + field[k + w + 1] * fu
    value = top * (1.0 - fv) + bottom * fv
    # outside the grid: plus the distance to it. Inside, numpy's version adds
    # hypot(0, 0) * res = +0.0, which leaves a value >= 0 as it is: the call is skipped
    if u != uc or v != vc:
        value = value + math.hypot(u - uc, v - vc) * res
    return value


@njit
def bilinear_and_gradient_at(field, h, w, res, u, v):
    """(value, d/dx, d/dy) of the field at cell coordinates (u, v) (not NaN), in the
    difference form; the gradient is the interpolant's in metres (outside the grid the
    component across the edge is 0: the distance-to-the-grid term is left out). A float32
    field's differences stay float32, as numpy's would."""
    uc = _clamped(u, w - 1.0)
    vc = _clamped(v, h - 1.0)
    c0 = min(np.int64(uc), w - 2)
    r0 = min(np.int64(vc), h - 2)
    fu = uc - c0
    fv = vc - r0
    i = r0 * w + c0
    f00 = field[i]
    f01 = field[i + 1]
    f10 = field[i + w]
    f11 = field[i + w + 1]
    bottom = f00 + (f01 - f00) * fu
    top = f10 + (f11 - f10) * fu
    value = bottom + (top - bottom) * fv
    # the distance to the grid (hypot(0, 0) * res = +0.0 inside it; the libm call is skipped)
    value += math.hypot(u - uc, v - vc) * res if u != uc or v != vc else 0.0
    gu = (f01 - f00) + (f11 - f10 - f01 + f00) * fv
    gv = top - bottom
    return value, (gu if u == uc else 0.0) / res, (gv if v == vc else 0.0) / res


@njit
def bilinear_lookup(field, h, w, ox, oy, res, px, py, out):
    """out[k] = bilinear_at of the metric point (px[k], py[k]) (finite points)."""
    for k in range(px.shape[0]):
        u, v = centre_coordinates(px[k], py[k], ox, oy, res)
        out[k] = bilinear_at(field, h, w, res, u, v)


@njit
def bilinear_and_gradient_lookup(field, h, w, ox, oy, res, px, py, value, gx, gy):
    """bilinear_and_gradient_at of every metric point (px[k], py[k]) into value, gx, gy;
    a NaN point reads NaN (value and gradient)."""
    for k in range(px.shape[0]):
        u, v = centre_coordinates(px[k], py[k], ox, oy, res)
        if u != u or v != v:
            value[k] = gx[k] = gy[k] = np.nan
            continue
        value[k], gx[k], gy[k] = bilinear_and_gradient_at(field, h, w, res, u, v)
