"""Model generation for a round (paper 3.2-3.3): minimal samples drawn per solver (3L, 2L,
LC, 2C) against the pruned floorplan tuples, solved in batches; the correlative seeds
(exhaustive SE(2) search at a known or prior scale) and the models guided by a tracked
mode. Each returns (K, 4) model rows (tx, ty, theta, s)."""

from __future__ import annotations

import numpy as np

from dataclasses import field

from ..settings.loading import EstimatorSettings
from .field_fit import refine_batch
from ..geometry.shapes import LineSet
from ..observation import BevObservation
from ..geometry.sim2 import Sim2, wrap_angle
from .correlative import DIRECTION_RATIO, correlative_models, plausible_angles
from .correspondences import BevSamples, FloorplanMatches, line_angles, probabilities
from .draws import draw
from .scoring import floorplan_scorer
from .solvers import drawn_2l, drawn_3l, solve_2c, solve_2l, solve_3l, solve_lc
from .views import implied_poses


def _relative(alpha: np.ndarray, rows: np.ndarray) -> np.ndarray:
    return np.mod(alpha[rows[:, 1:]] - alpha[rows[:, :1]], np.pi)


def models_3l(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng):
    picks = bev.triplets[rng.choice(len(bev.triplets), size=n, p=bev.triplet_p)]
    starts, sizes = fp.triplets.ranges(_relative(bev.alpha, picks))
    if cfg.scale_mode == "fixed":
        # at a fixed scale the third line adds nothing: the rigid two-line solve of the
        # anchor and the second line (solve_3l's fixed mode), drawn and solved compiled
        return drawn_2l(starts, sizes, cfg.ransac.match_fraction, rng, picks[:, :2], fp.triplet_heads, bev.lines, fp.lines,
                        line_angles(bev.lines), fp.line_angles, 1.0, cfg.solvers, "fixed")[0]
    # draw and solve in one compiled loop
    return drawn_3l(starts, sizes, cfg.ransac.match_fraction, rng, picks, fp.triplets.rows, bev.lines, fp.lines,
                    line_angles(bev.lines), fp.line_angles, cfg.solvers)[0]


def models_2l(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng, scale_prior: float):
    picks = bev.pairs[rng.choice(len(bev.pairs), size=n, p=bev.pair_p)]
    starts, sizes = fp.pairs.ranges(_relative(bev.alpha, picks))
    mode = "fixed" if cfg.scale_mode == "fixed" else "prior"
    # draw and solve in one compiled loop (the draws' random numbers, then the scale noise)
    return drawn_2l(starts, sizes, cfg.ransac.match_fraction, rng, picks, fp.pairs.rows, bev.lines, fp.lines,
                    line_angles(bev.lines), fp.line_angles, scale_prior, cfg.solvers, mode)[0]


def models_lc(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng):
    picks = bev.line_circle[rng.choice(len(bev.line_circle), size=n, p=bev.line_circle_p)]
    starts = np.zeros((n, 1), dtype=np.int64)
    sizes = np.full((n, 1), len(fp.line_circle), dtype=np.int64)
    q, row = draw(starts, sizes, cfg.ransac.match_fraction, rng)
    b, f = picks[q], fp.line_circle[row]
    return solve_lc(
        bev.lines.normals[b[:, 0]],
        bev.lines.offsets[b[:, 0]],
        bev.circles.centers[b[:, 1]],
        fp.lines.normals[f[:, 0]],
        fp.lines.offsets[f[:, 0]],
        fp.circles.centers[f[:, 1]],
        cfg.solvers,
        cfg.scale_mode,
        bev.circles.radii[b[:, 1]],
        fp.circles.radii[f[:, 1]],
    )[0]


def models_2c(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng):
    pick = rng.integers(len(bev.circle_pairs), size=n)
    picks, dist = bev.circle_pairs[pick], bev.circle_dist[pick]
    lo = np.searchsorted(fp.circle_dist, cfg.solvers.min_scale * dist, side="left")
    hi = np.searchsorted(fp.circle_dist, cfg.solvers.max_scale * dist, side="right")
    q, row = draw(lo[:, None], (hi - lo)[:, None], cfg.ransac.match_fraction, rng)
    b, f = picks[q], fp.circle_pairs[row]
    return solve_2c(
        bev.circles.centers[b], fp.circles.centers[f], cfg.solvers, cfg.scale_mode, bev.circles.radii[b], fp.circles.radii[f]
    )[0]


def solver_pool(cfg: EstimatorSettings, bev: BevSamples, fp: FloorplanMatches) -> list[str]:
    """Enabled solvers after the scale-mode reduction and the primitive availability check
    (order follows settings.solvers.pool, duplicates removed)."""
    wanted: list[str] = []
    for name in cfg.solvers.pool:
        if cfg.scale_mode == "free" and name == "2L":
            continue  # 2L needs a metric prior
        if cfg.scale_mode == "fixed" and name == "3L":
            name = "2L"  # rigid: two lines suffice
        if name not in wanted:
            wanted.append(name)
    available = {
        "3L": len(bev.triplets) > 0 and len(fp.triplets.rows) > 0,
        "2L": len(bev.pairs) > 0 and len(fp.pairs.rows) > 0,
        "LC": len(bev.line_circle) > 0 and len(fp.line_circle) > 0,
        "2C": len(bev.circle_pairs) > 0 and len(fp.circle_pairs) > 0,
    }
    return [name for name in wanted if available[name]]


# --------------------------------------------------------------------------------------
# localize
# --------------------------------------------------------------------------------------


def correlative_seeds(floorplan, obs: BevObservation, cfg: EstimatorSettings, scale_prior: float,
                      across_prior: bool = False) -> np.ndarray:
    """Exhaustive grid placements at the prior (or fixed) scale, LM-refined on the
    wall-face field so they enter the ranking as sharp as the refined RANSAC models.

    across_prior: at a scale prior, search at correlative.scales scales spread over the
    prior's range (cfg.solvers' bounds, as localize narrowed them) instead: a round that
    follows no mode has no evidence of the scale yet."""
    c = cfg.correlative
    if cfg.scale_mode == "fixed":
        scales = [1.0]
    elif across_prior and c.scales > 1:  # the range's end points stay out: their neighbours cover them
        scales = np.geomspace(cfg.solvers.min_scale, cfg.solvers.max_scale, c.scales + 2)[1:-1]
    else:
        scales = [scale_prior]
    angles = plausible_angles(obs.lines, floorplan.lines, c.angle_step_deg, DIRECTION_RATIO)
    models = np.concatenate([correlative_models(
        floorplan, obs.wall_points, float(scale), cell=c.cell, angle_step_deg=c.angle_step_deg, tolerance=c.tolerance,
        peaks=c.peaks, angles=angles, distinct_distance=c.distinct_distance, distinct_angle_deg=c.distinct_angle_deg,
    ) for scale in scales])
    if len(models) == 0:
        return np.zeros((0, 4))
    field = floorplan_scorer(floorplan, cfg.scoring).face_field
    return refine_batch(field, obs.wall_points, models, cfg.refine, cfg.scale_mode, (cfg.solvers.min_scale, cfg.solvers.max_scale))


def _guided_candidates(lines: LineSet, fp_lines: LineSet, warm: Sim2, cfg) -> tuple[np.ndarray, np.ndarray]:
    """For each BEV line, the floorplan lines it lies on under the warm alignment (angle
    within guided_angle_deg, both ends within guided_distance of the line), as CSR
    (starts (N + 1,), indices). Collinear floorplan walls are equivalent constraints."""
    ends = warm.apply(lines.endpoints.reshape(-1, 2)).reshape(-1, 2, 2)
    direction = ends[:, 1] - ends[:, 0]
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    aligned = np.abs(direction @ fp_lines.normals.T) < np.sin(np.deg2rad(cfg.guided_angle_deg))
    offset = np.abs(np.einsum("nkd,md->nkm", ends, fp_lines.normals) + fp_lines.offsets[None, None, :]).max(axis=1)  # n.x + d = 0
    rows, cols = np.nonzero(aligned & (offset < cfg.guided_distance))
    starts = np.searchsorted(rows, np.arange(len(lines) + 1))
    return starts, cols


def guided_models(bev: BevSamples, fp: FloorplanMatches, warm: Sim2, n: int, cfg: EstimatorSettings, rng, scale_prior: float) -> np.ndarray:
    """Minimal samples near a live mode: BEV line pairs (triplets in free scale) matched
    only to the floorplan lines they lie on under its alignment, so nearly every model is
    a small correction of the mode (drift, a better fit) instead of a global guess. Among
    thousands of floorplan lines a global sample rarely meets these few matches."""
    r = cfg.ransac
    free = cfg.scale_mode == "free"
    samples, weights = (bev.triplets, bev.triplet_p) if free else (bev.pairs, bev.pair_p)
    if n <= 0 or not len(samples):
        return np.zeros((0, 4))
    starts, cols = _guided_candidates(bev.lines, fp.lines, warm, r)
    counts = np.diff(starts)
    usable = (counts[samples] > 0).all(axis=1)
    if not usable.any():
        return np.zeros((0, 4))
    samples = samples[usable]
    p = None if weights is None else probabilities(weights[usable])
    picks = samples[rng.choice(len(samples), size=n, p=p)]
    f = cols[starts[picks] + np.floor(rng.random(picks.shape) * counts[picks]).astype(np.int64)]
    if free:
        models = solve_3l(bev.lines.normals[picks], bev.lines.offsets[picks], fp.lines.normals[f], fp.lines.offsets[f], cfg.solvers, "free")[0]
    else:
        mode = "fixed" if cfg.scale_mode == "fixed" else "prior"
        models = solve_2l(bev.lines.normals[picks], bev.lines.offsets[picks], fp.lines.normals[f], fp.lines.offsets[f],
                          scale_prior, rng, cfg.solvers, mode)[0]
    if not len(models):
        return models
    # the solvers also return the mirrored rotation of each sample: keep what is near the mode
    anchor = bev.lines.endpoints.reshape(-1, 2).mean(axis=0)  # compare where the BEV lands, not the raw translation
    landed, heading = implied_poses(models, anchor)
    shift = np.linalg.norm(landed - warm.apply(anchor), axis=1)
    near = (np.abs(wrap_angle(heading - warm.theta)) < np.deg2rad(2 * r.guided_angle_deg)) & (shift < r.guided_shift)
    return models[near]
