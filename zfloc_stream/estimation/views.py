"""What the scores read: models applied to points, and one BEV observation as the scores
see it (BevView: the state of every cell, computed once per localization). Shared by the
compiled scorer (scoring.py) and the torch one (scoring_torch.py)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from ..observation import BevObservation

UNSEEN, FREE, DEEP_FREE, WALL = 0, 1, 2, 3  # BevView.state codes

# The floorplan's coarse grid (FloorplanScorer.coarse, uint8) codes "at least cap from any
# wall" as the top of the uint8 range; the codes below it quantise distances in [0, cap).
COARSE_FAR = 255


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
