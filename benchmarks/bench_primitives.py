"""Speed of line/circle extraction and floorplan construction (numbers, not asserts).

    .venv/bin/python benchmarks/bench_primitives.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from zfloc_stream.settings.loading import Settings
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.primitives.extract import extract_circles, extract_lines
from zfloc_stream.sim.raycast2d import cast_rays
from zfloc_stream.runtime.rng import make_rng

ROOT = Path(__file__).resolve().parents[1]
INTEL = ROOT.parent / "shared" / "data" / "sessions" / "intel-camera-30" / "map.yaml"


def bev_like_points(n_rooms_x: int, n_rooms_y: int, rng, spacing=0.05, noise=0.015, outliers=0.05, pillars=True):
    """Wall points of a grid of 6 x 4 m rooms with doors (+ pillars, clutter)."""
    segs = []
    for i in range(n_rooms_x):
        for j in range(n_rooms_y):
            o = np.array([i * 6.5, j * 4.5])
            for a, b in (((0, 0), (6, 0)), ((6, 0), (6, 4)), ((6, 4), (3.5, 4)), ((2.5, 4), (0, 4)), ((0, 4), (0, 0))):
                segs.append((o + a, o + b))
    pts = []
    for a, b in segs:
        n = int(np.linalg.norm(np.subtract(b, a)) / spacing)
        t = np.arange(n)[:, None] / n
        pts.append(a + t * (np.subtract(b, a)))
    if pillars:
        for i in range(n_rooms_x):
            for j in range(n_rooms_y):
                ang = np.linspace(0, 2 * np.pi, 38, endpoint=False)
                pts.append(np.array([i * 6.5 + 3, j * 4.5 + 2]) + 0.3 * np.stack([np.cos(ang), np.sin(ang)], 1))
    p = np.concatenate(pts)
    p = p + rng.normal(0, noise, p.shape)
    k = int(outliers * len(p))
    return np.concatenate([p, rng.uniform(p.min(0), p.max(0), (k, 2))])


def timed(fn, repeat=3):
    """Best-of-repeat CPU time of this process (steadier than wall time on a shared machine)."""
    best = np.inf
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def office_grid(size_m=50.0, res=0.05, room=5.0, thickness=0.15, door=1.0):
    """A ~size_m x size_m office of room x room cells with doors: a (H, W) occupancy grid."""
    n = int(size_m / res)
    occ = np.zeros((n, n), dtype=bool)
    t = max(int(thickness / res), 1)
    step = int(room / res)
    d = int(door / res)
    for k in range(0, n, step):
        occ[k : k + t, :] = True
        occ[:, k : k + t] = True
    for k in range(0, n, step):  # a door in every wall between rooms
        for m in range(step // 2, n, step):
            occ[k : k + t, m : m + d] = False
            occ[m : m + d, k : k + t] = False
    occ[:t], occ[-t:], occ[:, :t], occ[:, -t:] = True, True, True, True
    # pillars in the middle of every other room
    yy, xx = np.mgrid[0:n, 0:n]
    for cy in range(step // 2, n, 2 * step):
        for cx in range(step // 2, n, 2 * step):
            occ |= np.hypot(xx - cx, yy - cy) <= 0.3 / res
    return occ


def main():
    rng = np.random.default_rng(0)
    s = Settings()
    for nx, ny in ((2, 3), (4, 3), (5, 4)):
        pts = bev_like_points(nx, ny, rng)
        dt, lines = timed(lambda: extract_lines(pts, s.primitives.lines, make_rng(0)))
        dc, circles = timed(lambda: extract_circles(pts, s.primitives.circles, make_rng(0)))
        print(f"BEV-like {len(pts):6d} points: extract_lines {dt * 1e3:7.1f} ms ({len(lines)} lines), "
              f"extract_circles {dc * 1e3:7.1f} ms ({len(circles)} circles)")
    occ = office_grid()
    dt, fp = timed(lambda: Floorplan.from_occupancy(occ, 0.05, (0, 0)), repeat=1)
    print(f"office 50x50 m ({occ.shape[1]}x{occ.shape[0]} cells, {occ.sum()} wall cells, {len(fp.face_points)} face cells): "
          f"construction {dt:.2f} s, {len(fp.lines)} lines, {len(fp.circles)} circles")
    if INTEL.is_file():
        dt, fp = timed(lambda: Floorplan.load(INTEL), repeat=1)
        print(f"intel map ({fp.shape[1]}x{fp.shape[0]}): construction {dt:.2f} s, {len(fp.lines)} lines, {len(fp.circles)} circles")
    q = rng.uniform(-5, 55, (1_000_000, 2))
    dd, _ = timed(lambda: fp.distance(q))
    print(f"Floorplan.distance: {dd * 1e3:.1f} ms per 1e6 points")
    big = Floorplan.from_occupancy(np.pad(occ, ((0, 0), (0, 0))), 0.05, (0, 0))
    dr, scan = timed(lambda: cast_rays(big, (12.3, 17.1, 0.3), 2 * np.pi, 10.0, 360), repeat=10)
    print(f"cast_rays 360 beams x 10 m on {big.shape[1]}x{big.shape[0]}: {dr * 1e3:.2f} ms ({scan.hit_mask.sum()} hits)")


if __name__ == "__main__":
    main()
