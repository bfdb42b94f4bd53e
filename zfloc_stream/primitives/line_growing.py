"""Line extraction by seeded region growing (primitives.extract_lines), compiled: the whole
seed loop in one kernel.

A random unused seed (the order: rng.permutation(n), drawn in Python) gives, by PCA on its
neighbourhood, an initial line; the line then collects every still-free point within
INLIER_DISTANCE of it that is connected to the seed along the line (no gap longer than
gap), is refitted by total least squares and grows again until its support stops
changing. Growth runs inside a local window first (most seeds end there: short fragments,
noise); only a line that reaches the window's rim regrows over all free points.

Neighbourhoods: the points are sorted once into grid cells (row-major, cell side
NEIGHBOURHOOD_RADIUS); a ball query visits only the grid rows and columns it can reach
(found by binary search, so its cost does not grow with the cloud) and tests each point
there as dx*dx + dy*dy <= r*r, so it returns the same points in the same order as a scan
of the whole cloud in grid order would. A line regrown over all free points reads only
the cells its band crosses (free_points_in_band), not the whole cloud, and taken points
are skipped by a flag instead of compacting the free list after every line: a 250 m plan
raster (577 k points) takes ~0.5 s instead of ~2 s.

Determinism: every sum runs in a fixed order (plain IEEE operations, no fastmath), so a
machine gives the same lines bit for bit run after run. Another machine (another libm
atan2) may differ in the last bits of a direction: the same lines (count, support, order)
unless a point sits within rounding of a threshold, coordinates within ~1e-12 m.
"""

from __future__ import annotations

import math

import numpy as np

from ..geometry.shapes import LineSet
from ..runtime.numba_support import njit

# |normal component| below which a band is treated as parallel to a grid axis (its
# interval along the other axis would be a division by ~0)
_SLANT = 1e-6

# The growing's inner tuning (were primitives.lines.*; every recorded result used these:
# the replay samples, eval_real, the benchmark scenes).
# They are in metres of the plane the points are in, sized for 0.05 m BEV and plan cells
# and walls 0.1-0.3 m thick; what a user tunes is which lines count (gap, min_points,
# min_length in the settings).
NEIGHBOURHOOD_RADIUS = 0.25  # m, PCA neighbourhood of a seed: ~5 cells each side, enough to give a wall's direction
MIN_SEED_NEIGHBOURS = 3  # a seed with fewer free points around it is noise (PCA of 2 points is any line through them)
LOCAL_RADIUS = 2.0  # m, a line first grows inside this window around its seed: most seeds end there (speed only)
INLIER_DISTANCE = 0.05  # m, orthogonal distance to grow a line: one cell, a wall face's rasterisation and range noise
MAX_GROW_ITERATIONS = 20  # refit/regrow rounds per seed; growth converges in 2-4, this only bounds a pathological one
CONVERGE_TOLERANCE = 0.001  # m, growth stops once a refit moves the line less than this (1/50 of a cell)

@njit
def _dot(x0, x1, y0, y1):
    """x . y for two 2-vectors."""
    return x0 * y0 + x1 * y1


@njit
def _pca_line(xy, idx, m):
    """Centroid and unit direction (cx, cy, dx, dy) of the total-least-squares line through
    the rows xy[idx[:m]]: the principal direction of the scatter matrix in closed form
    (a symmetric 2x2 matrix: faster than an eigensolver)."""
    sx = 0.0
    sy = 0.0
    for k in range(m):
        sx += xy[idx[k], 0]
        sy += xy[idx[k], 1]
    cx = sx / m
    cy = sy / m
    a = 0.0
    b = 0.0
    d = 0.0
    for k in range(m):
        qx = xy[idx[k], 0] - cx
        qy = xy[idx[k], 1] - cy
        a += qx * qx
        b += qx * qy
        d += qy * qy
    angle = 0.5 * math.atan2(2.0 * b, a - d)
    return cx, cy, math.cos(angle), math.sin(angle)


@njit
def _first_at_or_after(cell_y, cell_x, cy, cx):
    """First position in grid order whose cell (cell_y, cell_x) is not before (cy, cx)
    (row-major): a binary search over the sorted cells."""
    lo = 0
    hi = cell_y.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if cell_y[mid] < cy or (cell_y[mid] == cy and cell_x[mid] < cx):
            lo = mid + 1
        else:
            hi = mid
    return lo


@njit
def free_points_in_ball(grid, qx, qy, r2, taken, out):
    """Points within sqrt(r2) of (qx, qy) that are not taken, in the grid order (see the
    module docstring), written to out; returns their count. Only the grid rows and columns
    the ball can reach are visited (one cell of margin on each side absorbs the rounding of
    the cell arithmetic; every point is then tested exactly), each row's cells being one
    consecutive run of the grid order."""
    pos_xy, tree_index, cell_y, cell_x, grid_origin, cell, _ = grid
    r = math.sqrt(r2)
    x0 = math.floor((qx - r - grid_origin[0]) / cell) - 1
    x1 = math.floor((qx + r - grid_origin[0]) / cell) + 1
    y0 = max(math.floor((qy - r - grid_origin[1]) / cell) - 1, cell_y[0])
    y1 = min(math.floor((qy + r - grid_origin[1]) / cell) + 1, cell_y[cell_y.shape[0] - 1])
    count = 0
    for cy in range(y0, y1 + 1):
        start = _first_at_or_after(cell_y, cell_x, cy, x0)
        stop = _first_at_or_after(cell_y, cell_x, cy, x1 + 1)
        for k in range(start, stop):
            i = tree_index[k]
            if taken[i]:
                continue
            dx = pos_xy[k, 0] - qx
            dy = pos_xy[k, 1] - qy
            if dx * dx + dy * dy <= r2:
                out[count] = i
                count += 1
    return count


@njit
def free_points_in_band(grid, taken, nx, ny, cn, inlier, out):
    """Points p not taken with |n . p - cn| <= inlier (the band around a line, n its unit
    normal), sorted by index, written to out; returns their count. Only the cells the band
    can cross are visited: per grid row, the band's x-interval over the row's y-span (one
    cell of margin around both, for the rounding of the cell arithmetic), or the whole row
    for a nearly horizontal band; rows are limited to the band's y-interval over the
    cloud's x-extent for a band that is not nearly vertical. Each point is then tested
    exactly as a scan of every free point would test it."""
    pos_xy, tree_index, cell_y, cell_x, origin, cell, max_col = grid
    n = pos_xy.shape[0]
    lo_x = origin[0] - cell
    hi_x = origin[0] + (max_col + 2) * cell
    row_first = cell_y[0]
    row_last = cell_y[n - 1]
    if abs(ny) >= _SLANT:
        ya = (cn - inlier - nx * lo_x) / ny
        yb = (cn + inlier - nx * hi_x) / ny
        yc = (cn + inlier - nx * lo_x) / ny
        yd = (cn - inlier - nx * hi_x) / ny
        row_first = max(row_first, math.floor((min(ya, yb, yc, yd) - origin[1]) / cell) - 1)
        row_last = min(row_last, math.floor((max(ya, yb, yc, yd) - origin[1]) / cell) + 1)
    count = 0
    for row in range(row_first, row_last + 1):
        if abs(nx) >= _SLANT:
            y0 = origin[1] + (row - 1) * cell
            y1 = origin[1] + (row + 2) * cell
            xa = (cn - inlier - ny * y0) / nx
            xb = (cn - inlier - ny * y1) / nx
            xc = (cn + inlier - ny * y0) / nx
            xd = (cn + inlier - ny * y1) / nx
            first_col = max(math.floor((min(xa, xb, xc, xd) - origin[0]) / cell) - 1, 0)
            last_col = min(math.floor((max(xa, xb, xc, xd) - origin[0]) / cell) + 1, max_col)
            if first_col > last_col:
                continue
        else:
            first_col = 0
            last_col = max_col
        start = _first_at_or_after(cell_y, cell_x, row, first_col)
        stop = _first_at_or_after(cell_y, cell_x, row, last_col + 1)
        for k in range(start, stop):
            i = tree_index[k]
            if not taken[i] and abs(_dot(pos_xy[k, 0], pos_xy[k, 1], nx, ny) - cn) <= inlier:
                out[count] = i
                count += 1
    out[:count].sort()
    return count


@njit
def _grow(xy, pn, grid, taken, init_xy, init_idx, init_m, seed_x, seed_y, inlier, gap, max_iter, tol, rim, local):
    """The line grown from the rows init_xy[init_idx[:init_m]], anchored at the seed (the run
    of collinear points nearest it): the converged support (sorted row indices of xy), or
    an empty array when nothing grows. Converged: the support stopped changing, or the
    refit moved the line by less than tol over the support's extent. local: grow over the
    first pn rows of xy (a window around the seed) and stop, unconverged, once the support
    reaches farther than rim from the seed (the caller then regrows it); otherwise grow
    over every free point (xy: all points, their band found on the grid)."""
    none = np.empty(0, np.int64)
    cx, cy, dx, dy = _pca_line(init_xy, init_idx, init_m)
    previous = none
    cand = np.empty(pn, np.int64)
    t = np.empty(pn)
    for _ in range(max_iter):
        nx = -dy
        ny = dx
        cn = _dot(cx, cy, nx, ny)
        if local:
            nc = 0
            for k in range(pn):
                if abs(_dot(xy[k, 0], xy[k, 1], nx, ny) - cn) <= inlier:
                    cand[nc] = k
                    nc += 1
        else:
            nc = free_points_in_band(grid, taken, nx, ny, cn, inlier, cand)
        if nc < 2:
            return none
        cd = _dot(cx, cy, dx, dy)
        for k in range(nc):
            t[k] = _dot(xy[cand[k], 0], xy[cand[k], 1], dx, dy) - cd
        t_seed = _dot(seed_x - cx, seed_y - cy, dx, dy)
        # the run (consecutive spacing <= gap) of sorted t holding the value nearest
        # t_seed (a stable sort; order among ties cannot change the run, whose indices
        # are sorted below)
        order = np.argsort(t[:nc], kind="mergesort")
        ts = t[:nc][order]
        k = np.searchsorted(ts, t_seed)
        if k == 0:
            i = 0
        elif k == nc:
            i = nc - 1
        else:
            i = k - 1 if t_seed - ts[k - 1] <= ts[k] - t_seed else k
        if abs(ts[i] - t_seed) > gap:
            return none
        lo = i
        while lo > 0 and ts[lo] - ts[lo - 1] <= gap:
            lo -= 1
        hi = i
        while hi < nc - 1 and ts[hi + 1] - ts[hi] <= gap:
            hi += 1
        if hi - lo + 1 < 2:
            return none
        support = np.sort(cand[order[lo : hi + 1]])
        if len(support) == len(previous) and np.array_equal(support, previous):
            break
        previous = support
        t_lo = ts[lo]
        t_hi = ts[hi]
        if local and max(t_seed - t_lo, t_hi - t_seed) > rim:
            break
        ncx, ncy, ndx, ndy = _pca_line(xy, support, len(support))
        # largest displacement of the line over the support's extent after the refit
        shift = abs(_dot(ncx - cx, ncy - cy, nx, ny)) + 0.5 * (t_hi - t_lo) * abs(_dot(ndx, ndy, nx, ny))
        cx, cy, dx, dy = ncx, ncy, ndx, ndy
        if shift < tol:
            break
    return previous


@njit
def _extract(pts, perm, grid, r_neigh2, r_local2, min_seed, rim, inlier, gap, max_iter, tol, min_points, min_length):
    """The seed loop: (normals, offsets, endpoints, support) of the accepted lines in the
    order found (unsorted). grid: point_grid(pts, neighbourhood_radius)."""
    n = pts.shape[0]
    taken = np.zeros(n, np.bool_)
    tried = np.zeros(n, np.bool_)
    neigh = np.empty(n, np.int64)
    window = np.empty(n, np.int64)
    window_xy = np.empty((n, 2))
    normals = np.empty((n, 2))
    offsets = np.empty(n)
    ends = np.empty((n, 2, 2))
    counts = np.empty(n, np.int64)
    found = 0
    for seed in perm:
        if taken[seed] or tried[seed]:
            continue
        tried[seed] = True
        sx = pts[seed, 0]
        sy = pts[seed, 1]
        nn = free_points_in_ball(grid, sx, sy, r_neigh2, taken, neigh)
        if nn < min_seed:
            continue  # isolated point: noise
        nw = free_points_in_ball(grid, sx, sy, r_local2, taken, window)
        for k in range(nw):
            window_xy[k, 0] = pts[window[k], 0]
            window_xy[k, 1] = pts[window[k], 1]
        support = _grow(window_xy, nw, grid, taken, pts, neigh, nn, sx, sy, inlier, gap, max_iter, tol, rim, True)
        members = window[support]
        if len(support) > 0:
            reach = 0.0
            for i in members:
                ex = pts[i, 0] - sx
                ey = pts[i, 1] - sy
                reach = max(reach, ex * ex + ey * ey)
            if reach > rim * rim:  # reached the window's rim: regrow over all free points
                support = _grow(pts, n, grid, taken, pts, members, len(members), sx, sy, inlier, gap, max_iter, tol, rim,
                                False)
                members = support
        if len(support) == 0:
            tried[neigh[:nn]] = True  # nothing grows here: its neighbours would fail the same way
            continue
        m = len(members)
        cx, cy, dx, dy = _pca_line(pts, members, m)
        t_min = np.inf
        t_max = -np.inf
        for i in members:
            t = _dot(pts[i, 0] - cx, pts[i, 1] - cy, dx, dy)
            t_min = min(t_min, t)
            t_max = max(t_max, t)
        if m < min_points or t_max - t_min < min_length:
            tried[members] = True  # a fragment: stays free, seeds no more
            tried[neigh[:nn]] = True
            continue
        # canonical: the direction into the upper half plane, so the same wall gives the
        # same parameters whichever way it was grown
        if dy < 0 or (dy == 0 and dx < 0):
            dx, dy, t_min, t_max = -dx, -dy, -t_max, -t_min
        normals[found, 0] = -dy
        normals[found, 1] = dx
        offsets[found] = -_dot(-dy, dx, cx, cy)
        ends[found, 0, 0] = cx + t_min * dx
        ends[found, 0, 1] = cy + t_min * dy
        ends[found, 1, 0] = cx + t_max * dx
        ends[found, 1, 1] = cy + t_max * dy
        counts[found] = m
        found += 1
        taken[members] = True
    return normals[:found].copy(), offsets[:found].copy(), ends[:found].copy(), counts[:found].copy()


def point_grid(pts: np.ndarray, cell: float) -> tuple:
    """The points sorted into grid cells (row-major, side `cell`, from the points' minimum),
    then by index: (xy in that order, their indices, cell rows, cell columns, origin, cell,
    last column), what the ball and band queries read. Cells are int64 coordinates, no
    dense grid, so a sparse cloud over a large area costs nothing extra."""
    origin = pts.min(axis=0)
    cells = np.floor((pts - origin) / cell).astype(np.int64)
    order = np.lexsort((np.arange(len(pts)), cells[:, 0], cells[:, 1]))
    return (np.ascontiguousarray(pts[order]), order, np.ascontiguousarray(cells[order, 1]),
            np.ascontiguousarray(cells[order, 0]), origin, float(cell), int(cells[:, 0].max()))


def extract_lines(pts: np.ndarray, settings, rng: np.random.Generator) -> LineSet:
    """Lines of checked points pts (N, 2) (primitives.as_points), longest first; takes
    rng.permutation(n) from rng."""
    n = len(pts)
    if n < max(settings.min_points, 2):
        return LineSet.empty()
    pts = np.ascontiguousarray(pts, dtype=np.float64)
    perm = rng.permutation(n)
    s = settings
    normals, offsets, ends, support = _extract(
        pts, perm.astype(np.int64), point_grid(pts, NEIGHBOURHOOD_RADIUS),
        NEIGHBOURHOOD_RADIUS * NEIGHBOURHOOD_RADIUS, LOCAL_RADIUS * LOCAL_RADIUS, MIN_SEED_NEIGHBOURS,
        LOCAL_RADIUS - s.gap, INLIER_DISTANCE, s.gap, MAX_GROW_ITERATIONS, CONVERGE_TOLERANCE,
        s.min_points, s.min_length)
    if len(offsets) == 0:
        return LineSet.empty()
    lines = LineSet(normals, offsets, ends, support)
    return lines.subset(np.argsort(-lines.lengths, kind="stable"))
