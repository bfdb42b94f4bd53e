"""A synthetic solver workload for the draws and solvers (test_draws.py, test_threads.py):
BEV lines and a floorplan holding them among clutter, with degenerate lines in both."""

from types import SimpleNamespace

import numpy as np

from zfloc_stream.settings.loading import Settings
from zfloc_stream.estimation import correspondences
from zfloc_stream.geometry.shapes import CircleSet, LineSet


def draw_scene(seed, n_bev=24, clutter=150):
    """BEV lines and a floorplan holding them moved by one Sim(2) (normals of either
    sign) among clutter, with degenerate lines in both (exact axis normals, repeated
    normals: parallel samples, zero and huge offsets), random floorplan neighbours.
    Returns (BEV samples as models_3l / models_2l read them, FloorplanMatches)."""
    gen = np.random.default_rng(seed)
    a = gen.uniform(-np.pi, np.pi, n_bev)
    a[::2] = np.round(a[::2] / (np.pi / 2)) * (np.pi / 2)  # exact axis normals (cosines 0, +-1)
    bev_n = np.column_stack([np.cos(a), np.sin(a)])
    bev_n[-3:] = bev_n[0]  # repeated normals
    bev_d = gen.normal(0, 6, n_bev)
    bev_d[-2:] = [0.0, 1.7e308]
    theta, s, t = gen.uniform(-np.pi, np.pi), gen.uniform(0.9, 1.1), gen.normal(0, 5, 2)
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    moved = bev_n @ rot.T
    sign = np.where(gen.random(n_bev) < 0.5, -1.0, 1.0)
    c = gen.uniform(-np.pi, np.pi, clutter)
    fp_n = np.vstack([moved * sign[:, None], np.column_stack([np.cos(c), np.sin(c)])])
    with np.errstate(over="ignore"):
        fp_d = np.concatenate([(s * bev_d - moved @ t) * sign, gen.normal(0, 8, clutter)])
    n_fp = len(fp_d)
    fp_lines = LineSet(fp_n, fp_d, np.zeros((n_fp, 2, 2)))
    neighbours = [np.flatnonzero(gen.random(n_fp) < 0.06) for _ in range(n_fp)]
    neighbours = [nb[nb != i] for i, nb in enumerate(neighbours)]
    floorplan = SimpleNamespace(lines=fp_lines, circles=CircleSet.empty(), line_neighbours=neighbours)
    solvers = Settings().estimator.solvers
    fp = correspondences.FloorplanMatches(floorplan, solvers)
    bev_lines = LineSet(bev_n, bev_d, np.zeros((n_bev, 2, 2)))
    triplets = gen.integers(0, n_bev, (400, 3))
    pairs = gen.integers(0, n_bev, (300, 2))
    bev = SimpleNamespace(lines=bev_lines, alpha=correspondences.normal_angles(bev_lines), triplets=triplets, pairs=pairs,
                          triplet_p=correspondences.probabilities(gen.random(len(triplets))), pair_p=None)
    return bev, fp


def estimator_for(mode, fraction):
    cfg = Settings().estimator
    solvers = cfg.solvers
    if mode == "prior":  # the bounds localize sets at a prior of 1
        solvers = solvers.model_copy(update={"min_scale": 1 / 1.15, "max_scale": 1.15})
    return cfg.model_copy(update={"scale_mode": mode, "solvers": solvers,
                                  "ransac": cfg.ransac.model_copy(update={"match_fraction": fraction})})


def assert_same_bits(got, ref):
    assert got.shape == ref.shape and got.dtype == ref.dtype == np.float64
    assert np.array_equal(got.view(np.int64), ref.view(np.int64))  # -0.0 for +0.0 fails too
