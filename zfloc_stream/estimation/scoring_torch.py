"""The scores of scoring.py in torch (scoring.backend: torch): CUDA when present, CPU otherwise.

Same interface and the same element-wise arithmetic as FloorplanScorer's compiled kernels,
so the two agree to the last bit wherever float operations round alike (torch on CPU, as
measured in tests/test_scoring_torch.py); the stated tolerance is one point in N: on a GPU,
fused multiply-adds may move a point that sits on a cell boundary to the next cell, so a
hypothesis' Cc or Cv may differ by one point in N (|difference| <= 1 / N). The per-model trigonometry stays in numpy (float64) and only the
(hypotheses x points) work runs in torch, where a GPU scores many more hypotheses per round.

Cv differs in how it finds the floorplan wall points under a hypothesis' footprint: the
compiled kernel reads them bucket by bucket; here every model reads every wall point, masked
by the same buckets, which selects exactly the same points and suits a GPU.
"""

from __future__ import annotations

import numpy as np

from ..runtime.torch_support import choose_device, require_torch
from .views import COARSE_FAR, DEEP_FREE, FREE, transform_points

_CACHE_CHUNK = 1 << 18  # elements per coarse-scoring chunk


def _chunks(n_models: int, n_points: int, chunk_size: int):
    """Slices of the models, at most chunk_size (models x points) elements each: bounds
    the tensors a chunk builds."""
    step = max(1, chunk_size // max(n_points, 1))
    for lo in range(0, n_models, step):
        yield slice(lo, min(lo + step, n_models))


def _gather(flat, index):
    """flat[index] for any index shape (index_select: several times faster than advanced
    indexing on CPU)."""
    return flat.index_select(0, index.reshape(-1)).reshape(index.shape)


class TorchScorer:
    """A FloorplanScorer's data as tensors on one device, with its three kernels."""

    def __init__(self, scorer, floorplan, device: str = "auto"):
        torch = self.torch = require_torch("estimator.scoring.backend: torch")
        self.device = choose_device(torch, device, "scoring.device")
        self.scorer = scorer
        self.shape = scorer.shape
        self.origin = scorer.origin
        self.resolution = scorer.resolution
        self._coarse = torch.as_tensor(scorer.coarse_field, device=self.device)  # uint8
        self._field = torch.as_tensor(np.asarray(floorplan._flat_field, dtype=np.float64), device=self.device)
        self._field_shape = floorplan.shape
        self._field_origin = np.asarray(floorplan.origin, dtype=float)
        self._field_resolution = float(floorplan.resolution)
        self._walls = torch.as_tensor(scorer.wall_points, dtype=torch.float64, device=self.device)
        self._wall_col = torch.as_tensor(scorer.wall_cells[:, 0], device=self.device)
        self._wall_row = torch.as_tensor(scorer.wall_cells[:, 1], device=self.device)

    def _tensor(self, array, dtype):
        return self.torch.as_tensor(np.ascontiguousarray(array), dtype=dtype, device=self.device)

    # ---- coarse Cc -----------------------------------------------------------------------
    def coarse_consistency(self, models: np.ndarray, points: np.ndarray, chunk_size: int) -> np.ndarray:
        """FloorplanScorer.coarse_consistency (same value, same tie-break)."""
        torch = self.torch
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0 or len(models) == 0:
            return out
        h, w = self.shape
        n = len(points)
        field = self._coarse
        px = self._tensor(np.asarray(points[:, 0], dtype=np.float32), torch.float32)
        py = self._tensor(np.asarray(points[:, 1], dtype=np.float32), torch.float32)
        # the model terms in numpy float64 -> float32, exactly as the compiled kernel makes them
        terms = self._tensor(np.stack(self.scorer.coarse_terms(models), axis=1), torch.float32)
        # chunks bound the device memory; on CPU, cache-sized ones
        chunk_size = chunk_size if self.device.type == "cuda" else min(chunk_size, _CACHE_CHUNK)
        sums, nears = [], []
        for sl in _chunks(len(models), n, chunk_size):
            a, b, cu, cv = (terms[sl, i, None] for i in range(4))
            col = torch.clamp(a * px - b * py + cu, 0, w - 1).to(torch.int64)
            row = torch.clamp(b * px + a * py + cv, 0, h - 1).to(torch.int64)
            q = _gather(field, row * w + col)
            sums.append(q.sum(dim=1, dtype=torch.int64))
            nears.append((q != COARSE_FAR).sum(dim=1))
        near = torch.cat(nears).cpu().numpy()
        spread = torch.cat(sums).cpu().numpy() / (float(COARSE_FAR) * n)
        out[:] = (near - spread / (1.0 + 1.0 / n)) / n
        return out

    # ---- full Cc -------------------------------------------------------------------------
    def _distance(self, q):
        """Floorplan.distance on a (M, 2) float64 tensor (bilinear; outside: nearest + gap).
        geometry/bilinear.py's bilinear_at written again in tensor operations, on purpose:
        the compiled scalar code runs on the CPU only, and this runs where the tensors are
        (a GPU), over every (model, point) pair at once. Same expressions, same order."""
        torch = self.torch
        h, w = self._field_shape
        u = (q[:, 0] - self._field_origin[0]) / self._field_resolution - 0.5
        v = (q[:, 1] - self._field_origin[1]) / self._field_resolution - 0.5
        uc = torch.clamp(u, 0.0, w - 1.0)
        vc = torch.clamp(v, 0.0, h - 1.0)
        c0 = torch.clamp(uc.to(torch.int64), max=w - 2)
        r0 = torch.clamp(vc.to(torch.int64), max=h - 2)
        fu, fv = uc - c0, vc - r0
        i = r0 * w + c0
        f = self._field
        top = _gather(f, i) * (1.0 - fu) + _gather(f, i + 1) * fu
        bottom = _gather(f, i + w) * (1.0 - fu) + _gather(f, i + w + 1) * fu
        value = top * (1.0 - fv) + bottom * fv
        return value + torch.hypot(u - uc, v - vc) * self._field_resolution

    def consistency(self, models: np.ndarray, points: np.ndarray, tau_c: float, chunk_size: int) -> np.ndarray:
        """FloorplanScorer.consistency: Cc with the floorplan's bilinear f^c."""
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        if len(points) == 0:
            return out
        for sl in _chunks(len(models), len(points), chunk_size):
            q = self._tensor(transform_points(models[sl], points), self.torch.float64)
            f = self._distance(q.reshape(-1, 2)).reshape(q.shape[:2])
            out[sl] = (f < tau_c).to(self.torch.float64).mean(dim=1).cpu().numpy()
        return out

    # ---- Cv ------------------------------------------------------------------------------
    def violation(self, models: np.ndarray, bev, tau_v: float, chunk_size: int, per: str = "free") -> np.ndarray:
        """FloorplanScorer.violation, every wall point masked by the buckets the compiled kernel
        gathers (the ones overlapping the box around the mapped footprint)."""
        torch = self.torch
        scorer = self.scorer
        models = np.asarray(models, dtype=float).reshape(-1, 4)
        out = np.zeros(len(models))
        nr, nc = scorer.bucket_shape
        if len(scorer.wall_points) == 0 or len(models) == 0 or bev.radius <= 0 or nr == 0:
            return out
        # the buckets FloorplanScorer.points_in_boxes gathers, per model
        c0, c1, r0, r1, empty = scorer.bucket_ranges(*scorer.footprint_boxes(models, bev))
        c, sn = np.cos(models[:, 2]), np.sin(models[:, 2])
        k = 1.0 / (models[:, 3] * bev.resolution)
        per_model = self._tensor(np.column_stack([models[:, 0], models[:, 1], c, sn, k]), torch.float64)
        ranges = self._tensor(np.column_stack([c0, c1, r0, r1, empty]), torch.int64)
        state = self._tensor(bev.state.ravel(), torch.int64)
        h, w = bev.state.shape
        ou, ov = float(bev.origin_cells[0]), float(bev.origin_cells[1])
        qx, qy = self._walls[None, :, 0], self._walls[None, :, 1]
        for sl in _chunks(len(models), len(scorer.wall_points), chunk_size):
            tx, ty, cs, ss, kk = (per_model[sl, i, None] for i in range(5))
            bc0, bc1, br0, br1, bempty = (ranges[sl, i, None] for i in range(5))
            taken = (self._wall_col >= bc0) & (self._wall_col <= bc1) & (self._wall_row >= br0) & (self._wall_row <= br1) & (bempty == 0)
            dx, dy = qx - tx, qy - ty
            u = (cs * dx + ss * dy) * kk - ou
            v = (-ss * dx + cs * dy) * kk - ov
            inside = taken & (u >= 0) & (u < w) & (v >= 0) & (v < h)
            cell = torch.clamp(v, 0, h - 1).to(torch.int64) * w + torch.clamp(u, 0, w - 1).to(torch.int64)
            st = torch.where(inside, _gather(state, cell), torch.zeros_like(cell))
            seen = ((st == FREE) | (st == DEEP_FREE)) if per == "free" else st > 0
            n_free = seen.sum(dim=1).to(torch.float64)
            n_bad = (st == DEEP_FREE).sum(dim=1).to(torch.float64)
            out[sl] = torch.where(n_free > 0, n_bad / torch.clamp(n_free, min=1), torch.zeros_like(n_free)).cpu().numpy()
        return out
