"""Speed of line/circle extraction and floorplan construction (numbers, not asserts).

    python -m benchmarks.bench_primitives

Times are the best of --repeat runs in process CPU time. --quick: the smallest room grid,
a 10 x 10 m office, 10,000 distance queries, no Intel map.
"""

from __future__ import annotations

import time

import numpy as np

from zfloc_stream.settings.loading import Settings
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.primitives.extract import extract_circles, extract_lines
from zfloc_stream.sim.raycast2d import cast_rays
from zfloc_stream.runtime.rng import make_rng

from benchmarks.harness import Benchmark
from benchmarks.shared_data import SHARED_DATA

INTEL = SHARED_DATA / "sessions" / "intel-camera-30" / "map.yaml"


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


def main(argv=None) -> int:
    bench = Benchmark("primitives", __doc__, repeat=3)
    args = bench.parse(argv)
    grids, office_m, queries, intel = ((2, 3), (4, 3), (5, 4)), 50.0, 1_000_000, INTEL.is_file()
    if args.quick:
        grids, office_m, queries, intel, args.repeat = ((2, 3),), 10.0, 10_000, False, 1
    rng = np.random.default_rng(0)
    s = Settings()
    table = bench.table(["case", "size", ("cpu_ms", "CPU ms"), "result"])
    for nx, ny in grids:
        pts = bev_like_points(nx, ny, rng)
        dt, lines = timed(lambda: extract_lines(pts, s.primitives.lines, make_rng(0)), args.repeat)
        dc, circles = timed(lambda: extract_circles(pts, s.primitives.circles, make_rng(0)), args.repeat)
        table.add(case="extract_lines", size=f"{len(pts)} BEV-like points", cpu_ms=dt * 1e3, result=f"{len(lines)} lines", points=len(pts))
        table.add(case="extract_circles", size=f"{len(pts)} BEV-like points", cpu_ms=dc * 1e3, result=f"{len(circles)} circles", points=len(pts))
    occ = office_grid(office_m)
    dt, fp = timed(lambda: Floorplan.from_occupancy(occ, 0.05, (0, 0)), repeat=1)
    table.add(case="Floorplan.from_occupancy", size=f"office {office_m:g}x{office_m:g} m ({occ.shape[1]}x{occ.shape[0]} cells, "
              f"{occ.sum()} wall cells, {len(fp.face_points)} face cells)", cpu_ms=dt * 1e3, result=f"{len(fp.lines)} lines, {len(fp.circles)} circles")
    if intel:
        dt, fp = timed(lambda: Floorplan.load(INTEL), repeat=1)
        table.add(case="Floorplan.load", size=f"intel map ({fp.shape[1]}x{fp.shape[0]})", cpu_ms=dt * 1e3,
                  result=f"{len(fp.lines)} lines, {len(fp.circles)} circles")
    q = rng.uniform(-5, office_m + 5, (queries, 2))
    dd, _ = timed(lambda: fp.distance(q), args.repeat)
    table.add(case="Floorplan.distance", size=f"{queries:,} points", cpu_ms=dd * 1e3, result="")
    pose = (2.3, 3.1, 0.3) if args.quick else (12.3, 17.1, 0.3)
    big = Floorplan.from_occupancy(np.pad(occ, ((0, 0), (0, 0))), 0.05, (0, 0))
    dr, scan = timed(lambda: cast_rays(big, pose, 2 * np.pi, 10.0, 360), repeat=max(args.repeat, 10 * (not args.quick)))
    table.add(case="cast_rays", size=f"360 beams x 10 m on {big.shape[1]}x{big.shape[0]}", cpu_ms=dr * 1e3, result=f"{scan.hit_mask.sum()} hits")
    return bench.done()


if __name__ == "__main__":
    raise SystemExit(main())
