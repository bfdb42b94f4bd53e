"""Camera walks through a scene's free space: plan, smooth, resample, orient.

Paths are planned by Dijkstra (scipy.sparse.csgraph) on a 0.1 m grid whose edge costs grow
near obstacles, so walks keep to the middle of corridors and doorways. The cell path is
smoothed with a Gaussian along its arc length (less where smoothing would cut a corner too
close to a wall), resampled at seeded steps, and oriented along the direction of motion
with a turn-rate limit and small seeded wiggles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ..errors import InputError
from ..geometry.sim2 import wrap_angle


@dataclass(frozen=True)
class WalkSettings:
    """How a simulated person/robot walks (scenario parameters, not algorithm ones)."""

    step_min: float = 0.3  # m per frame
    step_max: float = 0.5
    clearance: float = 0.3  # m, planned paths keep at least this far from obstacles
    centering: float = 0.5  # m, edge cost factor 1 + centering / clearance
    smoothing: float = 0.6  # m, Gaussian sigma along the path
    min_clearance: float = 0.2  # m, smoothed paths must keep this
    max_turn_deg: float = 35.0  # heading change per frame
    wiggle_deg: float = 4.0  # std of the heading wiggle
    wiggle_frames: float = 3.0  # correlation length of the wiggle (frames)


_PLAN_RES = 0.1  # m, planning grid


@dataclass(frozen=True)
class _PlanGrid:
    origin: np.ndarray
    shape: tuple[int, int]
    node: np.ndarray  # (H, W) node index or -1
    cells: np.ndarray  # (N, 2) row, col of every node
    graph: csr_matrix


def _plan_grid(scene, ws: WalkSettings) -> _PlanGrid:
    key = ("_plan_grid", ws.clearance, ws.centering)
    cached = scene.__dict__.get(key)
    if cached is not None:
        return cached
    factor = max(int(round(_PLAN_RES / scene.resolution)), 1)
    fine = scene.clearance
    h, w = fine.shape[0] // factor, fine.shape[1] // factor
    # clearance at the fine cell nearest each coarse cell centre
    clear = fine[factor // 2:h * factor:factor, factor // 2:w * factor:factor][:h, :w]
    ok = clear >= ws.clearance
    node = np.full((h, w), -1, dtype=np.int64)
    cells = np.argwhere(ok)
    node[ok] = np.arange(len(cells))
    rows, cols, weights = [], [], []
    for dr, dc in ((0, 1), (1, 0), (1, 1), (1, -1)):
        r0, r1 = max(0, -dr), h - max(0, dr)
        c0, c1 = max(0, -dc), w - max(0, dc)
        a = node[r0:r1, c0:c1]
        b = node[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
        both = (a >= 0) & (b >= 0)
        ca = clear[r0:r1, c0:c1][both]
        cb = clear[r0 + dr:r1 + dr, c0 + dc:c1 + dc][both]
        length = np.hypot(dr, dc) * _PLAN_RES
        weight = length * (1.0 + ws.centering / np.minimum(ca, cb))
        rows += [a[both], b[both]]
        cols += [b[both], a[both]]
        weights += [weight, weight]
    n = len(cells)
    graph = csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
    origin = np.asarray(scene.origin, dtype=float)
    out = _PlanGrid(origin, (h, w), node, cells, graph)
    scene.__dict__[key] = out  # scenes are immutable: safe to memoise
    return out


def _xy(point) -> str:
    """'(4.32, 4.78)': plain numbers in messages, not numpy reprs."""
    return "({:.2f}, {:.2f})".format(*(float(v) for v in np.asarray(point, dtype=float)[:2]))


def _nearest_node(pg: _PlanGrid, point) -> int:
    rc = np.floor((np.asarray(point, dtype=float) - pg.origin)[::-1] / _PLAN_RES).astype(int)
    d = np.abs(pg.cells - rc).max(axis=1)
    k = int(np.argmin(d))
    if d[k] > 10:  # more than a metre from any walkable cell
        raise InputError(f"point {_xy(point)} is not in the walkable space")
    return k


def plan_path(scene, start, goal, ws: WalkSettings = WalkSettings()) -> np.ndarray:
    """Shortest clearance-weighted path (K, 2) from start to goal (cell centres between the
    exact endpoints). Raises InputError when no path exists."""
    pg = _plan_grid(scene, ws)
    a, b = _nearest_node(pg, start), _nearest_node(pg, goal)
    dist, pred = dijkstra(pg.graph, indices=a, return_predecessors=True)
    if not np.isfinite(dist[b]):
        raise InputError(
            f"no walkable path from {_xy(start)} to {_xy(goal)}: openings need a clear width of at least "
            f"{2 * ws.clearance:.1f} m (walk clearance {ws.clearance:g} m each side): check the drawing's scale "
            "(--scale M_PER_UNIT) or widen the openings in the plan"
        )
    chain = [b]
    while chain[-1] != a:
        chain.append(pred[chain[-1]])
    rc = pg.cells[np.array(chain[::-1])]
    pts = pg.origin + (rc[:, ::-1] + 0.5) * _PLAN_RES
    return np.concatenate([[start], pts, [goal]])


def _resample_polyline(points: np.ndarray, spacing: float) -> np.ndarray:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] < 1e-9:
        return points[:1]
    t = np.linspace(0.0, s[-1], max(int(np.ceil(s[-1] / spacing)) + 1, 2))
    return np.stack([np.interp(t, s, points[:, 0]), np.interp(t, s, points[:, 1])], axis=1)


def smooth_path(scene, path: np.ndarray, ws: WalkSettings = WalkSettings()) -> np.ndarray:
    """Gaussian-smoothed dense path (0.05 m spacing) that keeps ws.min_clearance; the
    smoothing shrinks until it does (the raw path is kept where nothing else fits)."""
    spacing = 0.05
    dense = _resample_polyline(path, spacing)
    sigma = ws.smoothing / spacing
    while sigma >= 1.0:
        smooth = ndimage.gaussian_filter1d(dense, sigma, axis=0, mode="nearest")
        if (scene.clearance_at(smooth) >= ws.min_clearance).all():
            return smooth
        sigma /= 2.0
    return dense


def _sample_steps(points: np.ndarray, rng, ws: WalkSettings, n_max: int | None = None) -> np.ndarray:
    """Positions along a dense path, each a seeded straight-line step in [step_min,
    step_max] from the previous one (so turnarounds are stepped over, not crept along)."""
    n_max = n_max if n_max is not None else len(points) + 1
    out = [points[0]]
    cur, i = points[0], 0  # current position, lies on segment (i, i + 1)
    while len(out) < n_max:
        step = rng.uniform(ws.step_min, ws.step_max)
        ahead = points[i + 1:]
        far = np.nonzero(np.linalg.norm(ahead - cur, axis=1) >= step)[0]
        if len(far) == 0:
            break
        j = i + 1 + far[0]
        # the point on segment (j - 1, j) exactly `step` from cur: |a + f (b - a) - cur| = step
        a, b = points[j - 1], points[j]
        d, e = b - a, a - cur
        qa, qb, qc = d @ d, 2 * d @ e, e @ e - step * step
        f = (-qb + np.sqrt(max(qb * qb - 4 * qa * qc, 0.0))) / (2 * qa) if qa > 0 else 1.0
        cur = a + np.clip(f, 0.0, 1.0) * d
        out.append(cur)
        i = j - 1
    return np.asarray(out)


def _headings(positions: np.ndarray, rng, ws: WalkSettings) -> np.ndarray:
    """Direction of motion, turn-rate limited, plus a smooth seeded wiggle."""
    n = len(positions)
    if n == 1:
        return np.array([float(rng.uniform(-np.pi, np.pi))])
    d = np.diff(positions, axis=0)
    motion = np.arctan2(d[:, 1], d[:, 0])
    motion = np.concatenate([motion, motion[-1:]])
    max_turn = np.radians(ws.max_turn_deg)
    heading = np.empty(n)
    heading[0] = motion[0]
    for k in range(1, n):
        turn = float(wrap_angle(motion[k] - heading[k - 1]))
        heading[k] = heading[k - 1] + np.clip(turn, -max_turn, max_turn)
    noise = rng.normal(0.0, 1.0, n)
    if ws.wiggle_frames > 0 and n > 1:
        noise = ndimage.gaussian_filter1d(noise, ws.wiggle_frames, mode="reflect")
        noise /= max(noise.std(), 1e-9)
    return wrap_angle(heading + np.radians(ws.wiggle_deg) * noise)


def trajectory_through(scene, waypoints, rng: np.random.Generator, step: float | tuple[float, float] | None = None,
                       ws: WalkSettings = WalkSettings()) -> np.ndarray:
    """(N, 3) poses x, y, theta walking through the given (x, y) waypoints in order."""
    ws = _with_step(ws, step)
    pts = [np.asarray(p, dtype=float) for p in waypoints]
    if len(pts) < 2:
        raise InputError("trajectory_through needs at least two waypoints")
    legs = [plan_path(scene, a, b, ws) for a, b in zip(pts[:-1], pts[1:])]
    path = np.concatenate([legs[0]] + [leg[1:] for leg in legs[1:]])
    positions = _sample_steps(smooth_path(scene, path, ws), rng, ws)
    return np.column_stack([positions, _headings(positions, rng, ws)])


def random_free_point(scene, room, rng, min_clearance: float = 0.5) -> np.ndarray:
    """A random walkable point in a room, at least min_clearance from obstacles."""
    r0, r1, c0, c1 = scene.grid.window(room.x0, room.y0, room.x1, room.y1)
    sub = scene.clearance[r0:r1, c0:c1]
    cand = np.argwhere(sub >= min(min_clearance, sub.max()))
    i, j = cand[rng.integers(len(cand))]
    x, y = scene.grid.centres(np.array(r0 + i), np.array(c0 + j))
    return np.array([float(x), float(y)])


def random_walk(scene, rng: np.random.Generator, n_frames: int, step: float | tuple[float, float] | None = None,
                ws: WalkSettings = WalkSettings()) -> np.ndarray:
    """(n_frames, 3) poses of a walk from a random room through further random rooms."""
    if n_frames < 1:
        raise InputError(f"n_frames must be >= 1, got {n_frames}")
    ws = _with_step(ws, step)
    rooms = list(scene.rooms)
    current = rooms[rng.integers(len(rooms))]
    point = random_free_point(scene, current, rng)
    path = [point[None]]
    length, needed = 0.0, 1.15 * n_frames * ws.step_max + 2.0  # smoothing shortens a little
    for _ in range(1000):
        if length >= needed:
            break
        others = [r for r in rooms if r is not current]
        nxt = others[rng.integers(len(others))]
        goal = random_free_point(scene, nxt, rng)
        leg = plan_path(scene, point, goal, ws)[1:]
        length += float(np.linalg.norm(np.diff(np.vstack([path[-1][-1:], leg]), axis=0), axis=1).sum())
        path.append(leg)
        current, point = nxt, goal
    dense = smooth_path(scene, np.concatenate(path), ws)
    positions = _sample_steps(dense, rng, ws, n_max=n_frames)
    return np.column_stack([positions, _headings(positions, rng, ws)])


def _with_step(ws: WalkSettings, step) -> WalkSettings:
    if step is None:
        return ws
    lo, hi = (step, step) if np.isscalar(step) else step
    if not 0 < lo <= hi:
        raise InputError(f"step must be positive (min <= max), got {step}")
    return WalkSettings(**{**ws.__dict__, "step_min": float(lo), "step_max": float(hi)})
