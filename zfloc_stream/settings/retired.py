"""Retired settings: algorithm-internal tuning that was once a setting and is now a named
constant next to the code that uses it (a person can hold the settings that remain).

Users' config files and session logs (every log carries its whole settings block, the
replay samples included) still name these keys. Reading them drops each retired key; one
whose value differs from the constant's is reported with one warning (the value is no
longer applied), so an old file keeps loading and nobody is misled about what ran.
A --set override (or any other settings dict) naming one is an error that says what the
value is now (loading._format_validation_error).

RETIRED: dotted key -> (the constant's value, "module:NAME" where the constant lives). The
settings layer may import nothing above it, so the value is written here as well;
tests/test_retired_settings.py checks that each one equals its constant, value and type.
"""

from __future__ import annotations

import warnings

RETIRED: dict[str, tuple[object, str]] = {
    # plans/raster_files.py: read by nothing while it was a setting (Gibson maps are 1 cm/px)
    "datasets.gibson.map_resolution": (0.01, "zfloc_stream.plans.raster_files:GIBSON_RESOLUTION"),
    # plans/floorplan.py
    "floorplan.wall_sample_spacing": (0.2, "zfloc_stream.plans.floorplan:WALL_SAMPLE_SPACING"),
    "floorplan.line_point_spacing": (0.025, "zfloc_stream.plans.floorplan:LINE_POINT_SPACING"),
    # primitives/line_growing.py
    "primitives.lines.neighbourhood_radius": (0.25, "zfloc_stream.primitives.line_growing:NEIGHBOURHOOD_RADIUS"),
    "primitives.lines.min_seed_neighbours": (3, "zfloc_stream.primitives.line_growing:MIN_SEED_NEIGHBOURS"),
    "primitives.lines.local_radius": (2.0, "zfloc_stream.primitives.line_growing:LOCAL_RADIUS"),
    "primitives.lines.inlier_distance": (0.05, "zfloc_stream.primitives.line_growing:INLIER_DISTANCE"),
    "primitives.lines.max_grow_iterations": (20, "zfloc_stream.primitives.line_growing:MAX_GROW_ITERATIONS"),
    "primitives.lines.converge_tolerance": (0.001, "zfloc_stream.primitives.line_growing:CONVERGE_TOLERANCE"),
    # primitives/point_groups.py, circle_fitting.py
    "primitives.circles.min_cluster_size": (10, "zfloc_stream.primitives.point_groups:MIN_CLUSTER_SIZE"),
    "primitives.circles.hdbscan_min_samples": (2, "zfloc_stream.primitives.point_groups:HDBSCAN_MIN_SAMPLES"),
    "primitives.circles.ransac_iterations": (100, "zfloc_stream.primitives.circle_fitting:RANSAC_ITERATIONS"),
    "primitives.circles.inlier_distance": (0.03, "zfloc_stream.primitives.point_groups:INLIER_DISTANCE"),
    "primitives.circles.min_inlier_ratio": (0.8, "zfloc_stream.primitives.circle_fitting:MIN_INLIER_RATIO"),
    "primitives.circles.min_coverage_deg": (120.0, "zfloc_stream.primitives.circle_fitting:MIN_COVERAGE_DEG"),
    "primitives.circles.max_gap_deg": (30.0, "zfloc_stream.primitives.circle_fitting:MAX_GAP_DEG"),
    "primitives.circles.min_span_deg": (90.0, "zfloc_stream.primitives.circle_fitting:MIN_SPAN_DEG"),
    "primitives.circles.group_link_distance": (0.15, "zfloc_stream.primitives.point_groups:GROUP_LINK_DISTANCE"),
    "primitives.circles.refit_rounds": (2, "zfloc_stream.primitives.circle_fitting:REFIT_ROUNDS"),
    "primitives.circles.refit_iterations": (10, "zfloc_stream.primitives.circle_fitting:REFIT_ITERATIONS"),
    # estimation/solvers/
    "estimator.solvers.normal_consistency": (0.95, "zfloc_stream.estimation.solvers.models:NORMAL_CONSISTENCY"),
    "estimator.solvers.scale_prior_ggd_shape": (4.0, "zfloc_stream.estimation.solvers.scale_prior:SCALE_PRIOR_GGD_SHAPE"),
    "estimator.solvers.parallel_angle_deg": (10.0, "zfloc_stream.estimation.solvers.models:PARALLEL_ANGLE_DEG"),
    "estimator.solvers.min_baseline": (0.3, "zfloc_stream.estimation.solvers.models:MIN_BASELINE"),
    "estimator.solvers.singular_tolerance": (1e-9, "zfloc_stream.estimation.solvers.models:SINGULAR_TOLERANCE"),
    "estimator.solvers.radius_tolerance": (0.5, "zfloc_stream.estimation.solvers.models:RADIUS_TOLERANCE"),
    # estimation/correlative.py, field_fit.py, ransac.py
    "estimator.correlative.direction_ratio": (0.3, "zfloc_stream.estimation.correlative:DIRECTION_RATIO"),
    "estimator.refine.huber_delta": (0.1, "zfloc_stream.estimation.field_fit:HUBER_DELTA"),
    "estimator.refine.initial_damping": (1e-3, "zfloc_stream.estimation.field_fit:INITIAL_DAMPING"),
    "estimator.refine.damping_factor": (10.0, "zfloc_stream.estimation.field_fit:DAMPING_FACTOR"),
    "estimator.refine.top_n": (10, "zfloc_stream.estimation.ransac:REFINED_HYPOTHESES"),
    # frontend/gravity.py
    "frontend.gravity.points_per_frame": (1000, "zfloc_stream.frontend.gravity:POINTS_PER_FRAME"),
    "frontend.gravity.ransac_iterations": (100, "zfloc_stream.frontend.gravity:RANSAC_ITERATIONS"),
    "frontend.gravity.inlier_distance": (0.03, "zfloc_stream.frontend.gravity:INLIER_DISTANCE"),
    "frontend.gravity.refine_iterations": (3, "zfloc_stream.frontend.gravity:REFINE_ITERATIONS"),
    "frontend.gravity.floor_height_smoothing": (0.2, "zfloc_stream.frontend.gravity:FLOOR_HEIGHT_SMOOTHING"),
    # frontend/wallmask.py
    "frontend.wall_mask.tau_d": (0.3, "zfloc_stream.frontend.wallmask:TAU_D"),
    "frontend.wall_mask.segment_gap": (0.1, "zfloc_stream.frontend.wallmask:SEGMENT_GAP"),
    "frontend.wall_mask.segment_gap_per_m": (0.01, "zfloc_stream.frontend.wallmask:SEGMENT_GAP_PER_M"),
    "frontend.wall_mask.min_forward_depth": (0.05, "zfloc_stream.frontend.wallmask:MIN_FORWARD_DEPTH"),
    # frontend/labeller.py
    "frontend.labeller.vertical_normal_max_z": (0.35, "zfloc_stream.frontend.labeller:VERTICAL_NORMAL_MAX_Z"),
    "frontend.labeller.bootstrap_min_below": (0.5, "zfloc_stream.frontend.labeller:BOOTSTRAP_MIN_BELOW"),
    # frontend/bev.py, bev_snapshot.py
    "bev.logodds_free": (-0.4, "zfloc_stream.frontend.bev:LOGODDS_FREE"),
    "bev.logodds_min": (-2.0, "zfloc_stream.frontend.bev:LOGODDS_MIN"),
    "bev.logodds_max": (3.5, "zfloc_stream.frontend.bev:LOGODDS_MAX"),
    "bev.min_wall_points_per_cell": (3, "zfloc_stream.frontend.bev:MIN_WALL_POINTS_PER_CELL"),
    "bev.free_margin": (0.1, "zfloc_stream.frontend.bev:FREE_MARGIN"),
    "bev.azimuth_bin_deg": (0.5, "zfloc_stream.frontend.bev:AZIMUTH_BIN_DEG"),
    "bev.trajectory_length": (10000, "zfloc_stream.frontend.bev:TRAJECTORY_LENGTH"),
    "bev.wall_min_observations": (1, "zfloc_stream.frontend.bev_snapshot:WALL_MIN_OBSERVATIONS"),
    "bev.crop_margin": (0.5, "zfloc_stream.frontend.bev_snapshot:CROP_MARGIN"),
    # frontend/scan_match.py
    "bev.scan_match_min_walls": (50, "zfloc_stream.frontend.scan_match:MIN_WALLS"),
    "bev.scan_match_max_points": (200, "zfloc_stream.frontend.scan_match:MAX_POINTS"),
    "bev.scan_match_max_evaluations": (15, "zfloc_stream.frontend.scan_match:MAX_EVALUATIONS"),
    "bev.scan_match_inlier_distance": (0.15, "zfloc_stream.frontend.scan_match:INLIER_DISTANCE"),
    "bev.scan_match_angle_step_deg": (0.5, "zfloc_stream.frontend.scan_match:ANGLE_STEP_DEG"),
    "bev.scan_match_min_gain": (0.2, "zfloc_stream.frontend.scan_match:MIN_GAIN"),
}


class RetiredSettingWarning(UserWarning):
    """A config file or a logged settings block set a retired key to another value than
    the constant that now holds it: the value is not applied."""


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _without(tree: dict, path: list[str]) -> tuple[dict, object, bool]:
    """(tree without the key at path, its value, whether it was there); copies only the
    dicts on the path, never changes the caller's."""
    head, *rest = path
    if head not in tree:
        return tree, None, False
    if not rest:
        return {k: v for k, v in tree.items() if k != head}, tree[head], True
    if not isinstance(tree[head], dict):
        return tree, None, False
    child, value, found = _without(tree[head], rest)
    return ({**tree, head: child}, value, True) if found else (tree, None, False)


def drop_retired(data: dict, source: str, logged: bool = False) -> dict:
    """`data` (a settings tree read from a file or a log) without the retired keys, and one
    RetiredSettingWarning per retired key whose value differs from its constant. logged:
    the tree is a session's logged settings (the replay runs with the constant instead)."""
    for key, (fixed, home) in RETIRED.items():
        data, value, found = _without(data, key.split("."))
        if not found or (value == fixed and not isinstance(value, bool)):
            continue
        constant = home.split(":")[1]
        if logged:
            text = f"{source}: the log set {key}={_short(value)}, now fixed at {fixed!r} ({constant}); the replay may differ"
        else:
            text = f"{source}: {key}={_short(value)} is ignored: no longer a setting, fixed at {fixed!r} ({constant})"
        warnings.warn(text, RetiredSettingWarning, stacklevel=2)
    return data
