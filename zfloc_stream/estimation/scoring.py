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

Everything is vectorised over hypotheses, in chunks of at most chunk_size
(hypotheses x points) elements to bound memory.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import cv2
import numpy as np

from ..config import ScoringSettings
from ..geometry import LineSet
from ..observation import BevObservation
from ..sim2 import wrap_angle
from ..ties import descending

# --------------------------------------------------------------------------------------
# transforms
# --------------------------------------------------------------------------------------


def transform_points(models: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(H, N, 2): every point mapped by every model."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    p = np.asarray(points, dtype=float).reshape(-1, 2)
    a = models[:, 3] * np.cos(models[:, 2])
    b = models[:, 3] * np.sin(models[:, 2])
    x = a[:, None] * p[None, :, 0] - b[:, None] * p[None, :, 1] + models[:, 0, None]
    y = b[:, None] * p[None, :, 0] + a[:, None] * p[None, :, 1] + models[:, 1, None]
    return np.stack([x, y], axis=-1)


def implied_poses(models: np.ndarray, anchor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Floorplan position of the BEV point `anchor` under each model, and the heading."""
    return transform_points(models, np.asarray(anchor, dtype=float).reshape(1, 2))[:, 0], np.asarray(models)[:, 2]


def _chunks(n_models: int, n_points: int, chunk_size: int):
    step = max(1, chunk_size // max(n_points, 1))
    for lo in range(0, n_models, step):
        yield slice(lo, min(lo + step, n_models))


# --------------------------------------------------------------------------------------
# floorplan-side precomputation (cached per floorplan object)
# --------------------------------------------------------------------------------------


UNSEEN, FREE, DEEP_FREE, WALL = 0, 1, 2, 3  # BevView.state codes
MIN_INSIDE_SHARE = 0.25  # enclosed free space below this share of all free space is not "the inside"
_CACHE_CHUNK = 1 << 18  # elements per coarse-scoring chunk (four 1 MiB scratch buffers)


@dataclass(frozen=True)
class FaceField:
    """Distance to the nearest wall surface seen from inside the building, i.e. to a FACE
    cell (a wall cell next to an inside non-wall cell) less half a cell, on the
    floorplan's grid; same attributes as the floorplan's own field so the refinement can
    read either.

    The floorplan's f^c measures to any wall cell, so it is 0 inside a thick wall: a
    hypothesis whose scale pushes BEV walls into the walls' interiors (up to a wall
    thickness, 0.15-0.25 m) costs nothing in Cc nor in the LM residuals. BEV wall points
    are wall surfaces, and so are faces: measured to faces, that slack disappears. Used
    for the coarse ranking and the refinement; the full score keeps the paper's f^c."""

    distance_field: np.ndarray
    origin: np.ndarray
    resolution: float

    @classmethod
    def of(cls, floorplan) -> FaceField:
        from scipy import ndimage  # here, not at import: a CLI error must not pay for it

        res = float(floorplan.resolution)
        origin = np.asarray(floorplan.origin, dtype=float)
        occupied = getattr(floorplan, "occupied", None)
        occupied = np.asarray(floorplan.distance_field) == 0 if occupied is None else np.asarray(occupied, dtype=bool)
        free = ~occupied
        # Faces seen from inside: free space connected to the grid border is outside the
        # building and nobody observes the outer faces of exterior walls, so they are left
        # out (otherwise a BEV scaled too large snaps onto them, a wall thickness away).
        labels, _ = ndimage.label(free)
        border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
        inside = free & ~np.isin(labels, border[border > 0])
        # An open plan, or a map built from scans (its interior leaks into the unknown
        # around it through doorways and gaps, so only small pockets look enclosed):
        # every face counts. MIN_INSIDE_SHARE is a ratio of areas, not a tuned distance.
        seen_from = inside if inside.sum() >= MIN_INSIDE_SHARE * free.sum() else free
        faces = occupied & ndimage.binary_dilation(seen_from)
        if not faces.any():
            return cls(np.asarray(floorplan.distance_field), origin, res)
        # A face cell's centre lies half a cell inside the wall; the wall surface the
        # sensor sees is its edge, so the distance to the surface is about half a cell
        # less (without this, refined scales come out ~1-2 % large in small rooms).
        return cls(np.maximum(ndimage.distance_transform_edt(~faces, sampling=res) - 0.5 * res, 0.0), origin, res)


class FloorplanScorer:
    """Floorplan data the scores read (surface field, coarse grid, bucketed wall points
    for Cv), built once per floorplan object and settings."""

    def __init__(self, floorplan, settings: ScoringSettings):
        # weak: the scorer is cached in a WeakKeyDictionary keyed by this floorplan, and a
        # strong reference from the value would keep every floorplan (and its caches) alive
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
        coarse = np.where(field < self.cap, np.floor(field / self.cap * 255.0), 255.0).astype(np.uint8)
        coarse[[0, -1], :] = 255
        coarse[:, [0, -1]] = 255
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

    def coarse_consistency(self, models: np.ndarray, points: np.ndarray, chunk_size: int) -> np.ndarray:
        """Cc by nearest-cell lookup in the coarse grid (points outside the grid count as
        far from any wall), with ties broken by closeness: the value is
        Cc - mean(min(f^c, cap) / cap) / (n + 1) for n points, which orders exactly as
        (Cc, then smaller mean distance). Many hypotheses of one correspondence cluster
        reach the same Cc on few points; the tie-break makes the cluster's most precise
        member its representative, which is the one worth re-scoring and refining."""
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0 or len(models) == 0:
            return out
        h, w = self.shape
        n = len(points)
        px = np.asarray(points[:, 0], dtype=np.float32)
        py = np.asarray(points[:, 1], dtype=np.float32)
        # chunks of at most chunk_size elements, and at most _CACHE_CHUNK so the scratch
        # buffers stay in cache (each model's value does not depend on the chunking)
        chunk_size = min(chunk_size, _CACHE_CHUNK)
        step = max(1, chunk_size // max(n, 1))
        size = min(step, len(models)) * n
        # scratch buffers reused across chunks; every operation is the one the plain
        # expressions below would do (same dtypes, same order), written in place:
        #   col = clip(a * px - b * py + cu, 0, w - 1) -> int32
        #   row = clip(b * px + a * py + cv, 0, h - 1) -> int32
        f1, f2 = np.empty(size, np.float32), np.empty(size, np.float32)
        icol, irow = np.empty(size, np.int32), np.empty(size, np.int32)
        gathered = np.empty(size, np.uint8)
        for sl in _chunks(len(models), n, chunk_size):
            m = models[sl]
            k = len(m) * n
            shape = (len(m), n)
            b1, b2 = f1[:k].reshape(shape), f2[:k].reshape(shape)
            col, row = icol[:k].reshape(shape), irow[:k].reshape(shape)
            a, b, cu, cv = (t[:, None] for t in self.coarse_terms(m))
            np.multiply(a, px, out=b1)
            np.multiply(b, py, out=b2)
            np.subtract(b1, b2, out=b1)
            np.add(b1, cu, out=b1)
            np.clip(b1, 0, w - 1, out=b1)
            np.copyto(col, b1, casting="unsafe")
            np.multiply(b, px, out=b1)
            np.multiply(a, py, out=b2)
            np.add(b1, b2, out=b1)
            np.add(b1, cv, out=b1)
            np.clip(b1, 0, h - 1, out=b1)
            np.copyto(row, b1, casting="unsafe")
            row *= w
            row += col
            # one gather from the uint8 grid (a quarter of the memory an int32 copy would
            # take, so more of it stays in cache on a large map): the number of near points
            # and the sum of q, both exact integers
            q = gathered[:k].reshape(shape)
            np.take(self.coarse_field, row, out=q)
            near = n - np.count_nonzero(q == 255, axis=1)
            spread = q.sum(axis=1, dtype=np.int64) / (255.0 * n)
            out[sl] = (near - spread / (1.0 + 1.0 / n)) / n
        return out

    def consistency(self, models: np.ndarray, points: np.ndarray, tau_c: float, chunk_size: int) -> np.ndarray:
        """Cc with the floorplan's bilinear f^c lookup."""
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0:
            return out
        for sl in _chunks(len(models), len(points), chunk_size):
            q = transform_points(models[sl], points)
            f = self._floorplan().distance(q.reshape(-1, 2)).reshape(q.shape[:2])
            out[sl] = (f < tau_c).mean(axis=1)
        return out

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

    def points_in_boxes(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Floorplan wall points in the buckets overlapping each axis-aligned box
        (lo, hi: (H, 2)): (owner box (P,), point index (P,)). A superset of the points
        inside each box, which is all the violation test needs."""
        nr, nc = self.bucket_shape
        if nr == 0 or len(lo) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        c0, c1, r0, r1, empty = self.bucket_ranges(lo, hi)
        n_rows = np.where(empty, 0, r1 - r0 + 1)
        # one contiguous index range per (box, bucket row)
        box = np.repeat(np.arange(len(lo)), n_rows)
        row = r0[box] + (np.arange(n_rows.sum()) - np.repeat(np.cumsum(n_rows) - n_rows, n_rows))
        begin = self.bucket_start[row * nc + c0[box]]
        end = self.bucket_start[row * nc + c1[box] + 1]
        length = end - begin
        owner = np.repeat(box, length)
        index = np.repeat(begin - (np.cumsum(length) - length), length) + np.arange(length.sum())
        return owner, index

    def violation(self, models: np.ndarray, bev: "BevView", tau_v: float, chunk_size: int, per: str = "free") -> np.ndarray:
        """Cv: floorplan wall points under the mapped BEV footprint, pulled back into the
        BEV by the inverse transform; of those in observed free space (per="free", the
        paper) or in any observed cell, free or wall (per="observed"), the fraction whose
        clearance exceeds tau_v (precomputed per BEV cell in bev.state)."""
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(self.wall_points) == 0 or len(models) == 0 or bev.radius <= 0:
            return out
        box_lo, box_hi = self.footprint_boxes(models, bev)
        step = max(1, chunk_size // max(len(self.wall_points), 1))
        h, w = bev.state.shape
        flat_state = bev.state.ravel()
        for lo in range(0, len(models), step):
            sl = slice(lo, min(lo + step, len(models)))
            owner, index = self.points_in_boxes(box_lo[sl], box_hi[sl])
            if len(owner) == 0:
                continue
            q = self.wall_points[index]
            m = models[sl][owner]
            # inverse transform into BEV cell units: x = R^T (x' - t) / s, then the grid
            c, sn = np.cos(m[:, 2]), np.sin(m[:, 2])
            k = 1.0 / (m[:, 3] * bev.resolution)
            dx, dy = q[:, 0] - m[:, 0], q[:, 1] - m[:, 1]
            u = (c * dx + sn * dy) * k - bev.origin_cells[0]
            v = (-sn * dx + c * dy) * k - bev.origin_cells[1]
            inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
            cell = np.clip(v, 0, h - 1).astype(np.int64) * w + np.clip(u, 0, w - 1).astype(np.int64)
            state = np.where(inside, flat_state[cell], 0)
            n = sl.stop - sl.start
            seen = (state == FREE) | (state == DEEP_FREE) if per == "free" else state > 0
            n_free = np.bincount(owner, weights=seen, minlength=n)
            n_bad = np.bincount(owner, weights=state == DEEP_FREE, minlength=n)
            out[sl] = np.where(n_free > 0, n_bad / np.maximum(n_free, 1), 0.0)
        return out


_SCORERS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def floorplan_scorer(floorplan, settings: ScoringSettings) -> FloorplanScorer:
    """The cached FloorplanScorer of this floorplan object (rebuilt if settings changed)."""
    key = (settings.tau_c, settings.wall_bucket_size)
    try:
        cached = _SCORERS.get(floorplan)
    except TypeError:  # not weak-referenceable / hashable: no caching
        return FloorplanScorer(floorplan, settings)
    if cached is not None and cached[0] == key:
        return cached[1]
    scorer = FloorplanScorer(floorplan, settings)
    try:
        _SCORERS[floorplan] = (key, scorer)
    except TypeError:
        pass
    return scorer


def scoring_kernels(floorplan, settings: ScoringSettings, kernels: str = "numpy"):
    """What computes the scores: the cached FloorplanScorer (backend numpy), the same
    scorer's data read by compiled loops (backend numpy with estimator.kernels numba,
    scoring_numba.NumbaScorer), or its tensors on scoring.device (backend torch, built once
    per scorer and device)."""
    scorer = floorplan_scorer(floorplan, settings)
    if settings.backend == "numpy":
        if kernels == "numba":
            from .scoring_numba import NumbaScorer  # the optional [fast] extra, imported on first use

            return NumbaScorer(scorer)
        return scorer
    kernels = scorer._torch_kernels.get(settings.device)
    if kernels is None:
        from .scoring_torch import TorchScorer  # the optional [torch] extra, imported on first use

        kernels = scorer._torch_kernels[settings.device] = TorchScorer(scorer, floorplan, settings.device)
    return kernels


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


@dataclass(frozen=True)
class BevView:
    """What the scores read from one BEV observation, computed once per localization."""

    wall_points: np.ndarray  # (N, 2)
    state: np.ndarray  # (H, W) int8: UNSEEN, FREE, DEEP_FREE (clearance > tau_v) or WALL (a BEV wall point's cell)
    origin_cells: np.ndarray  # (2,) BEV origin in cell units
    resolution: float
    centre: np.ndarray  # (2,) centre of a disc covering every free cell
    radius: float  # its radius (0: no free cell)

    @classmethod
    def of(cls, obs: BevObservation, tau_v: float) -> BevView:
        free = np.asarray(obs.free, dtype=bool)
        # f^v as used here: distance to the nearest cell that is NOT observed free
        # (occupied or unknown), i.e. min(obs.clearance, depth into the free region).
        # The paper measures to occupied cells only; but a wall seen at grazing incidence
        # gets hits far apart while free space reaches it between them, so occupied-only
        # clearance flags the true wall as a violation. Depth into free space does not.
        # "depth > tau_v" is an erosion of the free mask by a disc of radius tau_v.
        r = int(np.floor(tau_v / obs.resolution))
        yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
        disc = ((xx * xx + yy * yy) * obs.resolution**2 <= tau_v * tau_v).astype(np.uint8)
        inner = cv2.erode(free.astype(np.uint8), disc, borderType=cv2.BORDER_CONSTANT, borderValue=0).astype(bool)
        deep = inner & (np.asarray(obs.clearance) > tau_v)
        state = free.astype(np.int8)
        state += deep  # FREE + 1 = DEEP_FREE where deep
        cells = np.floor((np.asarray(obs.wall_points) - obs.origin) / obs.resolution).astype(np.int64)
        h, w = state.shape
        ok = (cells[:, 0] >= 0) & (cells[:, 0] < w) & (cells[:, 1] >= 0) & (cells[:, 1] < h)
        state[cells[ok, 1], cells[ok, 0]] = WALL
        # the free cells' bounding box from per-row / per-column flags: the same box as
        # np.nonzero's indices give, without listing every free cell (~10x cheaper)
        rows, cols = np.flatnonzero(free.any(axis=1)), np.flatnonzero(free.any(axis=0))
        if len(rows):
            lo = obs.origin + obs.resolution * np.array([cols[0], rows[0]])
            hi = obs.origin + obs.resolution * np.array([cols[-1] + 1, rows[-1] + 1])
            centre, radius = 0.5 * (lo + hi), float(0.5 * np.linalg.norm(hi - lo) + obs.resolution)
        else:
            centre, radius = np.zeros(2), 0.0
        origin_cells = np.asarray(obs.origin, dtype=float) / obs.resolution
        return cls(obs.wall_points, state, origin_cells, float(obs.resolution), centre, radius)


# --------------------------------------------------------------------------------------
# scores and ranking
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Scores:
    """Full scores of a set of hypotheses."""

    total: np.ndarray  # C = Cc - violation_weight * Cv
    consistency: np.ndarray  # Cc
    violation: np.ndarray  # Cv


def score_hypotheses(floorplan, obs: BevObservation | BevView, models, settings: ScoringSettings = ScoringSettings(), kernels: str = "numpy") -> Scores:
    """Full C = Cc - Cv of every model on all BEV wall points."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    bev = obs if isinstance(obs, BevView) else BevView.of(obs, settings.tau_v)
    scorer = scoring_kernels(floorplan, settings, kernels)
    cc = scorer.consistency(models, bev.wall_points, settings.tau_c, settings.chunk_size)
    cv = scorer.violation(models, bev, settings.tau_v, settings.chunk_size, settings.violation_per)
    return Scores(cc - settings.violation_weight * cv, cc, cv)


def distinct(models: np.ndarray, anchor: np.ndarray, settings: ScoringSettings, limit: int | None = None) -> np.ndarray:
    """Indices (in the given order, which must be best first) of hypotheses kept by greedy
    suppression: a hypothesis is dropped when a better kept one implies a BEV-anchor
    position within distinct_translation AND a heading within distinct_angle_deg."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    n = len(models)
    limit = n if limit is None else int(limit)
    if n == 0 or limit <= 0:
        return np.zeros(0, dtype=np.int64)
    pos, ang = implied_poses(models, anchor)
    max_angle = np.deg2rad(settings.distinct_angle_deg)
    # Greedy suppression in order never looks ahead, so running it on a prefix gives the
    # same first survivors as on the whole list: grow the prefix only when it runs dry.
    block = min(n, max(256, 16 * limit))
    while True:
        kept = _greedy_distinct(pos[:block], ang[:block], settings.distinct_translation, max_angle, limit)
        if len(kept) >= limit or block >= n:
            return kept
        block = min(n, 4 * block)


def _greedy_distinct(pos, ang, max_distance, max_angle, limit) -> np.ndarray:
    alive = np.ones(len(pos), dtype=bool)
    kept: list[int] = []
    while len(kept) < limit:
        candidates = np.flatnonzero(alive)
        if len(candidates) == 0:
            break
        i = int(candidates[0])
        kept.append(i)
        rest = candidates[1:]
        near = (np.hypot(pos[rest, 0] - pos[i, 0], pos[rest, 1] - pos[i, 1]) < max_distance) & (
            np.abs(wrap_angle(ang[rest] - ang[i])) < max_angle
        )
        alive[i] = False
        alive[rest[near]] = False
    return np.array(kept, dtype=np.int64)


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
    kernels: str = "numpy",
) -> Ranking:
    """Coarse Cc on sparse line points for all models, full C on the top_k distinct."""
    models = np.asarray(models, dtype=float).reshape(-1, 4)
    bev = obs if isinstance(obs, BevView) else BevView.of(obs, settings.tau_v)
    scorer = scoring_kernels(floorplan, settings, kernels)
    points = sparse_points if len(sparse_points) else bev.wall_points
    coarse = scorer.coarse_consistency(models, points, settings.chunk_size)
    if kernels == "numba":
        # the same indices without sorting every model or posing it (scoring_numba.top_distinct)
        from .scoring_numba import top_distinct

        top = top_distinct(models, coarse, anchor, settings)
    else:
        order = descending(coarse)
        top = order[distinct(models[order], anchor, settings, settings.top_k)]
    scores = score_hypotheses(floorplan, bev, models[top], settings, kernels)
    best = descending(scores.total)
    return Ranking(top[best], Scores(scores.total[best], scores.consistency[best], scores.violation[best]), coarse)
