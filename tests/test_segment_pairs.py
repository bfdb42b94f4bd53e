"""segment_pairs.py: the neighbour lists and the duplicate rule without (N, N) matrices
give exactly what the matrices gave (the old implementations kept here as references), on
random segment sets of the kinds plans hold, and a large plan's lists cost its pairs, not N^2."""

from __future__ import annotations

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.geometry.shapes import LineSet
from zfloc_stream.geometry.segment_pairs import deduplicate_lines, segment_neighbours


def _segment_distances(a0, a1, b0, b1):
    """floorplan._segment_distances as it was (the reference)."""

    def point_to_segment(p, s0, s1):
        d = s1 - s0
        t = np.clip(np.sum((p - s0) * d, axis=-1) / np.maximum(np.sum(d * d, axis=-1), 1e-18), 0.0, 1.0)
        return np.linalg.norm(p - (s0 + t[..., None] * d), axis=-1)

    dist = np.minimum.reduce([point_to_segment(a0, b0, b1), point_to_segment(a1, b0, b1), point_to_segment(b0, a0, a1), point_to_segment(b1, a0, a1)])

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    da, db = a1 - a0, b1 - b0
    c1, c2 = cross(da, b0 - a0), cross(da, b1 - a0)
    c3, c4 = cross(db, a0 - b0), cross(db, a1 - b0)
    return np.where((c1 * c2 < 0) & (c3 * c4 < 0), 0.0, dist)


def _dense_neighbours(e, reach):
    """Floorplan.line_neighbour_matrix as it was: (N, N) bool."""
    n = len(e)
    lo, hi = e.min(axis=1), e.max(axis=1)
    near = np.zeros((n, n), dtype=bool)
    gap = np.maximum(lo[None, :, :] - hi[:, None, :], lo[:, None, :] - hi[None, :, :])
    rows, cols = np.nonzero(gap.max(axis=2) < reach * (1 + 1e-9) + 1e-9)
    near[rows, cols] = _segment_distances(e[rows, 0], e[rows, 1], e[cols, 0], e[cols, 1]) < reach
    np.fill_diagonal(near, False)
    return near


def _dense_deduplicate(lines, settings):
    """geometry.deduplicate_lines as it was: (m, m) matrices."""
    m = len(lines)
    if m < 2:
        return lines
    order = np.argsort(-lines.lengths, kind="stable")
    L = lines.subset(order)
    d = L.endpoints[:, 1] - L.endpoints[:, 0]
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    cos_limit = np.cos(np.deg2rad(settings.dedup_angle_deg))
    mid = L.midpoints
    t_i0 = np.einsum("ij,ij->i", L.endpoints[:, 0], d)
    t_i1 = np.einsum("ij,ij->i", L.endpoints[:, 1], d)
    lo_i, hi_i = np.minimum(t_i0, t_i1)[:, None], np.maximum(t_i0, t_i1)[:, None]
    parallel = np.abs(d @ d.T) >= cos_limit
    close = np.abs(mid @ L.normals.T + L.offsets[None, :]).T < settings.dedup_offset
    pj0, pj1 = L.endpoints[:, 0] @ d.T, L.endpoints[:, 1] @ d.T
    lo_j, hi_j = np.minimum(pj0, pj1).T, np.maximum(pj0, pj1).T
    overlap = (np.minimum(hi_i, hi_j) - np.maximum(lo_i, lo_j)) > 0
    dup = np.triu(parallel & close & overlap, 1)
    keep = np.ones(m, dtype=bool)
    for i in np.flatnonzero(dup.any(axis=1)):
        if keep[i]:
            keep &= ~dup[i]
    return L.subset(np.flatnonzero(keep))


def _plan_segments(rng, n, side):
    """Walls on a grid, in pieces, some doubled (two faces), some diagonal, some tiny."""
    kind = rng.integers(0, 4, n)
    p = rng.uniform(0, side, (n, 2))
    p[kind == 0, 1] = np.round(p[kind == 0, 1] / 2) * 2 + rng.choice([0, 0.1, 0.3], (kind == 0).sum())  # horizontal walls, faces
    p[kind == 1, 0] = np.round(p[kind == 1, 0] / 2) * 2
    angle = np.where(kind == 0, 0.0, np.where(kind == 1, np.pi / 2, rng.uniform(0, np.pi, n)))
    angle += np.where(rng.random(n) < 0.3, rng.normal(0, 0.03, n), 0.0)
    length = np.where(kind == 3, rng.uniform(0.001, 0.3, n), rng.uniform(0.2, side / 2, n))
    q = p + np.c_[np.cos(angle), np.sin(angle)] * length[:, None]
    return np.stack([p, q], axis=1)


@pytest.mark.parametrize("seed", range(12))
def test_neighbour_lists_equal_the_dense_matrix(seed):
    rng = np.random.default_rng(seed)
    e = _plan_segments(rng, int(rng.integers(2, 400)), float(rng.uniform(5, 60)))
    reach = float(rng.choice([0.5, 2.0, 6.0]))
    dense = _dense_neighbours(e, reach)
    lists = segment_neighbours(e, reach)
    assert len(lists) == len(e)
    for i, nb in enumerate(lists):
        assert np.array_equal(nb, np.flatnonzero(dense[i])), i
        assert nb.dtype == np.int32


def test_neighbour_lists_at_the_reach_and_crossing():
    e = np.array([[[0, 0], [10, 0]], [[5, -5], [5, 5]], [[0, 6], [10, 6]], [[0, 12.5], [10, 12.5]], [[20, 0], [20, 0]]], float)
    lists = segment_neighbours(e, 6.0)
    dense = _dense_neighbours(e, 6.0)
    assert [list(nb) for nb in lists] == [list(np.flatnonzero(r)) for r in dense]
    assert list(lists[0]) == [1] and list(lists[1]) == [0, 2]  # 6.0 apart is not within 6.0; crossing is 0 apart
    assert segment_neighbours(np.zeros((0, 2, 2)), 6.0) == []


@pytest.mark.parametrize("seed", range(12))
def test_deduplicate_equals_the_dense_rule(seed):
    rng = np.random.default_rng(100 + seed)
    e = _plan_segments(rng, int(rng.integers(1, 500)) if seed < 2 else int(rng.integers(150, 500)), float(rng.uniform(5, 40)))
    e = e[np.linalg.norm(e[:, 1] - e[:, 0], axis=1) > 1e-6]
    settings = Settings().primitives.lines
    lines = LineSet.from_endpoints(e)
    if seed % 3 == 0:  # normals from a fit, a little off the ends' perpendicular (extracted lines)
        tilt = rng.normal(0, 0.01, len(e))
        c, s = np.cos(tilt), np.sin(tilt)
        normals = np.c_[c * lines.normals[:, 0] - s * lines.normals[:, 1], s * lines.normals[:, 0] + c * lines.normals[:, 1]]
        lines = LineSet(normals, -np.einsum("ij,ij->i", normals, e.mean(axis=1)), e)
    got, want = deduplicate_lines(lines, settings), _dense_deduplicate(lines, settings)
    assert np.array_equal(got.endpoints, want.endpoints) and np.array_equal(got.normals, want.normals)
    assert len(want) < len(lines) or seed < 2  # the rule had duplicates to drop


def test_a_large_scatter_costs_its_pairs_not_n_squared():
    """20,000 short lines in a 50 m square: (N, N) matrices would be 400 M cells each."""
    rng = np.random.default_rng(0)
    p = rng.uniform(0, 50, (20_000, 2))
    a = rng.uniform(0, np.pi, 20_000)
    e = np.stack([p, p + np.c_[np.cos(a), np.sin(a)] * rng.uniform(0.2, 1.0, 20_000)[:, None]], axis=1)
    lists = segment_neighbours(e, 1.0)
    k = np.array([len(nb) for nb in lists])
    assert 20 < k.mean() < 80  # ~ 20,000 x (pi + 2 x 0.6) / 2500
    sample = rng.choice(len(e), 50, replace=False)  # rows checked against the dense rule
    for i in sample:
        d = _segment_distances(e[i, 0][None], e[i, 1][None], e[:, 0], e[:, 1])
        lo, hi = e.min(axis=1), e.max(axis=1)
        gap = np.maximum(lo - hi[i], lo[i] - hi).max(axis=1)
        want = np.flatnonzero((d < 1.0) & (gap < 1.0 * (1 + 1e-9) + 1e-9))
        assert np.array_equal(lists[i], want[want != i])
    kept = deduplicate_lines(LineSet.from_endpoints(e), Settings().primitives.lines)
    assert 0 < len(kept) <= len(e)


@pytest.mark.filterwarnings("ignore:.*gives no units")
def test_line_only_dxf_fast_reader_equals_ezdxf(tmp_path, monkeypatch):
    """plan_readers._dxf_lines_only (the group codes read directly) gives ezdxf's geometry
    for a LINE-only drawing, in every unit, and hands anything else to ezdxf."""
    from benchmarks.inputs.hostile_plans import write_dxf
    from benchmarks.inputs.plan_bombs import dxf_pieces

    from zfloc_stream.plans.readers import dxf as plan_readers

    rng = np.random.default_rng(5)
    lines = [((float(a), float(b)), (float(c), float(d))) for a, b, c, d in rng.uniform(0, 2000, (300, 4))] + [((1, 1), (1, 1))]
    cases = [write_dxf(tmp_path / f"u{u}.dxf", lines, u) for u in (None, 0, 1, 4, 5, 6, 21)] + [dxf_pieces(tmp_path / "pieces.dxf", 2000, seed=1)]
    for path in cases:
        assert plan_readers._dxf_lines_only(path) is not None, path
        fast = plan_readers.read_dxf(path, None, None, None)
        monkeypatch.setattr(plan_readers, "_dxf_lines_only", lambda p: None)
        slow = plan_readers.read_dxf(path, None, None, None)
        monkeypatch.undo()
        assert len(fast.polylines) == len(slow.polylines) and not fast.rings and not fast.circles
        assert all(np.array_equal(a, b) for a, b in zip(fast.polylines, slow.polylines)), path
    # not LINE-only, paper space, a bad number, binary: ezdxf's
    assert plan_readers._dxf_lines_only(write_dxf(tmp_path / "c.dxf", lines[:3], 6, circles=[(5, 5, 0.3)])) is None
    paper = (tmp_path / "u6.dxf").read_text().replace("LINE\n8\nWALLS", "LINE\n67\n1\n8\nWALLS", 1)
    assert plan_readers._dxf_lines_only(write_dxf(tmp_path / "e.dxf", [], 6)) is None
    (tmp_path / "p.dxf").write_text(paper)
    assert plan_readers._dxf_lines_only(tmp_path / "p.dxf") is None
    write_dxf(tmp_path / "n.dxf", [((float("nan"), 0.0), (1.0, 1.0))] + lines[:3], 6)
    assert plan_readers._dxf_lines_only(tmp_path / "n.dxf") is None
    (tmp_path / "b.dxf").write_bytes(b"AutoCAD Binary DXF\r\n\x1a\x00")
    assert plan_readers._dxf_lines_only(tmp_path / "b.dxf") is None
