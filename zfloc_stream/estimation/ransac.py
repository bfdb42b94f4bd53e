"""Hybrid RANSAC over the four minimal solvers (paper 3.2-3.4) -> ranked distinct hypotheses.

One iteration = one minimal sample of BEV primitives for a solver chosen at random from
the enabled pool. Without descriptors the floorplan side of a correspondence has to be
enumerated (paper 3.2, "correspondences must be enumerated exhaustively"); the pruning
makes that affordable and this module does it with lookup tables built once per floorplan:

  (i)   lines are deduplicated (floorplan: by Floorplan.lines; BEV: here);
  (ii)  floorplan triplets / pairs are a line and its spatial neighbours
        (Floorplan.line_neighbours), BEV samples likewise (same distance, divided by the
        scale prior); all-parallel triplets and parallel pairs are never sampled;
  (iii) normal consistency: floorplan tuples are binned by the angles of their lines
        relative to the anchor line, so the tuples whose normals can agree with a BEV
        sample (|cos| > tau_p once the anchor fixes the rotation) are a handful of
        contiguous index ranges; the exact test runs in the solver before solving.

Each BEV sample then meets ceil(match_fraction x n) floorplan tuples drawn uniformly from
its n pruned candidates (all of them for match_fraction >= 1). Drawing a fraction instead
of all keeps the cost of one iteration proportional to the floorplan's ambiguity while the
probability that the true correspondence is tried somewhere in the run stays
1 - exp(-iterations_per_solver * match_fraction * P(good BEV sample)), independent of the
floorplan's size. Everything is drawn vectorised and grouped by solver.

Circle samples: 2C pairs floorplan centre pairs whose distance ratio lies in
[min_scale, max_scale]; LC pairs a line with a circle within the neighbour distance.

Scale modes reduce the pool (see solvers.py): free -> 3L, 2C, LC; prior -> all four;
fixed -> one rigid two-line solver (labelled "2L", standing in for both 3L and 2L), 2C, LC.
Solvers whose primitives are missing (no circles -> no 2C / LC) are dropped.

Scoring is coarse to fine (scoring.py); the top refine.top_n distinct hypotheses are
refined (refine.py), rescored with the full C and the list re-ranked and de-duplicated.

Input: a BEV with neither lines nor circles is an InputError. A BEV whose primitives
suit no enabled solver (e.g. two lines at free scale) is not an error: the result simply
holds no hypothesis (besides re-scored warm starts), as early in a stream.
"""

from __future__ import annotations

import time
import warnings
import weakref
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from .. import threads
from ..config import EstimatorSettings, FloorplanSettings, LineSettings, Settings, SolverSettings
from ..errors import InputError
from ..geometry import CircleSet, LineSet
from ..observation import BevObservation
from ..primitives import deduplicate_lines
from ..sim2 import Sim2, wrap_angle
from .correlative import correlative_models, plausible_angles
from ..ties import descending, tie_keys
from ..field_fit import refine_batch
from .scoring import distinct, floorplan_scorer, rank_coarse_to_fine, score_hypotheses, sparse_line_points
from .views import BevView, implied_poses
from .draws import admissible_triplets, draw
from .solvers import drawn_2l, drawn_3l, normal_angle, solve_2c, solve_2l, solve_3l, solve_lc

WARM = "warm"
CORRELATIVE = "correlative"
GUIDED = "guided"


@dataclass(frozen=True)
class Hypothesis:
    alignment: Sim2  # BEV / odometry plane -> floorplan
    score: float  # C = Cc - Cv
    cc: float
    cv: float
    solver: str  # "3L", "2L", "2C", "LC", "guided", "correlative" or "warm"


@dataclass(frozen=True)
class LocalizationResult:
    hypotheses: list[Hypothesis]  # best first, pairwise distinct
    timings: dict[str, float] = field(default_factory=dict)  # seconds: model_estimation, scoring, refinement
    n_models: int = 0  # models generated (solver outputs + warm starts) before scoring
    cpu_timings: dict[str, float] = field(default_factory=dict)  # the same stages in CPU seconds of the calling thread

    @property
    def best(self) -> Hypothesis | None:
        return self.hypotheses[0] if self.hypotheses else None


# --------------------------------------------------------------------------------------
# small geometry helpers
# --------------------------------------------------------------------------------------


def model_rows(alignments: Sequence[Sim2]) -> np.ndarray:
    """(K, 4) model rows (tx, ty, theta, s), the layout solvers, scoring and LM work on."""
    return np.array([[a.t[0], a.t[1], a.theta, a.s] for a in alignments], dtype=float).reshape(-1, 4)


def alignment_of(model: np.ndarray) -> Sim2:
    """The Sim2 of one model row (tx, ty, theta, s)."""
    return Sim2(model[3], model[2], (model[0], model[1]))


def _normal_angles(lines: LineSet) -> np.ndarray:
    """Line orientation as the angle of its normal modulo pi (a line has no direction)."""
    return np.mod(np.arctan2(lines.normals[:, 1], lines.normals[:, 0]), np.pi)


def _parallel_mod_pi(a: np.ndarray, b: np.ndarray, max_angle: float) -> np.ndarray:
    return np.abs(np.sin(a - b)) < np.sin(max_angle)


def _point_segment_distance(p: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(P, S) distance from points (P, 2) to segments (S, 2, 2)."""
    a, b = ends[None, :, 0], ends[None, :, 1]
    d = b - a
    t = np.clip(np.sum((p[:, None] - a) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-18), 0.0, 1.0)
    return np.linalg.norm(p[:, None] - (a + t[..., None] * d), axis=-1)


def _segment_distance_matrix(ends: np.ndarray) -> np.ndarray:
    """(S, S) distance between segments (S, 2, 2): the smallest endpoint-to-segment
    distance, or 0 where two segments cross."""
    to_seg = _point_segment_distance(ends.reshape(-1, 2), ends).reshape(len(ends), 2, len(ends))
    d = to_seg.min(axis=1)  # d[i, j]: closest endpoint of i to segment j
    d = np.minimum(d, d.T)
    a, b = ends[:, None, 0], ends[:, None, 1]
    c, e = ends[None, :, 0], ends[None, :, 1]

    def side(p, q, r):  # sign of the turn p -> q -> r
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    crossing = (side(a, b, c) * side(a, b, e) < 0) & (side(c, e, a) * side(c, e, b) < 0)
    return np.where(crossing, 0.0, d)


def _neighbour_lists(lines: LineSet, distance: float) -> list[np.ndarray]:
    if len(lines) == 0:
        return []
    near = _segment_distance_matrix(lines.endpoints) < distance
    np.fill_diagonal(near, False)
    return [np.flatnonzero(row) for row in near]


def _nearest_neighbours(lines: LineSet, neighbours: Sequence[np.ndarray], max_rows: int) -> tuple[list[np.ndarray], int | None]:
    """Neighbour lists thinned so that their ordered triplets (sum of k (k - 1)) fit in
    max_rows: each line keeps its K nearest neighbours (segment distance, ties by index),
    K the largest that fits. A cluttered map (noise, a badly thresholded scan) has hundreds
    of short lines within the neighbour distance of each other, and its triplet table
    grows with the cube of its clutter. Returns (lists, K), K None when nothing was cut."""
    k = np.array([len(nb) for nb in neighbours], dtype=np.int64)
    if int((k * (k - 1)).sum()) <= max_rows:
        return list(neighbours), None
    lo, hi = 1, int(k.max())  # largest K with sum min(k, K) (min(k, K) - 1) <= max_rows
    while lo < hi:
        mid = (lo + hi + 1) // 2
        c = np.minimum(k, mid)
        lo, hi = (mid, hi) if int((c * (c - 1)).sum()) <= max_rows else (lo, mid - 1)
    ends = lines.endpoints
    out = []
    for i, nb in enumerate(neighbours):
        if len(nb) <= lo:
            out.append(nb)
            continue
        d = np.minimum(_point_segment_distance(ends[nb].reshape(-1, 2), ends[i : i + 1]).reshape(-1, 2).min(axis=1),
                       _point_segment_distance(ends[i], ends[nb]).min(axis=0))
        out.append(np.sort(nb[np.lexsort((nb, np.round(d, 9)))[:lo]]))
    return out, lo


def _ordered_pairs(neighbours: Sequence[np.ndarray]) -> np.ndarray:
    """(P, 2) rows (i, j): j a neighbour of i."""
    if not neighbours:
        return np.zeros((0, 2), dtype=np.int64)
    i = np.repeat(np.arange(len(neighbours)), [len(nb) for nb in neighbours])
    j = np.concatenate([np.asarray(nb, dtype=np.int64) for nb in neighbours]) if len(i) else np.zeros(0, dtype=np.int64)
    return np.stack([i, j], axis=1).astype(np.int64)


def _line_circle_pairs(lines: LineSet, circles: CircleSet, distance: float, min_lever: float) -> np.ndarray:
    """(P, 2) rows (line, circle): centre within `distance` of the segment and at least
    min_lever from the infinite line (the LC scale is the ratio of these levers)."""
    if len(lines) == 0 or len(circles) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    near = _point_segment_distance(circles.centers, lines.endpoints) < distance  # (C, L)
    lever = np.abs(circles.centers @ lines.normals.T + lines.offsets[None, :])
    c, li = np.nonzero(near & (lever >= min_lever))
    order = np.lexsort((c, li))
    return np.stack([li[order], c[order]], axis=1).astype(np.int64)


def _circle_pairs(circles: CircleSet, min_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """Ordered pairs (k, l), k != l, centres at least min_distance apart; and distances."""
    n = len(circles)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
    k, l = np.nonzero(~np.eye(n, dtype=bool))
    dist = np.linalg.norm(circles.centers[l] - circles.centers[k], axis=1)
    keep = dist >= min_distance
    return np.stack([k[keep], l[keep]], axis=1).astype(np.int64), dist[keep]


# --------------------------------------------------------------------------------------
# normal-consistency lookup
# --------------------------------------------------------------------------------------


class _AngleTable:
    """Floorplan tuples binned by the angles (mod pi) of their lines relative to the
    anchor line. A query returns the index ranges of the bins that can hold tuples within
    `tolerance` of the query angles: a superset of the normal-consistent tuples."""

    def __init__(self, rows: np.ndarray, relative: np.ndarray, tolerance: float):
        self.q = relative.shape[1]
        self.tolerance = tolerance
        nb = int(np.floor(np.pi / tolerance)) if tolerance > 0 else 1
        # bins at least `tolerance` wide, and >= 3 of them so a query's bins are distinct
        self.n_bins = nb if nb >= 3 else 1
        self.width = np.pi / self.n_bins
        key = self._key(np.floor(np.mod(relative, np.pi) / self.width).astype(np.int64) % self.n_bins)
        order = np.argsort(key, kind="stable")
        self.rows = rows[order]
        counts = np.bincount(key, minlength=self.n_bins**self.q)
        self.counts = counts
        self.start = np.cumsum(counts) - counts

    def _key(self, bins: np.ndarray) -> np.ndarray:
        key = np.zeros(bins.shape[:-1], dtype=np.int64)
        for j in range(self.q):
            key = key * self.n_bins + bins[..., j]
        return key

    def ranges(self, query: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(starts, sizes), each (B, R), for query angles (B, q)."""
        B = len(query)
        spread = 3 if self.n_bins >= 3 else 1
        per_dim_bins, per_dim_valid = [], []
        for j in range(self.q):
            if spread == 1:
                per_dim_bins.append(np.zeros((B, 1), dtype=np.int64))
                per_dim_valid.append(np.ones((B, 1), dtype=bool))
                continue
            lo = np.floor((query[:, j] - self.tolerance) / self.width).astype(np.int64)
            hi = np.floor((query[:, j] + self.tolerance) / self.width).astype(np.int64)
            offs = lo[:, None] + np.arange(3)[None, :]
            per_dim_bins.append(offs % self.n_bins)
            per_dim_valid.append(offs <= hi[:, None])
        # all combinations of per-dimension bins
        grids = np.meshgrid(*[np.arange(spread)] * self.q, indexing="ij")
        combos = np.stack([g.ravel() for g in grids], axis=1)  # (R, q)
        bins = np.stack([per_dim_bins[j][:, combos[:, j]] for j in range(self.q)], axis=-1)  # (B, R, q)
        valid = np.ones((B, len(combos)), dtype=bool)
        for j in range(self.q):
            valid &= per_dim_valid[j][:, combos[:, j]]
        key = self._key(bins)
        return self.start[key], np.where(valid, self.counts[key], 0)


# --------------------------------------------------------------------------------------
# floorplan tables (built once per floorplan object and settings)
# --------------------------------------------------------------------------------------


def _settings_of(floorplan) -> Settings:
    cfg = getattr(floorplan, "settings", None)
    return cfg if isinstance(cfg, Settings) else Settings()


class FloorplanMatches:
    """Pruned floorplan tuples for every solver."""

    def __init__(self, floorplan, solvers: SolverSettings):
        fp_cfg: FloorplanSettings = _settings_of(floorplan).floorplan
        self.lines: LineSet = floorplan.lines
        self.circles: CircleSet = floorplan.circles
        self.line_angles = _line_angles(self.lines)  # for solve_3l_indexed
        tol = float(np.arccos(np.clip(solvers.normal_consistency, -1.0, 1.0)))
        par = np.deg2rad(solvers.parallel_angle_deg)
        alpha = _normal_angles(self.lines)
        neighbours = [np.asarray(nb, dtype=np.int64) for nb in floorplan.line_neighbours] if len(self.lines) else []
        # 3L: a line, two of its neighbours, not all parallel (a bounded table: _nearest_neighbours)
        near, kept = _nearest_neighbours(self.lines, neighbours, fp_cfg.max_triplets)
        if kept is not None:
            warnings.warn(f"floorplan {getattr(floorplan, 'name', '')!r}: its {len(self.lines)} lines have more line triplets than "
                          f"floorplan.max_triplets ({fp_cfg.max_triplets:,}; a cluttered map, or a dense plan): each line's triplets "
                          f"use its {kept} nearest neighbours only (raise floorplan.max_triplets to keep all)", stacklevel=3)
        tri = admissible_triplets(near, alpha, par, self.lines.lengths)[0]
        self.triplets = _AngleTable(tri, (alpha[tri[:, 1:]] - alpha[tri[:, :1]]) if len(tri) else np.zeros((0, 2)), tol)
        # the triplets' first two lines, for the two-line solve at a fixed scale
        self.triplet_heads = np.ascontiguousarray(self.triplets.rows[:, :2], dtype=np.int64)
        # 2L: a line and a non-parallel neighbour
        pairs = _ordered_pairs(neighbours)
        if len(pairs):
            pairs = pairs[~_parallel_mod_pi(alpha[pairs[:, 0]], alpha[pairs[:, 1]], par)]
        self.pairs = _AngleTable(pairs, (alpha[pairs[:, 1:]] - alpha[pairs[:, :1]]) if len(pairs) else np.zeros((0, 1)), tol)
        # LC: a line and a nearby circle off the line (floorplan units: lever * min_scale)
        self.line_circle = _line_circle_pairs(self.lines, self.circles, fp_cfg.neighbour_distance, solvers.min_baseline * solvers.min_scale)
        # 2C: circle pairs sorted by centre distance (scale window -> one contiguous range)
        cpairs, dist = _circle_pairs(self.circles, solvers.min_baseline * solvers.min_scale)
        order = np.argsort(dist, kind="stable")
        self.circle_pairs, self.circle_dist = cpairs[order], dist[order]


_MATCHES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def floorplan_matches(floorplan, solvers: SolverSettings) -> FloorplanMatches:
    key = (solvers.normal_consistency, solvers.parallel_angle_deg, solvers.min_baseline, solvers.min_scale)
    try:
        cached = _MATCHES.get(floorplan)
    except TypeError:
        return FloorplanMatches(floorplan, solvers)
    if cached is not None and cached[0] == key:
        return cached[1]
    matches = FloorplanMatches(floorplan, solvers)
    try:
        _MATCHES[floorplan] = (key, matches)
    except TypeError:
        pass
    return matches


# --------------------------------------------------------------------------------------
# BEV samples
# --------------------------------------------------------------------------------------


class BevSamples:
    """Every admissible minimal sample of BEV primitives, per solver."""

    def __init__(self, obs: BevObservation, line_settings: LineSettings, solvers: SolverSettings, neighbour_distance: float):
        self.lines = deduplicate_lines(obs.lines, line_settings) if len(obs.lines) else obs.lines
        self.circles = obs.circles
        par = np.deg2rad(solvers.parallel_angle_deg)
        alpha = _normal_angles(self.lines)
        self.alpha = alpha
        # BEV segments are observed parts of floorplan walls, so two BEV lines can be
        # farther apart than their floorplan counterparts: when no admissible sample exists
        # within the neighbour distance, the restriction is lifted rather than giving up.
        def everyone():  # every other line, per line: built only when the fallback is taken
            return [np.delete(np.arange(len(self.lines)), i) for i in range(len(self.lines))]

        lengths = self.lines.lengths

        def triplets(nb):
            """The admissible triplets and their sampling weights (the shortest line's length)."""
            return admissible_triplets(nb, alpha, par, lengths)

        def pairs_of(nb):
            pairs = _ordered_pairs(nb)
            if len(pairs):
                pairs = pairs[~_parallel_mod_pi(alpha[pairs[:, 0]], alpha[pairs[:, 1]], par)]
            return pairs

        neighbours = _neighbour_lists(self.lines, neighbour_distance)
        self.triplets, triplet_weights = triplets(neighbours)
        if not len(self.triplets):
            self.triplets, triplet_weights = triplets(everyone())
        pairs = pairs_of(neighbours)
        self.pairs = pairs if len(pairs) else pairs_of(everyone())
        self.line_circle = _line_circle_pairs(self.lines, self.circles, neighbour_distance, solvers.min_baseline)
        if not len(self.line_circle):
            self.line_circle = _line_circle_pairs(self.lines, self.circles, np.inf, solvers.min_baseline)
        self.circle_pairs, self.circle_dist = _circle_pairs(self.circles, solvers.min_baseline)
        # Sampling weights: a line sample is as trustworthy as its shortest line (short
        # segments are often clutter, door jambs or fragments with no floorplan match), so
        # samples are drawn with probability proportional to that length.
        self.triplet_p = _probabilities(triplet_weights)
        self.pair_p = _probabilities(lengths[self.pairs].min(axis=1) if len(self.pairs) else np.zeros(0))
        self.line_circle_p = _probabilities(lengths[self.line_circle[:, 0]] if len(self.line_circle) else np.zeros(0))


def _probabilities(weights: np.ndarray) -> np.ndarray | None:
    total = float(np.sum(weights))
    return weights / total if len(weights) and total > 0 else None


# --------------------------------------------------------------------------------------
# model generation per solver
# --------------------------------------------------------------------------------------


def _line_angles(lines: LineSet) -> np.ndarray:
    """Angle of each line's normal, as the solvers compute it for a sample's anchor."""
    return normal_angle(lines.normals)


def _relative(alpha: np.ndarray, rows: np.ndarray) -> np.ndarray:
    return np.mod(alpha[rows[:, 1:]] - alpha[rows[:, :1]], np.pi)


def _models_3l(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng):
    picks = bev.triplets[rng.choice(len(bev.triplets), size=n, p=bev.triplet_p)]
    starts, sizes = fp.triplets.ranges(_relative(bev.alpha, picks))
    if cfg.scale_mode == "fixed":
        # at a fixed scale the third line adds nothing: the rigid two-line solve of the
        # anchor and the second line (solve_3l's fixed mode), drawn and solved compiled
        return drawn_2l(starts, sizes, cfg.ransac.match_fraction, rng, picks[:, :2], fp.triplet_heads, bev.lines, fp.lines,
                        _line_angles(bev.lines), fp.line_angles, 1.0, cfg.solvers, "fixed")[0]
    # draw and solve in one compiled loop
    return drawn_3l(starts, sizes, cfg.ransac.match_fraction, rng, picks, fp.triplets.rows, bev.lines, fp.lines,
                    _line_angles(bev.lines), fp.line_angles, cfg.solvers)[0]


def _models_2l(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng, scale_prior: float):
    picks = bev.pairs[rng.choice(len(bev.pairs), size=n, p=bev.pair_p)]
    starts, sizes = fp.pairs.ranges(_relative(bev.alpha, picks))
    mode = "fixed" if cfg.scale_mode == "fixed" else "prior"
    # draw and solve in one compiled loop (the draws' random numbers, then the scale noise)
    return drawn_2l(starts, sizes, cfg.ransac.match_fraction, rng, picks, fp.pairs.rows, bev.lines, fp.lines,
                    _line_angles(bev.lines), fp.line_angles, scale_prior, cfg.solvers, mode)[0]


def _models_lc(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng):
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


def _models_2c(bev: BevSamples, fp: FloorplanMatches, n: int, cfg: EstimatorSettings, rng):
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


def _correlative_seeds(floorplan, obs: BevObservation, cfg: EstimatorSettings, scale_prior: float) -> np.ndarray:
    """Exhaustive grid placements at the prior (or fixed) scale, LM-refined on the
    wall-face field so they enter the ranking as sharp as the refined RANSAC models."""
    c = cfg.correlative
    scale = 1.0 if cfg.scale_mode == "fixed" else scale_prior
    angles = plausible_angles(obs.lines, floorplan.lines, c.angle_step_deg, c.direction_ratio)
    models = correlative_models(
        floorplan, obs.wall_points, scale, cell=c.cell, angle_step_deg=c.angle_step_deg, tolerance=c.tolerance,
        peaks=c.peaks, angles=angles, distinct_distance=c.distinct_distance, distinct_angle_deg=c.distinct_angle_deg,
    )
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


def _guided_models(bev: BevSamples, fp: FloorplanMatches, warm: Sim2, n: int, cfg: EstimatorSettings, rng, scale_prior: float) -> np.ndarray:
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
    p = None if weights is None else _probabilities(weights[usable])
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


def _missing_warm_starts(floorplan, obs, view, warm, kept: np.ndarray, anchor, cfg: EstimatorSettings) -> list[tuple]:
    """Refined, fully scored rows for the warm starts that no kept hypothesis stands for
    (same implied pose at the BEV anchor), so the tracker can judge every live mode."""
    models = model_rows(warm)
    field = floorplan_scorer(floorplan, cfg.scoring).face_field
    models = refine_batch(field, obs.wall_points, models, cfg.refine, cfg.scale_mode, (cfg.solvers.min_scale, cfg.solvers.max_scale))
    scores = score_hypotheses(floorplan, view, models, cfg.scoring)
    rows = []
    for i, m in enumerate(models):
        both = np.vstack([m[None], kept]) if len(kept) else m[None]
        if len(distinct(both, anchor, cfg.scoring)) == len(both):  # not suppressed by any kept one
            rows.append((m, scores.total[i], scores.consistency[i], scores.violation[i], WARM))
    return rows


def _validate(obs, scale_prior: float, iterations: int) -> None:
    if not isinstance(obs, BevObservation):
        raise InputError(f"localize expects a BevObservation, got {type(obs).__name__}")
    if len(obs.lines) == 0 and len(obs.circles) == 0:
        raise InputError("BEV observation has no lines and no circles: nothing to align to the floorplan")
    if not (np.isfinite(scale_prior) and scale_prior > 0):
        raise InputError(f"scale_prior must be a positive finite number, got {scale_prior}")
    if iterations < 0:
        raise InputError(f"iterations must be >= 0, got {iterations}")


def localize(
    floorplan,
    obs: BevObservation,
    settings: EstimatorSettings,
    rng: np.random.Generator,
    *,
    scale_prior: float = 1.0,
    warm_start: Sequence[Sim2] = (),
    iterations: int | None = None,
    global_search: bool = True,
) -> LocalizationResult:
    """Align the BEV observation to the floorplan; hypotheses ranked best first.

    global_search: also seed with the exhaustive correlative search (fixed or prior
    scale, estimator.correlative.enabled); a round that only follows a tracked mode
    passes False.

    Runs its independent pieces on estimator.threads threads (threads.py), unless the
    caller set the round's thread count already (localizer.run_round)."""
    with threads.limit(threads.resolve(settings.threads), unless_set=True):
        return _localize(floorplan, obs, settings, rng, scale_prior, warm_start, iterations, global_search)


def _localize(floorplan, obs: BevObservation, settings: EstimatorSettings, rng: np.random.Generator, scale_prior: float,
              warm_start: Sequence[Sim2], iterations: int | None, global_search: bool) -> LocalizationResult:
    cfg = settings
    iterations = cfg.ransac.iterations if iterations is None else int(iterations)
    _validate(obs, scale_prior, iterations)
    if cfg.scale_mode == "prior":  # the prior bounds every solver, the refinement and the seeds
        lo, hi = scale_prior / (1.0 + cfg.solvers.prior_range), scale_prior * (1.0 + cfg.solvers.prior_range)
        bounded = {"min_scale": max(cfg.solvers.min_scale, lo), "max_scale": min(cfg.solvers.max_scale, hi)}
        cfg = cfg.model_copy(update={"solvers": cfg.solvers.model_copy(update=bounded)})
    t0, c0 = time.perf_counter(), time.thread_time()

    # ---- model estimation ------------------------------------------------------------
    full_cfg = _settings_of(floorplan)
    fp = floorplan_matches(floorplan, cfg.solvers)
    bev = BevSamples(obs, full_cfg.primitives.lines, cfg.solvers, full_cfg.floorplan.neighbour_distance / scale_prior)
    pool = solver_pool(cfg, bev, fp)
    warm = [w for w in warm_start if isinstance(w, Sim2) and w.is_finite()]
    blocks, labels = [], []
    if pool and iterations > 0:
        counts = np.bincount(rng.integers(len(pool), size=iterations), minlength=len(pool))
        for name, n in zip(pool, counts):
            if n == 0:
                continue
            if name == "3L":
                m = _models_3l(bev, fp, int(n), cfg, rng)
            elif name == "2L":
                m = _models_2l(bev, fp, int(n), cfg, rng, scale_prior)
            elif name == "LC":
                m = _models_lc(bev, fp, int(n), cfg, rng)
            else:
                m = _models_2c(bev, fp, int(n), cfg, rng)
            blocks.append(m)
            labels += [name] * len(m)
    if warm:
        blocks.append(model_rows(warm))
        labels += [WARM] * len(warm)
        guided_modes = warm[: cfg.ransac.guided_modes]
        per_mode = cfg.ransac.guided_iterations // max(1, len(guided_modes))
        for w in guided_modes:
            m = _guided_models(bev, fp, w, per_mode, cfg, rng, scale_prior)
            blocks.append(m)
            labels += [GUIDED] * len(m)
    if global_search and cfg.correlative.enabled and cfg.scale_mode != "free":
        seeds = _correlative_seeds(floorplan, obs, cfg, scale_prior)
        blocks.append(seeds)
        labels += [CORRELATIVE] * len(seeds)
    models = np.concatenate(blocks) if blocks else np.zeros((0, 4))
    labels_arr = np.array(labels, dtype=object)
    t1, c1 = time.perf_counter(), time.thread_time()

    # ---- scoring -----------------------------------------------------------------------
    anchor = obs.wall_points.mean(axis=0)
    if len(models) == 0:
        zero = {"scoring": 0.0, "refinement": 0.0}
        return LocalizationResult([], {"model_estimation": t1 - t0, **zero}, 0, {"model_estimation": c1 - c0, **zero})
    sparse = sparse_line_points(bev.lines, cfg.scoring.sparse_spacing, cfg.scoring.max_sparse_points)
    view = BevView.of(obs, cfg.scoring.tau_v)
    ranking = rank_coarse_to_fine(floorplan, view, models, sparse, anchor, cfg.scoring)
    t2, c2 = time.perf_counter(), time.thread_time()

    # ---- refinement --------------------------------------------------------------------
    top = ranking.index
    cand = models[top].copy()
    total = ranking.scores.total.copy()
    cc = ranking.scores.consistency.copy()
    cv = ranking.scores.violation.copy()
    n_refine = min(cfg.refine.top_n, len(top))
    scale_bounds = (cfg.solvers.min_scale, cfg.solvers.max_scale)
    if n_refine:
        field = floorplan_scorer(floorplan, cfg.scoring).face_field
        refined = refine_batch(field, obs.wall_points, cand[:n_refine], cfg.refine, cfg.scale_mode, scale_bounds)
        rescored = score_hypotheses(floorplan, view, refined, cfg.scoring)
        better = tie_keys(rescored.total) >= tie_keys(total[:n_refine])  # keep a refinement only if it does not hurt C
        cand[:n_refine][better] = refined[better]
        total[:n_refine][better] = rescored.total[better]
        cc[:n_refine][better] = rescored.consistency[better]
        cv[:n_refine][better] = rescored.violation[better]
    order = descending(total)
    keep = order[distinct(cand[order], anchor, cfg.scoring, cfg.ransac.max_hypotheses)]
    rows = [(cand[i], total[i], cc[i], cv[i], str(labels_arr[top[i]])) for i in keep]
    if warm:  # every live mode gets its fresh score, even when it ranks below max_hypotheses
        rows += _missing_warm_starts(floorplan, obs, view, warm, cand[keep], anchor, cfg)
        rows.sort(key=lambda row: -float(tie_keys(np.array([row[1]]))[0]))
    t3, c3 = time.perf_counter(), time.thread_time()

    hypotheses = [Hypothesis(alignment_of(m), float(c), float(a), float(v), label) for m, c, a, v, label in rows]
    timings = {"model_estimation": t1 - t0, "scoring": t2 - t1, "refinement": t3 - t2}
    cpu = {"model_estimation": c1 - c0, "scoring": c2 - c1, "refinement": c3 - c2}
    return LocalizationResult(hypotheses, timings, int(len(models)), cpu)
