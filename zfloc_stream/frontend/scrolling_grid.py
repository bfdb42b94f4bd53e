"""The BEV's storage: a fixed-size square of cells addressed by global integer cell
indices, which scrolls (content shifted, the part leaving dropped) when the sensor leaves a
box around its centre, so the cost of an update or a scroll never grows with session
length. Per cell: log-odds occupancy, wall evidence, hit count and the stamp of the frame
that last hit or freed it. The per-point passes of a fusion (distinct cells, a
neighbourhood test) are compiled: a frame's ~20,000 points otherwise cost a sort or a
gather of 169 cells each, in the stream's time."""

from __future__ import annotations

import math

import numpy as np

from ..errors import FrameError
from ..runtime.numba_support import njit

MAX_CELL = 2.0**52  # cell indices stay exact integers in float64 and far inside int64


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
        self._count = np.zeros(n * n, dtype=np.int32)  # scratch of unique_flat, all zero between calls

    def centre_on(self, xy: np.ndarray, slack_cells: int) -> None:
        if not all(math.isfinite(v) and abs(v / self.res) < MAX_CELL for v in xy):  # before any state changes
            raise FrameError(f"position {list(map(float, xy))} m is beyond the map's cells (|x| / resolution < 2^52); "
                             "frames bound their poses (frames.MAX_POSITION_M)")
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

    def unique_flat(self, xy: np.ndarray, min_count: int = 1) -> np.ndarray:
        """Flat indices (ascending) of the cells holding at least min_count of the points."""
        return _unique_cells(np.ascontiguousarray(xy, dtype=float), self.res, self.ix0, self.iy0, self.n,
                             max(int(min_count), 1), self._count)

    def open_without_wall_near(self, xy: np.ndarray, free_below: float, occupied_above: float, reach: int,
                               min_known: int) -> tuple[int, int]:
        """(cells some frame saw, hits among them on an open cell, logodds < free_below, with
        no cell above occupied_above within reach cells, a square): both 0 when fewer than
        min_known of the points land on seen cells."""
        return _open_without_wall_near(np.ascontiguousarray(xy, dtype=float), self.res, self.ix0, self.iy0,
                                       self.logodds, self.seen, np.float32(free_below), np.float32(occupied_above),
                                       int(reach), int(min_known))


@njit
def _cell(x, y, res, ix0, iy0, n):
    """(row, col) of a point, col -1 outside (cells' arithmetic: floor(v / res) - origin)."""
    col = np.int64(math.floor(x / res)) - ix0
    row = np.int64(math.floor(y / res)) - iy0
    if row < 0 or row >= n or col < 0 or col >= n:
        return 0, -1
    return row, col


@njit
def _unique_cells(xy, res, ix0, iy0, n, min_count, count):
    """np.unique of the flat cells of xy's inside points, kept where they hold min_count or
    more; count (n * n, zero) is scratch, zero again on return."""
    touched = np.empty(len(xy), dtype=np.int64)  # the inside points' cells, to reset the scratch
    flat = np.empty(len(xy), dtype=np.int64)
    k = m = 0
    for i in range(len(xy)):
        row, col = _cell(xy[i, 0], xy[i, 1], res, ix0, iy0, n)
        if col < 0:
            continue
        f = row * n + col
        touched[k] = f
        k += 1
        count[f] += 1
        if count[f] == min_count:  # each cell once, when it reaches min_count
            flat[m] = f
            m += 1
    count[touched[:k]] = 0
    return np.sort(flat[:m])


@njit
def _open_without_wall_near(xy, res, ix0, iy0, logodds, seen, free_below, occupied_above, reach, min_known):
    n = logodds.shape[0]
    rows = np.empty(len(xy), dtype=np.int64)  # the cells of the points on seen cells
    cols = np.empty(len(xy), dtype=np.int64)
    known = 0
    for i in range(len(xy)):
        row, col = _cell(xy[i, 0], xy[i, 1], res, ix0, iy0, n)
        if col >= 0 and seen[row, col] > 0:
            rows[known], cols[known] = row, col
            known += 1
    if known < min_known:
        return 0, 0
    lonely = 0
    for i in range(known):
        row, col = rows[i], cols[i]
        if not logodds[row, col] < free_below:
            continue
        near = False  # the window clipped to the grid, as a clipped index repeats the edge
        for r in range(max(row - reach, 0), min(row + reach, n - 1) + 1):
            for c in range(max(col - reach, 0), min(col + reach, n - 1) + 1):
                if logodds[r, c] > occupied_above:
                    near = True
                    break
            if near:
                break
        if not near:
            lonely += 1
    return known, lonely


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
