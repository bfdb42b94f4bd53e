import numpy as np
import pytest

from zfloc_stream.settings.loading import CircleSettings, LineSettings
from zfloc_stream.errors import InputError
from zfloc_stream.geometry.shapes import LineSet
from zfloc_stream.primitives.arc_checks import angular_coverage_and_span
from zfloc_stream.primitives.extract import deduplicate_lines, extract_circles, extract_lines, grid_subsample
from zfloc_stream.runtime.rng import make_rng

LINES = LineSettings()
CIRCLES = CircleSettings()


def sample_segments(segments, rng, spacing=0.05, noise=0.015):
    """Points every `spacing` along each segment ((x0, y0), (x1, y1)) + Gaussian noise."""
    out = []
    for a, b in segments:
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(int(np.linalg.norm(b - a) / spacing), 1)
        t = (np.arange(n) + rng.uniform(0, 1)) / n
        out.append(a + t[:, None] * (b - a))
    p = np.concatenate(out)
    return p + rng.normal(0.0, noise, p.shape)


def transform(segments, angle, shift):
    c, s = np.cos(angle), np.sin(angle)
    R = np.array([[c, -s], [s, c]])
    return [tuple(np.asarray(p, float) @ R.T + shift for p in seg) for seg in segments]


def room_walls(w=7.0, h=4.5):
    # a room with a door gap (0.9 m) in the top wall and an interior partition
    return [
        ((0, 0), (w, 0)),
        ((w, 0), (w, h)),
        ((w, h), (3.0, h)),
        ((2.1, h), (0, h)),
        ((0, h), (0, 0)),
        ((4.5, 0.8), (4.5, 3.0)),
    ]


def with_outliers(points, ratio, rng):
    lo, hi = points.min(axis=0) - 0.5, points.max(axis=0) + 0.5
    k = int(round(ratio * len(points)))
    return np.concatenate([points, rng.uniform(lo, hi, size=(k, 2))])


def recovered(lines: LineSet, seg, max_offset=0.05, max_angle_deg=2.0, min_cover=0.8) -> bool:
    a, b = (np.asarray(p, float) for p in seg)
    length = np.linalg.norm(b - a)
    u = (b - a) / length
    d = lines.endpoints[:, 1] - lines.endpoints[:, 0]
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    angle_ok = np.abs(d @ u) >= np.cos(np.deg2rad(max_angle_deg))
    # both wall ends are within max_offset of the (infinite) line
    off = np.maximum(np.abs(lines.normals @ a + lines.offsets), np.abs(lines.normals @ b + lines.offsets))
    # the segment extent covers most of the wall
    t = (lines.endpoints - a) @ u
    cover = (np.minimum(t.max(axis=1), length) - np.maximum(t.min(axis=1), 0.0)) / length
    return bool((angle_ok & (off < max_offset) & (cover >= min_cover)).any())


# --- lines ----------------------------------------------------------------------------------


@pytest.mark.parametrize("trial", range(8))
def test_room_walls_are_recovered_with_noise_and_outliers(trial):
    rng = np.random.default_rng(100 + trial)
    walls = transform(room_walls(), rng.uniform(-np.pi, np.pi), rng.uniform(-20, 20, 2))
    points = with_outliers(sample_segments(walls, rng, noise=rng.uniform(0.01, 0.02)), 0.1, rng)
    lines = extract_lines(points, LINES, make_rng(0, "lines", trial))
    for wall in walls:
        if np.linalg.norm(np.subtract(*wall)) > 1.0:
            assert recovered(lines, wall), wall
    assert len(lines) <= 2 * len(walls)  # no swarm of spurious fragments
    assert (lines.support >= LINES.min_points).all() and (lines.lengths >= LINES.min_length).all()
    assert np.allclose(np.linalg.norm(lines.normals, axis=1), 1.0)
    # endpoints lie on the line (normal form and extent agree)
    assert np.abs(np.einsum("nj,nkj->nk", lines.normals, lines.endpoints) + lines.offsets[:, None]).max() < 1e-9


def test_door_gap_splits_a_wall():
    rng = np.random.default_rng(5)
    walls = [((0, 0), (3, 0)), ((4, 0), (7, 0))]  # 1 m gap > settings.gap
    lines = extract_lines(sample_segments(walls, rng, noise=0.005), LINES, make_rng(0))
    assert len(lines) == 2
    assert all(recovered(lines, w) for w in walls)


def test_lines_are_deterministic_and_sorted():
    rng = np.random.default_rng(7)
    pts = with_outliers(sample_segments(room_walls(), rng), 0.1, rng)
    a = extract_lines(pts, LINES, make_rng(3, "x"))
    b = extract_lines(pts, LINES, make_rng(3, "x"))
    assert np.array_equal(a.endpoints, b.endpoints) and np.array_equal(a.support, b.support)
    assert np.all(np.diff(a.lengths) <= 1e-12)


def test_line_input_validation_and_empty():
    assert len(extract_lines(np.zeros((0, 2)), LINES, make_rng(0))) == 0
    assert len(extract_lines([], LINES, make_rng(0))) == 0
    assert len(extract_lines(np.zeros((3, 2)), LINES, make_rng(0))) == 0  # fewer than min_points
    with pytest.raises(InputError, match="NaN"):
        extract_lines(np.array([[0.0, 1.0], [np.nan, 2.0]]), LINES, make_rng(0))
    with pytest.raises(InputError, match="shape"):
        extract_lines(np.zeros((4, 3)), LINES, make_rng(0))
    with pytest.raises(InputError, match="NaN"):
        extract_circles(np.array([[np.inf, 1.0]] * 20), CIRCLES, make_rng(0))


def test_noise_only_gives_few_short_lines():
    rng = np.random.default_rng(11)
    pts = rng.uniform(0, 10, size=(800, 2))  # 8 points per m^2: no structure
    lines = extract_lines(pts, LINES, make_rng(0))
    assert len(lines) <= 2


def test_dedup_removes_a_near_duplicate_and_keeps_distinct_lines():
    ends = [
        ((0, 0), (5, 0)),  # long wall
        ((1, 0.08), (3, 0.1)),  # near-duplicate: 1 deg, 9 cm, overlapping
        ((6, 0.05), (8, 0.05)),  # same offset but no overlap: a different wall
        ((0, 1.0), (5, 1.0)),  # parallel, 1 m away
        ((2, -1), (2.1, 3)),  # crossing at 90 deg
    ]
    lines = LineSet.from_endpoints(ends)
    lines = LineSet(lines.normals, lines.offsets, lines.endpoints, np.full(len(ends), 50))
    out = deduplicate_lines(lines, LINES)
    assert len(out) == 4
    kept = {tuple(np.round(e.ravel(), 2)) for e in out.endpoints}
    assert (1.0, 0.08, 3.0, 0.1) not in kept and (0.0, 0.0, 5.0, 0.0) in kept
    # an anti-parallel copy (opposite normal) is a duplicate as well
    flipped = LineSet.from_endpoints([((0, 0), (5, 0)), ((4, 0.03), (1, 0.03))])
    assert len(deduplicate_lines(flipped, LINES)) == 1


def test_extract_then_dedup_on_thick_wall_faces():
    rng = np.random.default_rng(2)
    # two faces of a 10 cm thick wall are within dedup_offset: one line survives
    pts = sample_segments([((0, 0), (4, 0)), ((0, 0.1), (4, 0.1))], rng, noise=0.003)
    lines = deduplicate_lines(extract_lines(pts, LINES, make_rng(0)), LINES)
    assert len(lines) == 1


def test_grid_subsample():
    p = np.array([[0.0, 0.0], [0.01, 0.01], [0.2, 0.0], [0.21, 0.0]])
    assert np.array_equal(grid_subsample(p, 0.1), p[[0, 2]])


# --- circles --------------------------------------------------------------------------------


def arc(centre, radius, start, span, rng, spacing=0.05, noise=0.01):
    n = max(int(radius * span / spacing), 3)
    a = start + np.linspace(0, span, n)
    p = np.asarray(centre) + radius * np.stack([np.cos(a), np.sin(a)], axis=1)
    return p + rng.normal(0, noise, p.shape)


def test_coverage_and_span():
    a = np.deg2rad(np.arange(0, 181, 10))  # half circle in 10 deg steps
    cov, span = angular_coverage_and_span(a, np.deg2rad(30))
    assert np.isclose(np.rad2deg(cov), 180) and np.isclose(np.rad2deg(span), 180)
    # a 60 deg hole in the middle: coverage stays, contiguous span halves
    b = np.deg2rad(np.r_[np.arange(0, 61, 10), np.arange(120, 181, 10)])
    cov, span = angular_coverage_and_span(b, np.deg2rad(30))
    assert np.isclose(np.rad2deg(cov), 180) and np.isclose(np.rad2deg(span), 60)
    # wrap-around run across 0 deg
    c = np.deg2rad(np.r_[np.arange(300, 360, 10), np.arange(0, 41, 10)])
    cov, span = angular_coverage_and_span(c, np.deg2rad(30))
    assert np.isclose(np.rad2deg(span), 100) and np.isclose(np.rad2deg(cov), 100)


@pytest.mark.parametrize("trial", range(10))
def test_pillar_seen_over_half_its_arc_is_found(trial):
    rng = np.random.default_rng(200 + trial)
    centre = rng.uniform(-5, 5, 2)
    radius = rng.uniform(0.2, 0.6)
    span = np.deg2rad(rng.uniform(180, 360))
    pillar = arc(centre, radius, rng.uniform(0, 2 * np.pi), span, rng)
    # walls of the room around it, 2 m away, and scattered clutter
    room = [((0, 0), (8, 0)), ((8, 0), (8, 6)), ((8, 6), (0, 6)), ((0, 6), (0, 0))]
    walls = sample_segments(transform(room, 0.0, centre - (4, 3)), rng)
    pts = np.concatenate([pillar, walls])
    circles = extract_circles(pts, CIRCLES, make_rng(0, "circles", trial))
    assert len(circles) == 1
    assert np.linalg.norm(circles.centers[0] - centre) < 0.1
    assert abs(circles.radii[0] - radius) < 0.05


def test_two_pillars_and_a_small_one():
    rng = np.random.default_rng(9)
    pts = np.concatenate([
        arc((0, 0), 0.3, 0, 2 * np.pi, rng),
        arc((2, 0), 0.5, 1.0, np.pi, rng),
        arc((0, 3), 0.15, 0, 2 * np.pi, rng, spacing=0.04, noise=0.005),
    ])
    c = extract_circles(pts, CIRCLES, make_rng(0))
    assert len(c) == 3
    order = np.argsort(c.radii)
    assert np.allclose(c.radii[order], [0.15, 0.3, 0.5], atol=0.04)


def _no_pillar_scene(kind: str, rng) -> np.ndarray:
    angle, shift = rng.uniform(-np.pi, np.pi), rng.uniform(-5, 5, 2)
    noise = rng.uniform(0.005, 0.02)
    if kind == "wall":  # a straight wall fragment, short enough to pass the size filter
        segs = [((0, 0), (rng.uniform(0.4, 1.9), 0))]
    elif kind == "corner":  # a room corner seen as an L
        a, b = rng.uniform(0.4, 1.0, 2)
        segs = [((a, 0), (0, 0)), ((0, 0), (0, b))]
    elif kind == "u":  # a niche: three sides of a small box
        a, b = rng.uniform(0.4, 0.9, 2)
        segs = [((0, b), (0, 0)), ((0, 0), (a, 0)), ((a, 0), (a, b))]
    else:  # a small room without pillars, with clutter
        a, b = rng.uniform(2.0, 4.0, 2)
        segs = [((0, 0), (a, 0)), ((a, 0), (a, b)), ((a, b), (0, b)), ((0, b), (0, 0))]
    pts = sample_segments(transform(segs, angle, shift), rng, noise=noise)
    if kind == "room":
        pts = with_outliers(pts, 0.05, rng)
    return pts


def test_no_circle_on_walls_corners_and_rooms_over_100_trials():
    kinds = ["wall", "corner", "u", "room"]
    false_positives = []
    for trial in range(100):
        rng = np.random.default_rng(1000 + trial)
        kind = kinds[trial % len(kinds)]
        pts = _no_pillar_scene(kind, rng)
        c = extract_circles(pts, CIRCLES, make_rng(0, "fp", trial))
        if len(c):
            false_positives.append((trial, kind, c.radii.tolist()))
    assert not false_positives


def test_circle_empty_input():
    assert len(extract_circles(np.zeros((0, 2)), CIRCLES, make_rng(0))) == 0
    assert len(extract_circles(np.zeros((5, 2)), CIRCLES, make_rng(0))) == 0


# --- degenerate inputs of the compiled line extraction -----------------------------------


@pytest.mark.parametrize("n", [0, 1, 2, 7])
def test_too_few_points_give_no_line(n):
    lines = extract_lines(np.random.default_rng(3).uniform(0, 5, (n, 2)), LINES, np.random.default_rng(0))
    assert len(lines) == 0 and lines.normals.shape == (0, 2) and lines.endpoints.shape == (0, 2, 2)


def test_exactly_collinear_points_and_an_axis_aligned_line():
    gen = np.random.default_rng(5)
    x = np.sort(gen.uniform(0, 6, 300))
    line = np.stack([x, 0.5 * x + 1.0], axis=1)  # exactly collinear, with a gap wider than `gap`
    line = line[(x < 2.0) | (x > 2.5)]
    lines = extract_lines(line, LINES, np.random.default_rng(2))
    assert len(lines) == 2
    assert np.allclose(np.abs(lines.normals @ [-0.5, 1.0]) / np.hypot(0.5, 1.0), 1.0, atol=1e-9)
    axis = np.stack([x, np.zeros_like(x)], axis=1)  # on a coordinate axis: degenerate covariance
    lines = extract_lines(axis, LINES, np.random.default_rng(2))
    assert len(lines) == 1 and np.allclose(np.abs(lines.normals[0]), [0.0, 1.0]) and abs(lines.offsets[0]) < 1e-12


def test_sparse_noise_gives_no_line():
    pts = np.random.default_rng(9).uniform(0, 30, (200, 2))  # no seed has neighbours
    assert len(extract_lines(pts, LINES, np.random.default_rng(1))) == 0


def test_lines_are_bit_for_bit_repeatable_and_take_one_permutation():
    rng_points = np.random.default_rng(4)
    pts = sample_segments([((0, 0), (6, 0)), ((6, 0), (6, 4)), ((0, 4), (6, 4))], rng_points)
    a_rng, b_rng = np.random.default_rng(8), np.random.default_rng(8)
    a, b = extract_lines(pts, LINES, a_rng), extract_lines(pts, LINES, b_rng)
    for name in ("normals", "offsets", "endpoints", "support"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    c_rng = np.random.default_rng(8)
    c_rng.permutation(len(pts))
    assert a_rng.random() == c_rng.random()  # the seed order is the only draw


def test_no_circle_in_degenerate_or_too_wide_input():
    for pts in (np.zeros((0, 2)), np.zeros((5, 2)), np.zeros((30, 2)), np.ones((12, 2))):
        assert len(extract_circles(pts, CIRCLES, np.random.default_rng(0))) == 0
    long_wall = np.stack([np.arange(100) * 0.05, np.random.default_rng(3).normal(0, 0.01, 100)], axis=1)  # wider than a pillar
    assert len(extract_circles(long_wall, CIRCLES, np.random.default_rng(1))) == 0
    collinear = np.stack([np.arange(20) * 0.05, np.zeros(20)], axis=1)  # every triplet degenerate
    assert len(extract_circles(collinear, CIRCLES, np.random.default_rng(2))) == 0


def test_grid_queries_return_what_a_scan_of_every_free_point_returns():
    """The ball and band queries of line growing read only the grid cells they can reach;
    they must return exactly the free points a scan of the whole cloud finds (the ball's in
    grid order, the band's sorted by index), on clouds sparse over a large area, dense,
    and with bands parallel, nearly parallel and oblique to the grid axes."""
    from zfloc_stream.primitives.line_growing import free_points_in_ball, free_points_in_band, point_grid

    rng = make_rng(3, "grid-queries")
    for n, extent, cell in [(40, 300.0, 0.25), (3000, 12.0, 0.25), (2000, 5.0, 0.05), (500, 50.0, 1.5)]:
        pts = rng.uniform(-extent / 2, extent / 2, (n, 2)) + rng.uniform(-1e3, 1e3, 2)
        grid = point_grid(pts, cell)
        xy, index = grid[0], grid[1]
        taken = rng.uniform(size=n) < 0.3
        out = np.empty(n, np.int64)
        for _ in range(30):
            q = pts[rng.integers(n)] + rng.normal(0, cell, 2)
            r = float(rng.uniform(0.1, 3.0)) * cell * 4
            d2 = (xy[:, 0] - q[0]) ** 2 + (xy[:, 1] - q[1]) ** 2
            want = index[(d2 <= r * r) & ~taken[index]]
            got = out[: free_points_in_ball(grid, q[0], q[1], r * r, taken, out)]
            assert np.array_equal(got, want)
        for angle in [0.0, np.pi / 2, 1e-9, np.pi / 2 + 1e-9, 1e-5, 0.3, 2.0, np.pi]:
            normal = np.array([-np.sin(angle), np.cos(angle)])
            through = pts[rng.integers(n)]
            cn, inlier = float(normal @ through), float(rng.uniform(0.02, 0.5))
            dist = np.abs(pts[:, 0] * normal[0] + pts[:, 1] * normal[1] - cn)
            want = np.flatnonzero((dist <= inlier) & ~taken)
            got = out[: free_points_in_band(grid, taken, normal[0], normal[1], cn, inlier, out)]
            assert np.array_equal(got, want)
