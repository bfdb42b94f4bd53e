"""The BEV's storage: a fixed-size square of cells addressed by global integer cell
indices, which scrolls (content shifted, the part leaving dropped) when the sensor leaves a
box around its centre, so the cost of an update or a scroll never grows with session
length. Per cell: log-odds occupancy, wall evidence, hit count and the stamp of the frame
that last hit or freed it."""

from __future__ import annotations

import numpy as np


class ScrollingGrid:
    """Fixed-size square grid addressed by global integer cell indices (ix0, iy0 = cell (0, 0))."""

    def __init__(self, n: int, resolution: float):
        self.n = n
        self.res = resolution
        self.ix0 = self.iy0 = None
        self.logodds = np.zeros((n, n), dtype=np.float32)
        self.wall = np.zeros((n, n), dtype=np.uint16)
        self.hits = np.zeros((n, n), dtype=np.uint16)
        self.seen = np.zeros((n, n), dtype=np.int32)  # stamp of the last frame that hit or freed the cell (0: never)
        self.stamp = 0  # frames fused into this grid

    def centre_on(self, xy: np.ndarray, slack_cells: int) -> None:
        cx, cy = (int(np.floor(v / self.res)) for v in xy)
        half = self.n // 2
        if self.ix0 is None:
            self.ix0, self.iy0 = cx - half, cy - half
            return
        dx, dy = cx - half - self.ix0, cy - half - self.iy0
        if max(abs(dx), abs(dy)) <= slack_cells:
            return
        self.logodds = shifted(self.logodds, dy, dx)
        self.wall = shifted(self.wall, dy, dx)
        self.hits = shifted(self.hits, dy, dx)
        self.seen = shifted(self.seen, dy, dx)
        self.ix0 += dx
        self.iy0 += dy

    def forget_before(self, stamp: int) -> None:
        """Empty every cell no frame from this stamp on touched (hit or freed): what only
        older frames saw is gone, as if never seen."""
        old = self.seen < stamp
        for a in (self.logodds, self.wall, self.hits, self.seen):
            a[old] = 0

    def cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of the points inside the grid."""
        col = np.floor(xy[:, 0] / self.res).astype(np.int64) - self.ix0
        row = np.floor(xy[:, 1] / self.res).astype(np.int64) - self.iy0
        inside = (row >= 0) & (row < self.n) & (col >= 0) & (col < self.n)
        return row[inside], col[inside]

    def unique_flat(self, xy: np.ndarray, min_count: int = 1) -> np.ndarray:
        """Flat indices of the cells holding at least min_count of the points."""
        row, col = self.cells(xy)
        if min_count <= 1:
            return np.unique(row * self.n + col)
        flat, counts = np.unique(row * self.n + col, return_counts=True)
        return flat[counts >= min_count]


def shifted(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """out[r, c] = a[r + dy, c + dx], zero where that falls outside a."""
    out = np.zeros_like(a)
    h, w = a.shape
    src_r, dst_r = slice(max(dy, 0), min(h, h + dy)), slice(max(-dy, 0), min(h, h - dy))
    src_c, dst_c = slice(max(dx, 0), min(w, w + dx)), slice(max(-dx, 0), min(w, w - dx))
    if src_r.start < src_r.stop and src_c.start < src_c.stop:
        out[dst_r, dst_c] = a[src_r, src_c]
    return out


def increment(counts: np.ndarray, flat: np.ndarray) -> None:
    """counts.flat[flat] += 1, saturating (uint16)."""
    view = counts.reshape(-1)
    view[flat] = np.minimum(view[flat].astype(np.int64) + 1, np.iinfo(counts.dtype).max)
