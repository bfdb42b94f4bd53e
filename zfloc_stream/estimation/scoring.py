"""Hypothesis scoring (paper 3.3): C = Cc - Cv, ranked coarse to fine.

Models are rows (tx, ty, theta, s) of x' = s R x + t (BEV -> floorplan).

Cc (consistency): fraction of transformed BEV wall points whose wall distance f^c (the
floorplan's precomputed distance field) is below tau_c.
Cv (violation): floorplan wall points mapped back into the BEV by the inverse transform;
of those landing in observed free space, the fraction whose clearance f^v exceeds tau_v
(a wall where the sensor saw open floor). No floorplan wall in free space: Cv = 0.

Coarse to fine: every hypothesis is first ranked by Cc on at most max_sparse_points
points sampled along the BEV lines, with a nearest-cell lookup in a precomputed uint8 grid
(~10 array operations per point; ties broken by closeness, see coarse_consistency). The
coarse grid measures to the wall surfaces seen from inside the building (FaceField), not
to any wall cell, so BEV walls pushed into a thick wall are not "consistent" there. The
best top_k DISTINCT hypotheses (greedy non-maximum suppression on the implied pose of the
BEV centroid) are then re-ranked with the full score: the floorplan's bilinear f^c on all
BEV wall points (the paper's Cc), and Cv.

Cv deviation from the paper: f^v is the distance to the nearest cell that is not observed
free (see BevView), which tolerates free space touching walls seen at grazing incidence.

The three scores are compiled loops (numba) over hypotheses and points: per point the
float operations are element-wise (the same cell, the same test on any thread count), and
what is summed are integer counts (and the coarse grid's uint8 levels), exact in any
order. A call over many hypotheses is split into ranges of them, one per thread the round
was given (threads.py), each writing its own slots: the same bits. These kernels are what
`scoring.backend: numpy` selects (the setting's name is older than the kernels). The torch
backend (scoring_torch.py) computes the same scores on tensors.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from ..runtime import threads
from ..settings.loading import ScoringSettings
from ..errors import InputError
from ..geometry.shapes import LineSet
from ..observation import BevObservation
from .views import COARSE_FAR, DEEP_FREE, FREE, BevView, implied_poses, transform_points  # noqa: F401 (implied_poses, transform_points: public here too)
from ..runtime.numba_support import njit
from ..geometry.bilinear import bilinear_at, centre_coordinates
from ..runtime.ties import descending
from .distinct_poses import top_distinct
from .face_field import FaceField
from .plan_cache import cached_per_floorplan

# --------------------------------------------------------------------------------------
# floorplan-side precomputation (cached per floorplan object)
# --------------------------------------------------------------------------------------


COARSE_BLOCK_ROWS = 512  # rows of the coarse grid quantised at once (bounds the float64 temporaries)


# --------------------------------------------------------------------------------------
# compiled score kernels (read a FloorplanScorer's arrays; trigonometry stays in numpy)
# --------------------------------------------------------------------------------------


# a kernel call is split over the round's threads (threads.py) only into pieces of at
# least this many point lookups (~0.2 ms): handing a piece to a worker costs ~0.05 ms
_MIN_LOOKUPS_PER_THREAD = 200_000
_MIN_VIOLATION_MODELS_PER_THREAD = 64  # violation: a model reads the floorplan walls under its footprint

def _model_ranges(n_models: int, n_points: int) -> list[tuple[int, int]]:
    return threads.ranges(n_models, _MIN_LOOKUPS_PER_THREAD // max(1, n_points) + 1)


@njit
def _coarse_kernel(models, inv, ox, oy, px, py, grid, h, w, index_type, out):
    """FloorplanScorer.coarse_consistency for every model, coarse_terms included: a, b,
    cu, cv are its float64 expressions rounded to float32 (the headings' cos and sin are
    the C library's here: numpy's on most machines, within an ulp where numpy has its own
    vector routines; computed per model in the loop, they cost a quarter of the numpy
    call's time at 10^5 models); the float32 cell coordinates a x - b y + cu and b x + a y + cv,
    clipped to the grid and truncated, index the uint8 coarse grid; out = (near - spread /
    (1 + 1/n)) / n. index_type: np.uint32 when every cell index fits in 32 bits (the
    index arithmetic then vectorises in 32-bit lanes, ~25 % faster), else np.uint64."""
    n = px.shape[0]
    col_max = np.float32(w - 1)  # np.clip's bounds, float32 like the array it clips
    row_max = np.float32(h - 1)
    zero = np.float32(0.0)
    for i in range(models.shape[0]):
        # coarse_terms: (s cos) * inv, (s sin) * inv, (t - origin) * inv, then float32
        ci = np.cos(models[i, 2])
        si = np.sin(models[i, 2])
        ai = np.float32(models[i, 3] * ci * inv)
        bi = np.float32(models[i, 3] * si * inv)
        cui = np.float32((models[i, 0] - ox) * inv)
        cvi = np.float32((models[i, 1] - oy) * inv)
        far = 0
        total = 0
        for j in range(n):
            x = ai * px[j] - bi * py[j] + cui
            y = bi * px[j] + ai * py[j] + cvi
            # clipped by selects (branch-free, so the loop vectorises); the first select
            # also sends NaN to the border ring, which reads as far from any wall, instead
            # of an arbitrary address
            x = x if x >= zero else zero
            x = x if x <= col_max else col_max
            y = y if y >= zero else zero
            y = y if y <= row_max else row_max
            # truncation of a value in [0, w - 1], as numpy's cast to int32; the unsigned
            # index also spares numba's negative-index wraparound test
            q = grid[index_type(np.int32(y) * w + np.int32(x))]
            total += q
            far += q == COARSE_FAR
        near = n - far
        spread = total / (float(COARSE_FAR) * n)
        out[i] = (near - spread / (1.0 + 1.0 / n)) / n


@njit
def _consistency_kernel(a, b, tx, ty, px, py, field, h, w, ox, oy, res, tau_c, out):
    """FloorplanScorer.consistency for every model: the points mapped by x' = s R x + t
    (a = s cos, b = s sin), f^c by Floorplan.distance's bilinear lookup (the same compiled
    bilinear_at, geometry/bilinear.py), out = the share
    below tau_c. False (out unfinished) when a mapped point is not finite, where
    Floorplan.distance raises."""
    n = px.shape[0]
    for i in range(a.shape[0]):
        ai, bi, txi, tyi = a[i], b[i], tx[i], ty[i]
        below = 0
        for j in range(n):
            x = ai * px[j] - bi * py[j] + txi
            y = bi * px[j] + ai * py[j] + tyi
            if not (math.isfinite(x) and math.isfinite(y)):
                return False
            u, v = centre_coordinates(x, y, ox, oy, res)
            value = bilinear_at(field, h, w, res, u, v)
            if value < tau_c:
                below += 1
        out[i] = below / n
    return True


@njit
def _violation_kernel(tx, ty, c, sn, k, c0, c1, r0, r1, empty, bucket_start, n_cols, walls, state, h, w, ou, ov, observed, out):
    """FloorplanScorer.violation for every model: the floorplan wall points of the buckets
    under its footprint box (rows r0..r1, columns c0..c1; one contiguous range per row)
    pulled back into BEV cells by (R^T (x' - t)) k - origin; of those in observed free
    space (or any observed cell, `observed`), the share in deep free space."""
    for i in range(tx.shape[0]):
        if empty[i]:
            continue
        txi, tyi, ci, si, ki = tx[i], ty[i], c[i], sn[i], k[i]
        n_seen = 0
        n_bad = 0
        for r in range(r0[i], r1[i] + 1):
            for p in range(bucket_start[r * n_cols + c0[i]], bucket_start[r * n_cols + c1[i] + 1]):
                dx = walls[p, 0] - txi
                dy = walls[p, 1] - tyi
                u = (ci * dx + si * dy) * ki - ou
                v = (-si * dx + ci * dy) * ki - ov
                if not (u >= 0 and u < w and v >= 0 and v < h):
                    continue  # outside the BEV grid: unseen
                s = state[np.int64(v) * w + np.int64(u)]
                if s == DEEP_FREE:
                    n_bad += 1
                    n_seen += 1
                elif s == FREE or (observed and s > 0):
                    n_seen += 1
        if n_seen > 0:
            out[i] = n_bad / n_seen


class FloorplanScorer:
    """Floorplan data the scores read (surface field, coarse grid, bucketed wall points
    for Cv), built once per floorplan object and settings."""

    def __init__(self, floorplan, settings: ScoringSettings):
        # weak: the scorer is cached beside this floorplan, weakly keyed (plan_cache.py), and
        # a strong reference from the value would keep every floorplan (and its caches) alive
        self._floorplan = weakref.ref(floorplan)
        self.face_field = FaceField.of(floorplan)
        field = self.face_field.distance_field
        self.shape = field.shape
        self.origin = np.asarray(floorplan.origin, dtype=float)
        self.resolution = float(floorplan.resolution)
        # Coarse grid: the surface distance per cell quantised to uint8 on [0, cap), 255 =
        # "not near a wall" (>= cap). cap = tau_c plus half a cell: points sit up to half a cell
        # diagonal from the cell centre where the field is sampled, and the margin makes
        # the nearest-cell test about unbiased against the bilinear full score. The
        # outermost ring is 255 so points clamped onto the border from outside the grid
        # count as far from any wall (no separate inside test needed).
        self.cap = settings.tau_c + 0.5 * self.resolution
        coarse = np.empty(field.shape, dtype=np.uint8)
        for r in range(0, field.shape[0], COARSE_BLOCK_ROWS):  # blocks of rows: float64 temporaries stay small
            f = field[r : r + COARSE_BLOCK_ROWS]
            coarse[r : r + COARSE_BLOCK_ROWS] = np.where(f < self.cap, np.floor(f / self.cap * float(COARSE_FAR)), float(COARSE_FAR))
        coarse[[0, -1], :] = COARSE_FAR
        coarse[:, [0, -1]] = COARSE_FAR
        self.coarse_field = np.ascontiguousarray(coarse).ravel()
        self._torch_kernels: dict[str, object] = {}  # scoring_kernels' TorchScorer per device
        # Cv's floorplan wall points, sorted into square buckets (row-major) so the points
        # under a hypothesis' footprint are a few contiguous index ranges.
        walls = np.asarray(floorplan.sample_wall_points(), dtype=float).reshape(-1, 2)
        self.bucket = float(settings.wall_bucket_size)
        self.bucket_origin = walls.min(axis=0) if len(walls) else np.zeros(2)
        cells = np.floor((walls - self.bucket_origin) / self.bucket).astype(np.int64) if len(walls) else np.zeros((0, 2), np.int64)
        self.bucket_shape = (int(cells[:, 1].max()) + 1, int(cells[:, 0].max()) + 1) if len(walls) else (0, 0)
        key = cells[:, 1] * self.bucket_shape[1] + cells[:, 0]
        order = np.argsort(key, kind="stable")
        self.wall_points = walls[order]
        self.wall_cells = cells[order]  # (P, 2) bucket (column, row) of each wall point
        counts = np.bincount(key, minlength=self.bucket_shape[0] * self.bucket_shape[1])
        self.bucket_start = np.concatenate([[0], np.cumsum(counts)])  # points of bucket b: [start[b], start[b + 1])

    def coarse_terms(self, models: np.ndarray) -> tuple[np.ndarray, ...]:
        """(a, b, cu, cv) float32 per model: s cos, s sin and the translation with the grid's
        origin and resolution folded in, so a point's cell is (a x - b y + cu, b x + a y + cv)."""
        inv = 1.0 / self.resolution
        return ((models[:, 3] * np.cos(models[:, 2]) * inv).astype(np.float32),
                (models[:, 3] * np.sin(models[:, 2]) * inv).astype(np.float32),
                ((models[:, 0] - self.origin[0]) * inv).astype(np.float32),
                ((models[:, 1] - self.origin[1]) * inv).astype(np.float32))

    def bucket_ranges(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, ...]:
        """Per axis-aligned box (lo, hi: (H, 2)) the bucket columns c0..c1 and rows r0..r1
        it overlaps (clipped to the grid), and whether it lies wholly below / left of it."""
        nr, nc = self.bucket_shape
        origin, size = self.bucket_origin, self.bucket
        c0 = np.clip(np.floor((lo[:, 0] - origin[0]) / size), 0, nc - 1).astype(np.int64)
        c1 = np.clip(np.floor((hi[:, 0] - origin[0]) / size), 0, nc - 1).astype(np.int64)
        r0 = np.clip(np.floor((lo[:, 1] - origin[1]) / size), 0, nr - 1).astype(np.int64)
        r1 = np.clip(np.floor((hi[:, 1] - origin[1]) / size), 0, nr - 1).astype(np.int64)
        empty = (hi[:, 0] < origin[0]) | (hi[:, 1] < origin[1])
        return c0, c1, r0, r1, empty

    @staticmethod
    def footprint_boxes(models: np.ndarray, bev: "BevView") -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) of the square around each model's image of the BEV's free-space disc."""
        centres = transform_points(models, bev.centre[None])[:, 0]
        reach = models[:, 3] * bev.radius
        return centres - reach[:, None], centres + reach[:, None]

    def coarse_consistency(self, models: np.ndarray, points: np.ndarray, chunk_size: int) -> np.ndarray:
        """Cc by nearest-cell lookup in the coarse grid (points outside the grid count as
        far from any wall), with ties broken by closeness: the value is
        Cc - mean(min(f^c, cap) / cap) / (n + 1) for n points, which orders exactly as
        (Cc, then smaller mean distance). Many hypotheses of one correspondence cluster
        reach the same Cc on few points; the tie-break makes the cluster's most precise
        member its representative, which is the one worth re-scoring and refining.
        chunk_size is the torch backend's (the loops build no temporaries to bound)."""
        scorer = self
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0 or len(models) == 0:
            return out
        h, w = scorer.shape
        px = np.ascontiguousarray(points[:, 0], dtype=np.float32)
        py = np.ascontiguousarray(points[:, 1], dtype=np.float32)
        index_type = np.uint32 if h * w <= 1 << 32 else np.uint64
        inv, ox, oy = 1.0 / scorer.resolution, float(scorer.origin[0]), float(scorer.origin[1])

        def piece(r):
            i = slice(*r)
            _coarse_kernel(models[i], inv, ox, oy, px, py, scorer.coarse_field, h, w, index_type, out[i])

        threads.run(piece, _model_ranges(len(models), len(px)))
        return out

    def consistency(self, models: np.ndarray, points: np.ndarray, tau_c: float, chunk_size: int) -> np.ndarray:
        """Cc with the floorplan's bilinear f^c lookup (Floorplan.distance's arithmetic)."""
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0 or len(models) == 0:
            return out
        floorplan = self._floorplan()
        p = np.asarray(points, dtype=float).reshape(-1, 2)
        # transform_points' a and b (numpy's cos and sin)
        a = models[:, 3] * np.cos(models[:, 2])
        b = models[:, 3] * np.sin(models[:, 2])
        h, w = floorplan.shape
        tx, ty = np.ascontiguousarray(models[:, 0]), np.ascontiguousarray(models[:, 1])
        px, py = np.ascontiguousarray(p[:, 0]), np.ascontiguousarray(p[:, 1])
        grid = (floorplan._flat_field, h, w, float(floorplan.origin[0]), float(floorplan.origin[1]), float(floorplan.resolution))

        def piece(r):
            i = slice(*r)
            return _consistency_kernel(a[i], b[i], tx[i], ty[i], px, py, *grid, float(tau_c), out[i])

        if not all(threads.run(piece, _model_ranges(len(models), len(p)))):
            raise InputError("points passed to Floorplan.distance contain NaN or inf")
        return out

    def violation(self, models: np.ndarray, bev, tau_v: float, chunk_size: int, per: str = "free") -> np.ndarray:
        """Cv: floorplan wall points under the mapped BEV footprint, pulled back into the
        BEV by the inverse transform; of those in observed free space (per="free", the
        paper) or in any observed cell, free or wall (per="observed"), the fraction whose
        clearance exceeds tau_v (precomputed per BEV cell in bev.state)."""
        scorer = self
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        n_rows, n_cols = scorer.bucket_shape
        if len(scorer.wall_points) == 0 or len(models) == 0 or bev.radius <= 0 or n_rows == 0:
            return out
        c0, c1, r0, r1, empty = scorer.bucket_ranges(*scorer.footprint_boxes(models, bev))
        c, sn = np.cos(models[:, 2]), np.sin(models[:, 2])
        k = 1.0 / (models[:, 3] * bev.resolution)
        h, w = bev.state.shape
        tx, ty = np.ascontiguousarray(models[:, 0]), np.ascontiguousarray(models[:, 1])
        state = np.ascontiguousarray(bev.state).ravel()
        ou, ov = float(bev.origin_cells[0]), float(bev.origin_cells[1])

        def piece(r):
            i = slice(*r)
            _violation_kernel(tx[i], ty[i], c[i], sn[i], k[i], c0[i], c1[i], r0[i], r1[i], empty[i], scorer.bucket_start, n_cols,
                              scorer.wall_points, state, h, w, ou, ov, per == "observed", out[i])

        threads.run(piece, threads.ranges(len(models), _MIN_VIOLATION_MODELS_PER_THREAD))
        return out


def floorplan_scorer(floorplan, settings: ScoringSettings) -> FloorplanScorer:
    """The cached FloorplanScorer of this floorplan object (rebuilt if settings changed)."""
    key = (settings.tau_c, settings.wall_bucket_size)
    return cached_per_floorplan(floorplan, "scorer", key, lambda: FloorplanScorer(floorplan, settings))


def scoring_kernels(floorplan, settings: ScoringSettings):
    """What computes the scores, chosen by scoring.backend: the cached FloorplanScorer and
    its compiled numba kernels on the CPU ("numpy", a name older than the kernels, kept so
    existing configs stay valid: no numpy array code scores), or its tensors on scoring.device
    ("torch", built once per scorer and device). Both have coarse_consistency,
    consistency and violation with the same arguments."""
    scorer = floorplan_scorer(floorplan, settings)
    if settings.backend == "numpy":
        return scorer
    torch_scorer = scorer._torch_kernels.get(settings.device)
    if torch_scorer is None:
        from .scoring_torch import TorchScorer  # the optional [torch] extra, imported on first use

        torch_scorer = scorer._torch_kernels[settings.device] = TorchScorer(scorer, floorplan, settings.device)
    return torch_scorer


# --------------------------------------------------------------------------------------
# BEV-side helpers
# --------------------------------------------------------------------------------------


def sparse_line_points(lines: LineSet, spacing: float, max_points: int | None = None) -> np.ndarray:
    """Points every `spacing` along each segment (at least its two ends); the spacing
    grows when needed so that about max_points points are produced at most."""
    if len(lines) == 0:
        return np.zeros((0, 2))
    if max_points:
        spacing = max(spacing, float(lines.lengths.sum()) / max(max_points - 2 * len(lines), 1))
    e = lines.endpoints
    counts = np.maximum(np.ceil(lines.lengths / spacing).astype(np.int64), 1) + 1
    owner = np.repeat(np.arange(len(lines)), counts)
    start = np.cumsum(counts) - counts
    t = (np.arange(counts.sum()) - start[owner]) / (counts[owner] - 1)
    return e[owner, 0] + t[:, None] * (e[owner, 1] - e[owner, 0])


# --------------------------------------------------------------------------------------
# scores and ranking
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scores:
    """Full scores of a set of hypotheses."""

    total: np.ndarray  # C = Cc - violation_weight * Cv
    consistency: np.ndarray  # Cc
    violation: np.ndarray  # Cv


def score_hypotheses(floorplan, obs: BevObservation | BevView, models, settings: ScoringSettings = ScoringSettings()) -> Scores:
    """Full C = Cc - Cv of every model on all BEV wall points."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    bev = obs if isinstance(obs, BevView) else BevView.of(obs, settings.tau_v)
    scorer = scoring_kernels(floorplan, settings)
    cc = scorer.consistency(models, bev.wall_points, settings.tau_c, settings.chunk_size)
    cv = scorer.violation(models, bev, settings.tau_v, settings.chunk_size, settings.violation_per)
    return Scores(cc - settings.violation_weight * cv, cc, cv)


@dataclass(frozen=True)
class Ranking:
    """top_k distinct hypotheses re-ranked by the full score (best first)."""

    index: np.ndarray  # indices into the scored models
    scores: Scores
    coarse: np.ndarray  # coarse Cc of every input model


def rank_coarse_to_fine(
    floorplan,
    obs: BevObservation | BevView,
    models: np.ndarray,
    sparse_points: np.ndarray,
    anchor: np.ndarray,
    settings: ScoringSettings = ScoringSettings(),
) -> Ranking:
    """Coarse Cc on sparse line points for all models, full C on the top_k distinct."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    bev = obs if isinstance(obs, BevView) else BevView.of(obs, settings.tau_v)
    scorer = scoring_kernels(floorplan, settings)
    points = sparse_points if len(sparse_points) else bev.wall_points
    coarse = scorer.coarse_consistency(models, points, settings.chunk_size)
    top = top_distinct(models, coarse, anchor, settings)  # order[distinct(models[order])], order = descending(coarse)
    scores = score_hypotheses(floorplan, bev, models[top], settings)
    best = descending(scores.total)
    return Ranking(top[best], Scores(scores.total[best], scores.consistency[best], scores.violation[best]), coarse)
