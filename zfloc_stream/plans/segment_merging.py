"""Touching collinear wall pieces merged into one segment, in near-linear time and memory:
the merge rule runs in one compiled scan whose partner searches look only at segments
registered in a spatial hash near the segment at hand, so 10,000 pieces drawn on top of
each other, 100,000 short lines in a small square or a 200,000-point path cost a scan,
not a pairwise comparison (nor a k-d tree's millions of pairs).

The hash: every segment is registered in the cells (side `cell`) of sample points every
cell / 2 along its line, extended by `gap` past either end; a grown segment registers
the extension. A segment b can join a only with both ends within `offset` of a's line and
its extent within `gap` of a's, so b's ends lie within offset + cell / 4 of a sample of a
and of one of b's own: with cell >= 2.5 offset, b is registered in the 3 x 3 cells around
a sample of a (forward search), and a in the 3 x 3 cells around b's ends (backward)."""

from __future__ import annotations

import math

import numpy as np

from ..runtime.numba_support import njit


@njit
def _joins(segs, ia, ib, cos_tol, offset, gap):
    """Does segment ib join segment ia (parallel within the angle, both ends within offset
    of ia's line, extents along it touching up to gap)? The arithmetic of the vectorised
    test this replaces, operation for operation."""
    return _join_test(segs, ia, ib, cos_tol, offset, gap) == 1


@njit
def _join_test(segs, ia, ib, cos_tol, offset, gap):
    """1: ib joins ia (_joins). -1: it never will while ia only grows along its own line:
    its angle or its ends' offset fail by more than rounding can move them (ia's line is
    recomputed from its grown ends, which lie on it up to rounding: the margin is a
    micrometre and 1e-9 of the coordinates, the angle's 1e-9). 0: it does not join now
    (its extent, or too close to the limits to say)."""
    ax0, ay0, ax1, ay1 = segs[ia, 0, 0], segs[ia, 0, 1], segs[ia, 1, 0], segs[ia, 1, 1]
    bx0, by0, bx1, by1 = segs[ib, 0, 0], segs[ib, 0, 1], segs[ib, 1, 0], segs[ib, 1, 1]
    ex, ey = ax1 - ax0, ay1 - ay0
    na = math.sqrt(ex * ex + ey * ey)
    dx, dy = ex / na, ey / na
    fx, fy = bx1 - bx0, by1 - by0
    nb = math.sqrt(fx * fx + fy * fy)
    gx, gy = fx / nb, fy / nb
    cos = abs(dx * gx + dy * gy)
    if not cos >= cos_tol:
        return -1 if cos < cos_tol - 1e-9 else 0
    r0x, r0y, r1x, r1y = bx0 - ax0, by0 - ay0, bx1 - ax0, by1 - ay0
    off = max(abs(r0x * -dy + r0y * dx), abs(r1x * -dy + r1y * dx))
    if not off <= offset:
        reach = max(abs(ax0), abs(ay0), abs(ax1), abs(ay1), abs(bx0), abs(by0), abs(bx1), abs(by1))
        return -1 if off > offset + 1e-6 + 1e-9 * reach else 0
    tb0, tb1 = r0x * dx + r0y * dy, r1x * dx + r1y * dy
    ta0 = (ax0 - ax0) * dx + (ay0 - ay0) * dy
    ta1 = ex * dx + ey * dy
    if not (min(tb0, tb1) > max(ta0, ta1) + gap) and not (min(ta0, ta1) > max(tb0, tb1) + gap):
        return 1
    return 0


@njit
def _join_into(segs, ia, ib):
    """Segment ia extended along its own line over ib's extent (in place), with the
    arithmetic of the numpy code this replaces (its norm and products go through BLAS, as
    np.dot does here: the same roundings); returns ia's old start and direction, its old
    extent along them and the new one."""
    a0 = segs[ia, 0].copy()
    v = segs[ia, 1] - a0
    d = v / np.sqrt(np.dot(v, v))
    ta = np.dot(segs[ia] - a0, d)
    tb = np.dot(segs[ib] - a0, d)
    old_lo, old_hi = min(ta[0], ta[1]), max(ta[0], ta[1])
    lo = min(old_lo, min(tb[0], tb[1]))
    hi = max(old_hi, max(tb[0], tb[1]))
    segs[ia, 0] = a0 + lo * d
    segs[ia, 1] = a0 + hi * d
    return a0[0], a0[1], d[0], d[1], old_lo, old_hi, lo, hi


@njit
def _bucket(cx, cy, mask):
    h = (cx * 73856093) ^ (cy * 19349663)
    return h & mask


@njit
def _register(heads, rows, nexts, count, row, x0, y0, dx, dy, t0, t1, cell, mask, skip_first=False):
    """Register row in the cells of samples every cell / 2 along x0 + t (dx, dy), t in
    [t0, t1] (both ends included; with skip_first not in t0's cell, registered before);
    returns the new entry count and arrays (grown)."""
    n = max(int(math.ceil(abs(t1 - t0) / (0.5 * cell))), 1)
    last_cx, last_cy = np.int64(-(2 ** 62)), np.int64(-(2 ** 62))
    if skip_first:
        last_cx = np.int64(math.floor((x0 + t0 * dx) / cell))
        last_cy = np.int64(math.floor((y0 + t0 * dy) / cell))
    for s in range(n + 1):
        t = t0 + (t1 - t0) * s / n
        cx = np.int64(math.floor((x0 + t * dx) / cell))
        cy = np.int64(math.floor((y0 + t * dy) / cell))
        if cx == last_cx and cy == last_cy:
            continue
        last_cx, last_cy = cx, cy
        if count == len(rows):
            rows = np.concatenate((rows, np.empty(len(rows), np.int64)))
            nexts = np.concatenate((nexts, np.empty(len(nexts), np.int64)))
        b = _bucket(cx, cy, mask)
        rows[count] = row
        nexts[count] = heads[b]
        heads[b] = count
        count += 1
    return count, rows, nexts


@njit
def _gather_cell(heads, rows, nexts, alive, stamp, mark, cx, cy, mask, out, n_out, fixed_start, fixed_rows):
    """Rows registered in cell (cx, cy)'s bucket, not yet marked with stamp, into
    out[n_out:]: those of the fixed table (the first registrations, bucket by bucket in one
    array: a walk reads memory in order), then those of the linked one (registered since);
    entries of dead rows are unlinked from the linked table on the way."""
    b = _bucket(cx, cy, mask)
    for k in range(fixed_start[b], fixed_start[b + 1]):
        r = fixed_rows[k]
        if alive[r] and stamp[r] != mark:
            stamp[r] = mark
            if n_out == len(out):
                out = np.concatenate((out, np.empty(len(out), np.int64)))
            out[n_out] = r
            n_out += 1
    prev = -1
    e = heads[b]
    while e >= 0:
        r = rows[e]
        nxt = nexts[e]
        if not alive[r]:
            if prev < 0:
                heads[b] = nxt
            else:
                nexts[prev] = nxt
            e = nxt
            continue
        if stamp[r] != mark:
            stamp[r] = mark
            if n_out == len(out):
                out = np.concatenate((out, np.empty(len(out), np.int64)))
            out[n_out] = r
            n_out += 1
        prev = e
        e = nxt
    return out, n_out


@njit
def _gather(heads, rows, nexts, alive, stamp, mark, x, y, cell, mask, out, n_out, fixed_start, fixed_rows):
    """Rows registered in the 3 x 3 cells around (x, y), not yet marked with stamp, into
    out[n_out:] (_gather_cell)."""
    cx0 = np.int64(math.floor(x / cell))
    cy0 = np.int64(math.floor(y / cell))
    for ox in range(-1, 2):
        for oy in range(-1, 2):
            out, n_out = _gather_cell(heads, rows, nexts, alive, stamp, mark, cx0 + ox, cy0 + oy, mask, out, n_out, fixed_start, fixed_rows)
    return out, n_out


@njit
def _gather_along(heads, rows, nexts, alive, stamp, mark, x0, y0, dx, dy, t0, t1, cell, mask, out, n_out, fixed_start, fixed_rows, skip_first=False):
    """_gather around samples every cell / 2 along x0 + t (dx, dy), t in [t0, t1], once per
    cell (with skip_first not around t0's cell, gathered before). A cell of one sample's
    3 x 3 that an earlier sample's 3 x 3 covered is not walked again (neighbouring samples
    share most of theirs: the same rows, a third of the walks)."""
    n = max(int(math.ceil(abs(t1 - t0) / (0.5 * cell))), 1)
    seen_x = np.empty(n + 1, np.int64)
    seen_y = np.empty(n + 1, np.int64)
    n_seen = 0
    last_cx, last_cy = np.int64(-(2 ** 62)), np.int64(-(2 ** 62))
    for s in range(n + 1):
        t = t0 + (t1 - t0) * s / n
        x, y = x0 + t * dx, y0 + t * dy
        cx, cy = np.int64(math.floor(x / cell)), np.int64(math.floor(y / cell))
        if s == 0 and skip_first:
            last_cx, last_cy = cx, cy
            continue
        if cx == last_cx and cy == last_cy:
            continue
        last_cx, last_cy = cx, cy
        for ox in range(-1, 2):
            for oy in range(-1, 2):
                covered = False
                for k in range(n_seen):
                    if abs(cx + ox - seen_x[k]) <= 1 and abs(cy + oy - seen_y[k]) <= 1:
                        covered = True
                        break
                if not covered:
                    out, n_out = _gather_cell(heads, rows, nexts, alive, stamp, mark, cx + ox, cy + oy, mask, out, n_out, fixed_start, fixed_rows)
        seen_x[n_seen] = cx
        seen_y[n_seen] = cy
        n_seen += 1
    return out, n_out


@njit
def _direction(segs, i):
    ex, ey = segs[i, 1, 0] - segs[i, 0, 0], segs[i, 1, 1] - segs[i, 0, 1]
    length = math.sqrt(ex * ex + ey * ey)
    return ex / length, ey / length, length


@njit
def _merge_scan(segs, cos_tol, offset, gap, cell):
    """The merge rule in index order (see merge_collinear): returns the alive mask; segs
    is merged in place."""
    n = len(segs)
    size = 1
    while size < 4 * n:
        size *= 2
    mask = np.int64(size - 1)
    heads = np.full(size, -1, np.int64)
    rows = np.empty(16 * n + 16, np.int64)
    nexts = np.empty(16 * n + 16, np.int64)
    count = 0
    margin = gap + 0.5 * cell  # past either end: the reach of a join, and rounding
    for r in range(n):
        dx, dy, length = _direction(segs, r)
        count, rows, nexts = _register(heads, rows, nexts, count, r, segs[r, 0, 0], segs[r, 0, 1], dx, dy,
                                       -margin, length + margin, cell, mask)
    # the first registrations moved to one array, bucket by bucket (a 100,000-line scatter's
    # 1.2 M entries chased through a linked list were cache misses: ~2x slower); the
    # linked table keeps what is registered from here on
    fixed_start = np.zeros(size + 1, np.int64)
    fixed_rows = np.empty(count, np.int64)
    at = 0
    for b in range(size):
        fixed_start[b] = at
        e = heads[b]
        while e >= 0:
            fixed_rows[at] = rows[e]
            at += 1
            e = nexts[e]
        heads[b] = -1
    fixed_start[size] = at
    count = 0
    no_start = np.zeros(size + 1, np.int64)
    no_rows = np.empty(0, np.int64)
    # rows the scan has passed (the only ones a backward search can find), registered as
    # the scan leaves them: a backward search does not wade through the rows ahead
    heads_back = np.full(size, -1, np.int64)
    rows_back = np.empty(16 * n + 16, np.int64)
    nexts_back = np.empty(16 * n + 16, np.int64)
    count_back = 0
    alive = np.ones(n, np.bool_)
    stamp = np.full(n, -1, np.int64)  # forward candidates of row i: gathered once each
    stamp_back = np.full(n, -1, np.int64)
    mark = 0
    mark_back = 0
    cand = np.empty(64, np.int64)
    back = np.empty(64, np.int64)
    i = 0
    resume = 0  # the scan's furthest row: every live row before it is done
    fresh = True  # cand must be gathered anew for row i
    n_cand = 0
    start = 0
    while i < n:
        if not alive[i]:
            i += 1
            fresh = True
            continue
        if fresh:
            mark += 1
            stamp[i] = mark
            dx, dy, length = _direction(segs, i)
            cand, n_cand = _gather_along(heads, rows, nexts, alive, stamp, mark, segs[i, 0, 0], segs[i, 0, 1], dx, dy,
                                         -margin, length + margin, cell, mask, cand, 0, fixed_start, fixed_rows)
            cand[:n_cand] = np.sort(cand[:n_cand])
            start = 0
            fresh = False
        hit = -1
        # the first later row that joins i; rows that never will (dead, earlier, at another
        # angle or offset: _join_test -1) leave i's candidates, so a row that grows by many
        # joins does not test its whole neighbourhood again after each (a dense scatter of
        # 100,000 short lines: 107 s -> ~1 s)
        w = start
        for k in range(start, n_cand):
            j = cand[k]
            if hit >= 0:
                cand[w] = j
                w += 1
            elif j > i and alive[j]:
                verdict = _join_test(segs, i, j, cos_tol, offset, gap)
                if verdict == 1:
                    hit = j
                elif verdict == 0:
                    cand[w] = j
                    w += 1
        n_cand = w
        if hit < 0:  # row i is done (until an absorption moves the scan back to it)
            dx, dy, length = _direction(segs, i)
            count_back, rows_back, nexts_back = _register(heads_back, rows_back, nexts_back, count_back, i, segs[i, 0, 0], segs[i, 0, 1],
                                                          dx, dy, -margin, length + margin, cell, mask)
            # the next row not yet scanned: rows between an absorber the scan moved back to
            # and the row it was at are done, and stay done (their later rows are as they
            # were, less the dead; a later row that grew was offered to them by the
            # backward search), so they are not scanned again (each move back cost a
            # rescan of every row in between: 107 s on a dense scatter of 100,000 lines)
            i = max(i + 1, resume)
            fresh = True
            continue
        before_join = segs[i].copy()
        x0, y0, dx, dy, old_lo, old_hi, lo, hi = _join_into(segs, i, hit)
        alive[hit] = False
        # whether an earlier row joins i depends on i's ends only: unchanged (a piece inside
        # i's extent), nothing earlier can join it now
        moved = (segs[i, 0, 0] != before_join[0, 0] or segs[i, 0, 1] != before_join[0, 1]
                 or segs[i, 1, 0] != before_join[1, 0] or segs[i, 1, 1] != before_join[1, 1])
        # the grown part: registered, and its neighbours become candidates of i
        before = n_cand
        if lo < old_lo:  # walked from the old end outward: its cell was registered and gathered
            count, rows, nexts = _register(heads, rows, nexts, count, i, x0, y0, dx, dy, old_lo - margin, lo - margin, cell, mask, True)
            cand, n_cand = _gather_along(heads, rows, nexts, alive, stamp, mark, x0, y0, dx, dy, old_lo - margin, lo - margin, cell, mask, cand, n_cand, fixed_start, fixed_rows, True)
        if hi > old_hi:
            count, rows, nexts = _register(heads, rows, nexts, count, i, x0, y0, dx, dy, old_hi + margin, hi + margin, cell, mask, True)
            cand, n_cand = _gather_along(heads, rows, nexts, alive, stamp, mark, x0, y0, dx, dy, old_hi + margin, hi + margin, cell, mask, cand, n_cand, fixed_start, fixed_rows, True)
        if n_cand > before:  # keep the live later rows, in order
            keep = 0
            for k in range(n_cand):
                if cand[k] > i and alive[cand[k]]:
                    cand[keep] = cand[k]
                    keep += 1
            n_cand = keep
            cand[:n_cand] = np.sort(cand[:n_cand])
            start = 0
        while moved and i > 0:  # an earlier row (which joined nothing before) may join the grown one now
            mark_back += 1
            n_back = 0
            for p in range(2):
                back, n_back = _gather(heads_back, rows_back, nexts_back, alive, stamp_back, mark_back, segs[i, p, 0], segs[i, p, 1], cell, mask, back, n_back, no_start, no_rows)
            first = -1
            if n_back:
                back[:n_back] = np.sort(back[:n_back])
                for k in range(n_back):
                    j = back[k]
                    if j >= i:
                        break
                    if _joins(segs, j, i, cos_tol, offset, gap):
                        first = j
                        break
            if first < 0:
                break
            x0, y0, dx, dy, old_lo, old_hi, lo, hi = _join_into(segs, first, i)
            alive[i] = False
            resume = max(resume, i + 1)
            i = first
            if lo < old_lo:
                count, rows, nexts = _register(heads, rows, nexts, count, i, x0, y0, dx, dy, lo - margin, old_lo - margin, cell, mask)
            if hi > old_hi:
                count, rows, nexts = _register(heads, rows, nexts, count, i, x0, y0, dx, dy, old_hi + margin, hi + margin, cell, mask)
            fresh = True
    return alive


def merge_collinear(segments: np.ndarray, angle_deg: float, offset: float, gap: float) -> np.ndarray:
    """Join segments lying on one line whose extents touch or overlap (up to gap apart):
    a wall drawn in pieces is one line, as it is when extracted from pixels.

    Rule: in index order, the first segment that joins a later one (parallel within
    angle_deg, both ends within offset of its line, extents up to gap apart) absorbs it,
    extended along its own line; then the first earlier segment that joins the grown one
    absorbs it, and so on; until nothing joins. Survivors keep their (first member's)
    order. Near-linear in the number of segments for drawings of walls (see the module)."""
    segs = np.ascontiguousarray(np.asarray(segments, dtype=float).reshape(-1, 2, 2))
    segs = segs[np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > 1e-9].copy()
    if len(segs) < 2:
        return segs
    cos_tol = math.cos(math.radians(angle_deg))
    # cells no finer than 2.5 offset (the hash's guarantee) and coarse enough that the
    # samples along all segments stay ~10 per segment whatever their lengths
    lengths = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    cell = max(2.5 * offset, float(lengths.sum() + 2 * gap * len(segs)) / (5.0 * len(segs)), 1e-9)
    alive = _merge_scan(segs, cos_tol, float(offset), float(gap), cell)
    return segs[alive]
