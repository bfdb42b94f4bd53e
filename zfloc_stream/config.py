"""Typed settings: one pydantic model per stage, composed into Settings.

Every number the algorithm uses has a name here; configs/default.yaml is the dump of
these defaults (a test keeps the two identical). Unknown keys are errors, so a typo in a
config file fails loudly instead of being ignored.

Every setting carries its allowed range where it is declared (pydantic Field
constraints: gt/ge/lt/le on numbers, min_length on lists and strings; NaN and infinity
are refused everywhere), and pairs that must be ordered (min < max) are checked by
`ordered(...)` in their section. A value outside its range is one ConfigError line that
names the dotted key, the value and the allowed range. A new setting gets its bounds the
same way: `name: float = Field(default, gt=0, le=10)  # unit, meaning`.
"""

from __future__ import annotations

import re
import sys
import typing
import warnings
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError

from .documents import MAX_NESTING, TooDeep, load_yaml, text_number_hint, too_deep
from .errors import ConfigError

SolverName = Literal["3L", "2L", "2C", "LC"]
ScaleMode = Literal["free", "prior", "fixed"]

MAX_BEV_HALF_CELLS = 2000


def _numeric(annotation) -> bool:
    """Whether a field (or a list's item) annotation is int or float."""
    if typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    return annotation in (int, float)


def _number_problem(value) -> str | None:
    """Why a value given for a number setting is not one: pydantic would read True as 1,
    the text '5' as 5, and a subnormal float (4.9e-324) passes every `gt=0`."""
    if isinstance(value, bool):
        return "must be a number, not a boolean (true/false)"
    if isinstance(value, str):
        return f"must be a number, got text{text_number_hint(value)}: write the number itself"
    if isinstance(value, float) and value != 0 and abs(value) < sys.float_info.min:
        return f"is a subnormal number (below {sys.float_info.min:.3g}): no setting means anything that small"
    return None


class Section(BaseModel):
    # NaN or infinity is never a usable setting (a NaN threshold silently fails every comparison)
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def numbers_are_numbers(cls, data):
        """Number settings take numbers only: no booleans, no text, no subnormals."""
        if not isinstance(data, dict):
            return data
        for name, info in cls.model_fields.items():
            if name not in data:
                continue
            value, annotation = data[name], info.annotation
            if _numeric(annotation):
                problem = _number_problem(value)
            elif typing.get_origin(annotation) is list and _numeric(typing.get_args(annotation)[0]) and isinstance(value, list):
                problem = next((f"item {i} {p}" for i, p in ((i, _number_problem(v)) for i, v in enumerate(value)) if p), None)
            else:
                continue
            if problem is not None:
                raise section_rule_error(name, value, problem, ())
        return data


def section_rule_error(key: str, value: object, message: str, related: tuple[str, ...]) -> PydanticCustomError:
    """A cross-field rule broken in a section: `key` (the field reported) and the `related`
    fields named in `message` are spelled in full (dotted) by the error formatter."""
    return PydanticCustomError("section_rule", message, {"key": key, "value": value, "related": related})


def ordered(*pairs: tuple[str, str] | tuple[str, str, str]):
    """A section validator: for each (low, high) pair of field names, low < high
    (low <= high where the pair ends with "<=")."""

    def check(section):
        for low, high, *how in pairs:
            a, b = getattr(section, low), getattr(section, high)
            if not (a <= b if how == ["<="] else a < b):
                relation = "at most" if how == ["<="] else "less than"
                raise section_rule_error(low, a, f"must be {relation} {high} ({b})", (high,))
        return section

    return model_validator(mode="after")(check)


class LineSettings(Section):
    """Seeded region growing (paper 3.1)."""

    neighbourhood_radius: float = Field(0.25, gt=0, le=5)  # m, PCA neighbourhood of a seed
    min_seed_neighbours: int = Field(3, ge=2, le=1000)  # fewer free points around a seed: it is noise
    local_radius: float = Field(2.0, gt=0, le=100)  # m, a line first grows inside this window around its seed (speed)
    inlier_distance: float = Field(0.05, gt=0, le=1)  # m, orthogonal distance to grow a line
    gap: float = Field(0.3, gt=0, le=10)  # m, largest gap along a line before it is split
    max_grow_iterations: int = Field(20, ge=1, le=1000)  # refit/regrow rounds per seed (usually converges in 2-4)
    converge_tolerance: float = Field(0.001, gt=0, le=1)  # m, growth stops once a refit moves the line less than this
    min_points: int = Field(8, ge=2, le=100_000)
    min_length: float = Field(0.5, ge=0, le=100)  # m
    dedup_angle_deg: float = Field(5.0, ge=0, le=90)  # near-duplicate suppression
    dedup_offset: float = Field(0.15, ge=0, le=10)  # m


class CircleSettings(Section):
    """HDBSCAN clustering + 3-point RANSAC + angular checks (paper 3.1)."""

    min_cluster_size: int = Field(10, ge=2, le=100_000)
    hdbscan_min_samples: int = Field(2, ge=1, le=1000)  # small: a thin pillar ring has few points per neighbourhood (larger values drop arc points as noise)
    ransac_iterations: int = Field(100, ge=1, le=100_000)
    inlier_distance: float = Field(0.03, gt=0, le=1)  # m
    min_radius: float = Field(0.1, gt=0, le=10)  # m
    max_radius: float = Field(1.0, gt=0, le=10)  # m
    min_inlier_ratio: float = Field(0.8, ge=0, le=1)
    min_coverage_deg: float = Field(120.0, ge=0, le=360)  # 2*pi minus the largest angular gap
    max_gap_deg: float = Field(30.0, gt=0, le=360)  # angular continuity: consecutive gaps below this...
    min_span_deg: float = Field(90.0, ge=0, le=360)  # ...over a contiguous span at least this long
    group_link_distance: float = Field(0.15, gt=0, le=10)  # m, points closer than this are one group; groups wider than a pillar are skipped
    refit_rounds: int = Field(2, ge=0, le=100)  # least-squares refit + inlier re-selection rounds
    refit_iterations: int = Field(10, ge=1, le=1000)  # Gauss-Newton steps per refit

    _ordered = ordered(("min_radius", "max_radius"))


class PrimitiveSettings(Section):
    lines: LineSettings = LineSettings()
    circles: CircleSettings = CircleSettings()


class FloorplanSettings(Section):
    neighbour_distance: float = Field(6.0, gt=0, le=1000)  # m, lines closer than this are spatial neighbours (3L pruning)
    wall_sample_spacing: float = Field(0.2, gt=0, le=10)  # m, floorplan wall pixels used by Cv are subsampled to this (a ratio: 0.2 m is plenty, 16x cheaper than 0.05)
    line_point_spacing: float = Field(0.025, gt=0, le=10)  # m, wall-face pixels are subsampled to this before line extraction
    image_wall_threshold: float = Field(0.5, ge=0, le=1)  # plain images: occupancy (255 - v) / 255 above this is wall
    max_triplets: int = Field(2_000_000, ge=1, le=1_000_000_000)  # 3L table rows (~80 B each while built); a cluttered map past this keeps each line's nearest neighbours only (real maps: <= 0.5 M)
    # Memory budget of one plan, checked before anything is allocated: cells of its raster
    # (an image: read from the file's header), and cells of the estimator's search grid
    # over its extent (estimator.correlative.cell): a wrong resolution or unit blows that up.
    max_cells: int = Field(25_000_000, ge=1, le=2_000_000_000)


class SolverSettings(Section):
    pool: list[SolverName] = Field(["3L", "2L", "2C", "LC"], min_length=1)
    normal_consistency: float = Field(0.95, ge=0, le=1)  # tau_p: |cos(R n_i, n'_i)| required of the non-anchor lines (3L, 2L) before solving
    scale_prior_ggd_shape: float = Field(4.0, gt=0, le=100)  # 2L: generalised Gaussian noise on the metric scale
    scale_prior_prob: float = Field(0.8, gt=0, lt=1)  # P(|eps| <= scale_prior_window * s) = this
    scale_prior_window: float = Field(0.1, ge=0, le=1)
    min_scale: float = Field(0.5, gt=0, le=100)  # models outside [min_scale, max_scale] are discarded
    max_scale: float = Field(2.0, gt=0, le=100)
    prior_range: float = Field(0.15, gt=0, le=10)  # prior mode: scales outside prior * [1 / (1 + r), 1 + r] are discarded too (depth cameras and VIO: a few %; monocular depth networks: ~10 %)
    parallel_angle_deg: float = Field(10.0, ge=0, lt=90)  # lines closer than this in direction count as parallel (degenerate)
    min_baseline: float = Field(0.3, ge=0, le=100)  # m (BEV units): 2C centres, or an LC centre and its line, closer than this are degenerate
    singular_tolerance: float = Field(1e-9, gt=0, lt=1)  # relative determinant below which a linear solve is degenerate
    radius_tolerance: float = Field(0.5, gt=0, le=10)  # 2C/LC: model rejected when r_floorplan / (s r_bev) leaves [1/(1+x), 1+x]

    _ordered = ordered(("min_scale", "max_scale"))


class ScoringSettings(Section):
    tau_c: float = Field(0.1, gt=0, le=10)  # m, consistency threshold (paper)
    tau_v: float = Field(0.2, gt=0, le=10)  # m, violation threshold (paper)
    violation_weight: float = Field(1.0, ge=0, le=10)  # C = Cc - w * Cv (1 = the paper's C)
    # Cv's denominator: "free", the paper's (floorplan wall points landing in observed free
    # space), or "observed" (those landing in any observed cell, free or a BEV wall). Where
    # the map's walls mostly land on seen walls, as at the truth, the paper's denominator is
    # a handful of points (clutter, a door the map has closed) and Cv jumps to 0.4-0.6.
    violation_per: Literal["free", "observed"] = "free"
    sparse_spacing: float = Field(0.25, gt=0, le=10)  # m, spacing of BEV line samples for the coarse pass
    max_sparse_points: int = Field(128, ge=1, le=1_000_000)  # ...widened so the coarse pass uses about this many points at most
    top_k: int = Field(50, ge=1, le=100_000)  # hypotheses re-ranked with the full score
    distinct_translation: float = Field(0.5, ge=0, le=1000)  # m, hypotheses closer than this (and distinct_angle) are one
    distinct_angle_deg: float = Field(10.0, ge=0, le=180)
    chunk_size: int = Field(1_000_000, ge=1000, le=1_000_000_000)  # (hypotheses x points) elements per vectorised block: bounds memory
    wall_bucket_size: float = Field(2.0, ge=0.1, le=100)  # m, Cv fetches floorplan wall points by buckets of this size (speed only)
    # where the scores are computed: numpy, or torch (the [torch] extra; estimation/scoring_torch.py,
    # equal to numpy within one point per hypothesis) on scoring.device (auto: CUDA when present)
    backend: Literal["numpy", "torch"] = "numpy"
    device: str = "auto"


class RefineSettings(Section):
    huber_delta: float = Field(0.1, gt=0, le=10)  # m
    max_evaluations: int = Field(30, ge=1, le=10_000)  # residual evaluations per hypothesis (converges in ~10)
    top_n: int = Field(10, ge=1, le=1000)  # hypotheses refined (in one vectorised batch)
    max_points: int = Field(1000, ge=10, le=1_000_000)  # BEV wall points used by the refinement (evenly thinned)
    tolerance: float = Field(1e-4, gt=0, le=1)  # stop: relative cost decrease, step or gradient below this
    initial_damping: float = Field(1e-3, gt=0, le=1e6)  # Levenberg-Marquardt lambda at the start
    damping_factor: float = Field(10.0, gt=1, le=1000)  # lambda divided by this after a good step, multiplied after a bad one
    # m, residuals beyond this carry no weight (a truncated Huber loss): points of a room the
    # map lacks, or clutter, stop pulling the fit. 0: plain Huber (every point pulls).
    outlier_distance: float = Field(0.0, ge=0, le=100)


class RansacSettings(Section):
    iterations: int = Field(500, ge=1, le=1_000_000)  # BEV minimal samples per localization (solver drawn at random per sample)
    tracking_iterations: int = Field(150, ge=1, le=1_000_000)  # fewer fresh samples while one mode is tracked
    max_hypotheses: int = Field(10, ge=1, le=1000)  # ranked distinct hypotheses returned
    match_fraction: float = Field(0.03, gt=0, le=1)  # each BEV minimal sample meets this fraction (>= 1) of its pruned floorplan matches
    # guided samples near the live modes (warm start): BEV lines matched only to the
    # floorplan lines they lie on under a mode's alignment
    guided_iterations: int = Field(100, ge=0, le=1_000_000)  # per round, split over the guided modes
    guided_modes: int = Field(3, ge=0, le=100)  # the heaviest live modes sampled around
    guided_distance: float = Field(0.5, gt=0, le=100)  # m, a BEV segment's ends within this of a floorplan line match it
    guided_angle_deg: float = Field(10.0, gt=0, le=90)  # and its direction within this
    guided_shift: float = Field(2.0, gt=0, le=1000)  # m, translation change from the mode beyond which a guided model is dropped


class CorrelativeSettings(Section):
    """Exhaustive correlative seeding (estimation/correlative.py) at a known or prior scale:
    every rotation and translation on a coarse grid counted by BEV wall points near a
    floorplan wall; the best distinct placements are LM-refined and join the RANSAC pool.
    Minimal samples need the right line correspondences among thousands on a map built
    from scans; the exhaustive count does not, and costs one FFT correlation per angle."""

    enabled: bool = True  # runs in global rounds (not while confidently tracking), fixed or prior scale only
    cell: float = Field(0.25, ge=0.01, le=10)  # m, translation grid (and rasterisation of the BEV points)
    angle_step_deg: float = Field(4.0, ge=0.1, le=90)  # rotation grid
    tolerance: float = Field(0.3, gt=0, le=10)  # m, a point within this of a wall counts (coarse grid: about cell + LM basin)
    peaks: int = Field(10, ge=1, le=1000)  # distinct placements refined and added to the hypotheses
    # Rotations whose line-direction agreement with the floorplan (length-weighted
    # direction histograms, correlative.plausible_angles) is below this fraction of the
    # best rotation's are not searched: on a building whose walls run in two directions
    # most of the angle grid cannot put a wall on a wall. 0: search every angle.
    direction_ratio: float = Field(0.3, ge=0, le=1)


class EstimatorSettings(Section):
    # The hot loops of a round are compiled (numba) and have one implementation each, so
    # the former estimator.kernels (numpy | numba) chooses nothing: older configs and
    # session files that name it still load, with a FutureWarning, and it is dropped.
    @model_validator(mode="before")
    @classmethod
    def _drop_kernels(cls, data):
        if isinstance(data, dict) and "kernels" in data:
            data = {k: v for k, v in data.items() if k != "kernels"}
            warnings.warn("estimator.kernels is ignored: the compiled kernels are the only implementation "
                          "(remove it from the config)", FutureWarning, stacklevel=2)
        return data

    # prior: metric input (depth camera, VIO, depth network) known to about prior_range;
    # fixed: exactly metric (a laser; sources that know set it); free: any scale in
    # [min_scale, max_scale] (the paper's setting, on request).
    scale_mode: ScaleMode = "prior"
    scale_prior: float = Field(1.0, gt=0, le=100)  # expected BEV -> floorplan scale in prior mode (1 = both metric)
    solvers: SolverSettings = SolverSettings()
    correlative: CorrelativeSettings = CorrelativeSettings()
    scoring: ScoringSettings = ScoringSettings()
    refine: RefineSettings = RefineSettings()
    ransac: RansacSettings = RansacSettings()
    # Threads one round may use for its independent pieces (zfloc_stream/threads.py: the
    # correlative angles, the 3L draws, scoring and refining batches of hypotheses; the
    # compiled kernels only): the same bits with any count. 0 (auto): the cores this
    # process may use (at most threads.AUTO_MAX), less one for the stream when the round
    # runs on the worker beside it (localizer.pipeline: online once a pose exists, pipelined).
    threads: int = Field(0, ge=0, le=256)


class GravitySettings(Section):
    """Floor-plane fit (paper 3.1): the downward normal of the floor is gravity.

    Frames arriving before gravity is known wait in a bounded buffer; gravity is frozen
    once min_frames frames brought min_floor_points floor points, then the buffer is fused.
    """

    trust_odometry: bool = False  # VIO already gravity-aligned: take -z of odom as gravity
    min_floor_points: int = Field(300, ge=3, le=10_000_000)  # accumulated floor points needed before gravity is frozen
    min_frames: int = Field(2, ge=1, le=1000)  # frames contributing floor points before gravity is frozen
    points_per_frame: int = Field(1000, ge=3, le=10_000_000)  # floor points kept per frame (random subsample)
    max_points: int = Field(10000, ge=3, le=10_000_000)  # cap on accumulated floor points
    ransac_iterations: int = Field(100, ge=1, le=100_000)  # 3-point plane hypotheses
    inlier_distance: float = Field(0.03, gt=0, le=1)  # m, point-to-plane distance of a floor inlier
    refine_iterations: int = Field(3, ge=0, le=100)  # PCA re-fits on the inliers of the previous fit
    max_pending_frames: int = Field(20, ge=1, le=10_000)  # frames buffered while gravity is unknown (oldest dropped)
    floor_height_smoothing: float = Field(0.2, ge=0, le=1)  # EMA factor of a frame's floor height (tracks slow z drift)

    _ordered = ordered(("min_floor_points", "max_points", "<="))


class WallMaskSettings(Section):
    """Gravity-aligned column filter on the wall mask (paper eqs. 1-5)."""

    enabled: bool = True
    tau_d: float = Field(0.3, gt=0, le=10)  # m (paper's tau_d): a non-wall pixel deeper than median + tau_d drops the column
    segment_gap: float = Field(0.1, gt=0, le=10)  # m, depth gap that splits a column's wall pixels into segments...
    segment_gap_per_m: float = Field(0.01, ge=0, le=1)  # ...plus this much per metre of depth (noise grows with depth)
    min_forward_depth: float = Field(0.05, gt=0, le=10)  # m, points closer than this to the upright image plane are not warped


class LabellerSettings(Section):
    """Geometric labeller for frames without labels (gravity frame, depth normals)."""

    floor_tolerance: float = Field(0.08, gt=0, le=1)  # m, |height above floor| below this (and not vertical): floor
    vertical_normal_max_z: float = Field(0.35, gt=0, le=1)  # |n_z| below this: a vertical surface
    wall_min_height: float = Field(0.3, ge=0, le=10)  # m above floor, lower vertical surfaces are clutter ("other")
    ceiling_min_height: float = Field(1.8, gt=0, le=10)  # m above floor, non-vertical surfaces higher than this: ceiling
    normal_step: int = Field(2, ge=1, le=100)  # px, finite-difference step for depth normals
    max_tilt_deg: float = Field(35.0, gt=0, le=90)  # bootstrap: floor normal within this of the camera's up axis
    bootstrap_min_below: float = Field(0.5, ge=0, le=10)  # m, bootstrap floor candidates lie this far below the camera

    _ordered = ordered(("wall_min_height", "ceiling_min_height"))


class FrontendSettings(Section):
    gravity: GravitySettings = GravitySettings()
    wall_mask: WallMaskSettings = WallMaskSettings()
    labeller: LabellerSettings = LabellerSettings()
    pixel_stride: int = Field(0, ge=0, le=1000)  # camera pixels used: every pixel_stride-th row and column (0: automatic)...
    target_pixels: int = Field(12000, ge=1, le=100_000_000)  # ...automatic: stride = max(1, floor(sqrt(H * W / target_pixels)))
    max_depth: float = Field(10.0, gt=0, le=1000)  # m, depth readings beyond this are ignored
    min_obstacle_height: float = Field(0.1, ge=0, le=10)  # m above floor: lower non-floor points do not occupy
    max_obstacle_height: float = Field(2.0, gt=0, le=20)  # m above floor: higher points do not occupy (ceiling, lamps)

    _ordered = ordered(("min_obstacle_height", "max_obstacle_height"))


class BevSettings(Section):
    """Rolling log-odds BEV in the gravity-aligned odometry plane (scrolling fixed-size grid)."""

    resolution: float = Field(0.05, ge=0.01, le=1)  # m per cell
    window_radius: float = Field(15.0, gt=0, le=100)  # m, cells farther than this from the sensor are dropped
    recenter_distance: float = Field(1.0, ge=0, le=100)  # m, the grid scrolls when the sensor leaves this box around its centre
    logodds_hit: float = Field(0.85, gt=0, le=100)  # added to a cell holding an obstacle point (once per frame)
    logodds_free: float = Field(-0.4, ge=-100, lt=0)  # added to a cell crossed by a ray (once per frame)
    logodds_min: float = Field(-2.0, ge=-100, lt=0)  # clamp, so old evidence can be overturned
    logodds_max: float = Field(3.5, gt=0, le=100)
    free_threshold: float = Field(-0.3, ge=-100, le=100)  # log-odds below this: observed free space
    occupied_threshold: float = Field(0.0, ge=-100, le=100)  # log-odds above this: occupied
    wall_min_observations: int = Field(1, ge=1, le=1000)  # frames that saw wall evidence in a cell before it is a wall point
    wall_min_ratio: float = Field(0.5, ge=0, le=1)  # ...and at least this fraction of the frames that hit the cell
    min_wall_points_per_cell: int = Field(3, ge=1, le=10_000)  # camera: wall points one frame must put in a cell to count (laser: 1)
    free_margin: float = Field(0.1, ge=0, le=10)  # m, rays stop this short of the obstacle they hit
    azimuth_bin_deg: float = Field(0.5, ge=0.01, le=45)  # camera free space: one ray per azimuth bin
    crop_margin: float = Field(0.5, ge=0, le=100)  # m, observation is cropped to the known cells plus this margin
    trajectory_length: int = Field(10000, ge=1, le=1_000_000)  # plane poses kept (bounded memory)
    # Odometry drifts, so evidence fused long ago sits where the drifted poses put it: a
    # cell no frame touched (hit or ray) in the last memory_frames fused frames is left
    # out of the observation (unknown again). 0: the grid remembers everything it holds.
    # 300 (30 s at 10 Hz) changes nothing in a run of up to 300 frames (every evaluation
    # here); on a long walk it keeps the smeared walls of drifted passes out: on the
    # apartment walk (benchmarks/bench_localizer.py), frames 2,000-2,400, 335 -> 174 BEV
    # lines, median error 0.13-0.16 -> 0.04 m, round push 135 -> 45 ms (README, Speed).
    memory_frames: int = Field(300, ge=0, le=1_000_000)
    # Each frame's wall hits are matched to the BEV walls around them before they are fused
    # (frontend/scan_match.py): the odometry drift between frames is corrected, so the map
    # stays sharp. The correction applies to every later pose (plane_pose) as well. Which
    # frames: "laser" (default; a scan sees all around), "all" (cameras too: with their
    # narrow field of view and a perfect odometry it drifted 6.8 deg in 30 simulated frames,
    # so it is opt-in) or "none".
    scan_match: Literal["none", "laser", "all"] = "laser"
    scan_match_min_walls: int = Field(50, ge=3, le=1_000_000)  # BEV wall cells near the scan (and scan hits) needed to match
    scan_match_max_points: int = Field(200, ge=10, le=1_000_000)  # hits used (evenly thinned)
    scan_match_inlier_distance: float = Field(0.15, gt=0, le=10)  # m, a hit this close to a BEV wall is on it (the loss is cut at twice this)
    scan_match_max_shift: float = Field(0.3, gt=0, le=100)  # m, a larger correction in one frame is refused (odometry is good over one frame)
    scan_match_max_angle_deg: float = Field(5.0, gt=0, le=180)
    scan_match_min_gain: float = Field(0.2, ge=0, lt=1)  # a correction must lower the hits' robust cost by this fraction

    _ordered = ordered(("logodds_min", "logodds_max"), ("free_threshold", "occupied_threshold"))

    @model_validator(mode="after")
    def _bounded_grid(self):
        # the grid is a square of side 2 (window_radius + recenter_distance) / resolution
        # cells, 8 bytes each: at most MAX_BEV_HALF_CELLS per half side (4000^2 cells, 128 MB)
        half = (self.window_radius + self.recenter_distance) / self.resolution
        if half > MAX_BEV_HALF_CELLS:
            raise section_rule_error(
                "window_radius", self.window_radius,
                f"the grid would be {int(2 * half)} cells wide, at most {2 * MAX_BEV_HALF_CELLS}: "
                "(window_radius + recenter_distance) / resolution must stay below " + str(MAX_BEV_HALF_CELLS),
                ("window_radius", "recenter_distance", "resolution"),
            )
        return self


class TrackingSettings(Section):
    """Filter bank over the alignment, state anchored at the sensor (see tracking.py)."""

    # random-walk drift per round: variance grows with frames elapsed and metres travelled
    process_translation_std_per_frame: float = Field(0.01, ge=0, le=100)  # m per sqrt(frame), implied sensor position
    process_angle_deg_per_frame: float = Field(0.1, ge=0, le=180)  # deg per sqrt(frame)
    process_log_scale_per_frame: float = Field(0.001, ge=0, le=10)  # per sqrt(frame)
    process_translation_std_per_m: float = Field(0.05, ge=0, le=100)  # m per sqrt(m travelled)
    process_angle_deg_per_m: float = Field(1.0, ge=0, le=180)  # deg per sqrt(m travelled)
    process_log_scale_per_m: float = Field(0.01, ge=0, le=10)  # per sqrt(m travelled)
    # one refined RANSAC hypothesis, expressed at the sensor (also a new mode's covariance)
    measurement_translation_std: float = Field(0.15, gt=0, le=100)  # m
    measurement_angle_deg: float = Field(2.0, gt=0, le=180)
    measurement_log_scale: float = Field(0.02, gt=0, le=10)
    gate_chi2: float = Field(13.28, gt=0, le=1e6)  # Mahalanobis^2 gate, chi2(4 dof) at 99%
    # weights = softmax(weight_gain * running score); running score = EMA of fresh scores.
    # Every decision below compares modes with each other or with the round's best
    # hypothesis: score levels differ between map styles (0.8+ on clean plans, -0.5..0.45
    # on maps built from other passes), score differences mean the same everywhere.
    score_smoothing: float = Field(0.3, ge=0, le=1)  # EMA factor of a fresh score
    unobserved_penalty: float = Field(0.5, ge=0, le=10)  # a mode nothing matched this round: fresh = running score - this
    weight_gain: float = Field(15.0, ge=0, le=1000)
    # births, pruning, merging
    birth_score_gap: float = Field(0.15, ge=0, le=10)  # an unmatched hypothesis within this of the round's best starts a mode (the best always does)
    prune_weight: float = Field(0.001, ge=0, lt=1)
    max_modes: int = Field(8, ge=1, le=1000)
    merge_translation: float = Field(0.3, ge=0, le=100)  # m, implied sensor positions closer than this...
    merge_angle_deg: float = Field(5.0, ge=0, le=180)  # ...and headings closer than this...
    merge_log_scale: float = Field(0.05, ge=0, le=10)  # ...and log scales closer than this: one mode
    # status
    confirm_rounds: int = Field(2, ge=1, le=1000)  # rounds a mode was found near the top (within confirm_score_gap) before it can be tracked
    confirm_score_gap: float = Field(0.1, ge=0, le=10)  # "near the top": a fresh score within this of the round's best
    ambiguity_ratio: float = Field(0.5, gt=0, le=1)  # a second confirmed mode with weight >= this * best: ambiguous
    # tracking needs the best mode's share of the tracker's weight above this: 0.9 = its rivals
    # together hold under a tenth of it. At 0.5 (more than all rivals together) 2.9% of the
    # real laser windows' tracking frames were 1 m+ off (16 of 200 windows, rivals holding
    # 30-47%); at 0.9 0.4%, camera 0.2%, the same poses (docs/status.md).
    dominance_weight: float = Field(0.9, ge=0, lt=1)
    lost_score_gap: float = Field(0.1, ge=0, le=10)  # the tracked mode collapses in a round when a rival scores this much more (or nothing matches it)...
    lost_rounds: int = Field(3, ge=1, le=1000)  # ...this many rounds in a row: lost (the rival, if any, takes over)
    confident_rounds: int = Field(5, ge=1, le=10_000)  # rounds of tracking one mode before confidently_tracking


class LocalizerSettings(Section):
    every_k_frames: int = Field(5, ge=1, le=10_000)  # a RANSAC round every k fused frames
    min_wall_points: int = Field(100, ge=1, le=10_000_000)  # BEV wall cells needed before the first round
    min_primitives: int = Field(3, ge=1, le=1000)  # lines + circles needed before the first round
    # Per-frame consistency monitor: while tracking, each fused frame's wall points are
    # checked against the tracked alignment. A run of frames the map does not explain is
    # a part of the building the floorplan lacks, clutter, or an odometry jump; the
    # monitor cannot tell them apart on real sensors, so it never drops the track or the
    # BEV: it makes the next round a full global search, and the tracker decides from
    # relative evidence (a rival that explains the data better) whether the track is lost.
    monitor_distance: float = Field(0.3, gt=0, le=100)  # m, a wall point within this of a floorplan wall is consistent
    monitor_min_consistency: float = Field(0.05, ge=0, le=1)  # fraction of consistent points below which a frame is inconsistent (a jump gives ~0)
    monitor_min_points: int = Field(30, ge=1, le=1_000_000)  # frames with fewer wall points are not judged
    monitor_max_points: int = Field(400, ge=1, le=1_000_000)  # wall points checked per frame (subsampled)
    monitor_frames: int = Field(4, ge=1, le=10_000)  # consecutive inconsistent frames before a global search
    # local refinement: odometry drifts, so a BEV of many frames is a smeared picture and the
    # alignment that fits all of it can sit off where the sensor is now. After each round
    # (and every local_every_k_frames frames) the tracked mode's alignment is refined (LM,
    # its scale kept, a truncated Huber loss so walls the map lacks do not pull) on the wall
    # hits of the last local_frames frames alone, continuing from the last accepted local
    # fit; poses use it while it fits those hits at least as well.
    local_frames: int = Field(10, ge=0, le=10_000)  # 0: off
    local_max_step: float = Field(0.2, gt=0, le=1000)  # m per fused frame since the last local refinement: a refinement that moves the recent hits farther is refused (drift is slow)
    local_max_points: int = Field(2000, ge=10, le=1_000_000)  # recent hits used (subsampled)
    local_every_k_frames: int = Field(0, ge=0, le=10_000)  # also refine locally every k fused frames between rounds (0: after rounds only)
    local_outlier_distance: float = Field(0.0, ge=0, le=100)  # m, refine.outlier_distance of the local fit (0: plain Huber)
    # after each round, hand the allocator's free pages back to the OS (glibc malloc_trim,
    # ~2 ms; heap.py): without it resident memory drifts by tens of MB over long sessions
    release_memory: bool = True
    # Where a round runs (localizer.py). online (default, the Localizer API and `run`): a
    # round runs inline while no pose exists (the first pose lands at the frame whose round
    # finds it, as inline gives it) and, once there is a pose, on one worker beside the
    # stream, applied exactly join_delay frames later; whether a round is inline is decided
    # by the state at its start frame, so a run replays bit for bit. inline: inside the push
    # of the frame that starts it, applied at once (studies: offline, no latency to hide).
    # pipelined: every round on the worker, applied join_delay frames later (push blocks
    # there if the worker is late), so push costs about one fusion. delayed: computed inline
    # but applied join_delay frames later: bit for bit what pipelined gives, without a worker.
    pipeline: Literal["online", "inline", "pipelined", "delayed"] = "online"
    # frames from a round's start to its result (online / pipelined / delayed); 0 = every_k_frames.
    # 1: a round started at frame i is applied at frame i + 1, so a push blocks only when a
    # round takes longer than one frame interval (~50-90 ms against 100 ms at 10 Hz). With
    # every_k_frames (5) a correction landed 5 frames late and cost real-building and scene
    # windows at #20 / #35 / #100 (docs/kernels.md); at 1 no length is below inline.
    join_delay: int = Field(1, ge=0, le=10_000)
    worker: Literal["thread", "process"] = "thread"  # pipelined: where the round runs (a process has its own GIL, but pays start-up and copies)

    _ordered = ordered(("monitor_min_points", "monitor_max_points", "<="))

    @property
    def round_delay(self) -> int:
        """Frames between the start of a round and the frame its result is applied at (online:
        of the rounds that start once a pose exists; the others are inline)."""
        if self.pipeline == "inline":
            return 0
        return self.join_delay or self.every_k_frames


class LoggingSettings(Section):
    """MCAP session logs (zfloc_stream/session): what is written, how it is chunked, and
    how files from other tools are read. Never affects the estimates."""

    compression: Literal["zstd", "lz4", "none"] = "zstd"  # per-chunk compression
    chunk_size: int = Field(1048576, ge=1024, le=1 << 30)  # bytes; a chunk is closed once its records exceed this...
    # ...or once it holds this many complete frames (closed right after the frame's
    # estimate): what a killed process can lose besides the frame in flight. 1 measured
    # cheap (360-beam laser frames: +0.5 ms written and +19 % bytes per frame against 10;
    # 240x320 camera frames: no cost) and it loses nothing (benchmarks/bench_signals.py:
    # 10 kills, 0 frames lost; with 10, up to 8)
    chunk_max_frames: int = Field(1, ge=1, le=1_000_000)
    bev_every_n_frames: int = Field(10, ge=0, le=1_000_000)  # publish /zfloc/bev every n frames (0 = never)
    background: bool = True  # compress + write on a worker thread (the caller only serializes)
    max_pending_batches: int = Field(4, ge=1, le=10_000)  # batches (2 per frame) queued for the worker; a crash loses them too
    foreign_scan_range_min: float = Field(0.01, ge=0, le=1000)  # m, LaserScan without zfloc range metadata
    foreign_scan_range_max: float = Field(100.0, gt=0, le=10_000)  # m
    success_distance: float = Field(1.0, gt=0, le=1000)  # m, replay summary: SR@1m as in the paper...
    success_last_frames: int = Field(10, ge=1, le=1_000_000)  # ...every one of the final frames within the distance

    _ordered = ordered(("foreign_scan_range_min", "foreign_scan_range_max"))


class OdometrySettings(Section):
    """Synthetic odometry for logs whose poses are ground truth (Gibson(t), Carmen): the
    localizer only ever sees relative motion, re-expressed from a random odom origin."""

    # Per step (real wheel odometry / VIO): translation std per axis = noise * step length +
    # translation_floor, heading std = noise * (|turn| + heading_noise_per_m * step length) +
    # heading_floor_deg. noise 0 means the exact relative motion (the floors are off too).
    noise: float = Field(0.02, ge=0, le=1)  # drift fraction; real-data default (the issue-9 benchmark's model)
    heading_noise_per_m: float = Field(0.0, ge=0, le=10)  # rad per metre travelled, scaled by noise (heading drift from translation)
    translation_floor: float = Field(0.005, ge=0, le=10)  # m per axis per step, when noise > 0
    heading_floor_deg: float = Field(0.3, ge=0, le=90)  # deg per step, when noise > 0
    origin_extent: float = Field(50.0, ge=0, le=100_000)  # m, odom origin drawn uniformly in [-extent, extent]^2, heading uniform


class GibsonSettings(Section):
    """Gibson(t) (F3Loc release): 40 z-depths per frame become a small synthetic depth image.
    Camera and wall heights are not in the data; these are assumptions (documented in gibson.py)."""

    image_rows: int = Field(30, ge=1, le=10_000)  # synthesised rows for 40 columns (the 640x480 camera's aspect)
    focal_fraction: float = Field(0.375, gt=0, le=10)  # fx / image width (F3Loc's F_W): ~106 deg horizontal fov
    camera_height: float = Field(1.0, gt=0, le=10)  # m above the floor (assumed)
    wall_height: float = Field(2.6, gt=0, le=20)  # m, floor to ceiling (assumed)
    map_resolution: float = Field(0.01, ge=0.001, le=1)  # m per map.png pixel
    split: str = Field("test", min_length=1)  # split.yaml entry used when a spec names none

    _ordered = ordered(("camera_height", "wall_height"))


class CarmenSettings(Section):
    flaser_fov_deg: float = Field(180.0, gt=0, le=360)  # FLASER: n beams spread over this...
    flaser_start_deg: float = Field(-90.0, ge=-360, le=360)  # ...starting here (counter-clockwise from forward)
    max_range: float = Field(80.0, gt=0, le=1000)  # m, FLASER readings at or beyond this are no-returns (SICK reports 81.83)
    min_range: float = Field(0.01, ge=0, le=100)  # m, shorter readings are no-returns
    heldout_margin: int = Field(25, ge=0, le=1_000_000)  # scans: a study window's map leaves out [start - margin, stop + margin)

    _ordered = ordered(("min_range", "max_range"))


class MappingSettings(Section):
    """map-from-log: log-odds occupancy from scans with known poses."""

    resolution: float = Field(0.05, ge=0.01, le=10)  # m per cell
    logodds_hit: float = Field(0.85, gt=0, le=100)  # added to a cell holding a beam end (once per scan)
    logodds_free: float = Field(-0.4, ge=-100, lt=0)  # added to a cell crossed by a beam (once per scan)
    occupied_threshold: float = Field(0.0, ge=-100, le=100)  # log-odds above this: wall (more hit evidence than free)
    free_range: float = Field(15.0, gt=0, le=1000)  # m, beams (and no-returns) clear free space up to this range
    free_margin: float = Field(0.1, ge=0, le=10)  # m, a beam clears free space only up to this short of its return
    padding: float = Field(1.0, ge=0, le=1000)  # m of unknown margin around the mapped area


class SimDatasetSettings(Section):
    n_frames: int = Field(300, ge=1, le=1_000_000)  # frames simulated per built-in scene
    scene_seed: int = Field(0, ge=0, le=2**63 - 1)  # building layout (the walk and noise follow settings.seed)


class Ros2Settings(Section):
    """ROS 2 bags (rosbag2 MCAP, CDR messages) and sensors at their own rates (issue 13)."""

    max_odometry_gap: float = Field(0.5, gt=0, le=3600)  # s, a frame between two odometry/tf messages further apart than this is skipped


class VectorFloorplanSettings(Section):
    """DXF / SVG / GeoJSON floorplans: lines and circles come from the vectors; the
    occupancy raster (distance field, Cv) is drawn from them at this resolution."""

    resolution: float = Field(0.05, ge=0.005, le=10)  # m per raster cell
    wall_thickness: float = Field(0.1, gt=0, le=10)  # m, a wall drawn as a line is rasterised this thick
    solid_max_width: float = Field(0.6, ge=0, le=100)  # m, closed shapes narrower than this (2 area / perimeter) are solid (walls, columns); wider ones (rooms) are outlines
    margin: float = Field(1.0, ge=0, le=1000)  # m of free border around the drawing
    max_cells: int = Field(25_000_000, ge=1, le=1_000_000_000)  # larger rasters are refused (a wrong unit scale, usually)


class DatasetSettings(Section):
    ros2: Ros2Settings = Ros2Settings()
    vector_floorplan: VectorFloorplanSettings = VectorFloorplanSettings()
    odometry: OdometrySettings = OdometrySettings()
    gibson: GibsonSettings = GibsonSettings()
    carmen: CarmenSettings = CarmenSettings()
    mapping: MappingSettings = MappingSettings()
    sim: SimDatasetSettings = SimDatasetSettings()


class StudySettings(Section):
    """SR-vs-length studies (F3Loc protocol)."""

    eval_frames: int = Field(10, ge=1, le=1_000_000)  # success/RMSE look at this many final frames of a chunk
    thresholds: list[Annotated[float, Field(gt=0, le=1000)]] = Field([1.0, 0.5], min_length=1)  # m, success thresholds reported (<= counts as success)
    max_chunks_per_sequence: int = Field(20, ge=1, le=1_000_000)  # consecutive non-overlapping chunks kept per sequence and length
    connect_timeout_s: float = Field(10.0, gt=0, le=86_400)  # s, waiting for a remote dask scheduler (--scheduler)


class ReplaySettings(Section):
    """zfloc-replay --check: decisions (statuses, modes, hypothesis counts, skips) must
    match exactly; numbers within atol + rtol * max(|logged|, |replayed|), because another
    CPU or BLAS may change their last bits (--exact: bit for bit). Never affects the estimates."""

    # relative tolerance on logged numbers: chained LM fits (scan matching corrects every
    # frame's pose from the last one's, the local refinement continues from its last
    # result) carry a last-bit difference on; measured with a perturbed BLAS and numpy
    # SIMD off: up to 4e-6 relative (2.7e-7 m on a lower-ranked hypothesis' pose)
    rtol: float = Field(1e-5, ge=0, le=1)
    atol: float = Field(1e-6, ge=0, le=1)  # absolute tolerance (numbers near zero; 1 micrometre)


class BackboneSettings(Section):
    """Pretrained networks for plain RGB cameras (zfloc_stream/backbones, extra [torch]).
    A model is a local folder or a Hugging Face hub id; empty = not used. Depth from a
    depth camera always wins over network depth."""

    depth_model: str = ""  # e.g. depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf (metric depth)
    seg_model: str = ""  # e.g. nvidia/segformer-b0-finetuned-ade-512-512 (ADE20K classes)
    download: bool = False  # fetch a hub id that is not in the local Hugging Face cache (off: never touch the network)
    device: str = "auto"  # auto (CUDA when present, else CPU), cpu, cuda, cuda:N
    half_on_gpu: bool = True  # float16 weights and inputs on a GPU (CPU always float32)
    batch_size: int = Field(default=4, ge=1, le=1024)  # frames per network call (latency: a batch waits for its last frame)
    max_depth: float = Field(10.0, gt=0, le=1000)  # m, network depth beyond this is dropped (0 = no reading): far indoor depth is unreliable
    # classes of the segmenter, matched by name in the model's id2label (case-insensitive,
    # each 'a;b' or 'a, b' name split into synonyms); every other class is 'other'
    wall_classes: list[str] = ["wall", "door", "double door", "screen door", "windowpane", "window", "column", "pillar"]
    floor_classes: list[str] = ["floor", "flooring", "rug", "carpet", "carpeting", "mat"]
    ceiling_classes: list[str] = ["ceiling"]
    unknown_classes: list[str] = ["unlabeled", "unlabelled", "background", "void"]


class Settings(Section):
    seed: int = Field(0, ge=0, le=2**63 - 1)
    floorplan: FloorplanSettings = FloorplanSettings()
    primitives: PrimitiveSettings = PrimitiveSettings()
    estimator: EstimatorSettings = EstimatorSettings()
    frontend: FrontendSettings = FrontendSettings()
    bev: BevSettings = BevSettings()
    tracking: TrackingSettings = TrackingSettings()
    localizer: LocalizerSettings = LocalizerSettings()
    logging: LoggingSettings = LoggingSettings()
    datasets: DatasetSettings = DatasetSettings()
    study: StudySettings = StudySettings()
    replay: ReplaySettings = ReplaySettings()
    backbones: BackboneSettings = BackboneSettings()


def merge_nested(base: dict, update: dict) -> dict:
    """base updated by update, key by key at every depth (neither is changed)."""
    out = dict(base)
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_nested(out[key], value)
        else:
            out[key] = value
    return out


def dotted_to_nested(key: str, value) -> dict:
    """"a.b.c", v -> {"a": {"b": {"c": v}}} (a --set override as a settings tree)."""
    out: dict = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def _field_info(model: type[BaseModel], loc: tuple) -> Any:
    """The FieldInfo a validation error location points to (None past a list index)."""
    info = None
    for part in loc:
        if not isinstance(part, str) or model is None or part not in model.model_fields:
            return None
        info = model.model_fields[part]
        model = info.annotation if isinstance(info.annotation, type) and issubclass(info.annotation, BaseModel) else None
    return info


def allowed_range(info) -> str | None:
    """'(0, 10]', '[1, 1000] (integer)', 'at least 1 item'... from a field's constraints."""
    if info is None:
        return None
    c = {type(m).__name__: m for m in info.metadata}
    lo = ("(", c["Gt"].gt) if "Gt" in c else ("[", c["Ge"].ge) if "Ge" in c else None
    hi = (")", c["Lt"].lt) if "Lt" in c else ("]", c["Le"].le) if "Le" in c else None
    if lo and hi:
        text = f"{lo[0]}{_bound(lo[1])}, {_bound(hi[1])}{hi[0]}"
    elif lo:
        text = f"{'>' if lo[0] == '(' else '>='} {_bound(lo[1])}"
    elif hi:
        text = f"{'<' if hi[0] == ')' else '<='} {_bound(hi[1])}"
    elif "MinLen" in c:
        return f"at least {c['MinLen'].min_length} item(s)"
    else:
        return None
    return text + (" (integer)" if info.annotation is int else "")


def _suggest_key(parts: tuple) -> str:
    """' (did you mean 'a.b.c'?)' for an unknown key: the nearest field of its section."""
    import difflib

    info = _field_info(Settings, parts[:-1]) if len(parts) > 1 else None
    model = Settings if len(parts) == 1 else getattr(info, "annotation", None)
    if not (isinstance(model, type) and issubclass(model, BaseModel)) or not isinstance(parts[-1], str):
        return ""
    match = difflib.get_close_matches(parts[-1], list(model.model_fields), n=1, cutoff=0.6)
    return f" (did you mean '{'.'.join(str(p) for p in (*parts[:-1], match[0]))}'?)" if match else ""


def _bound(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:.10g}"


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _format_validation_error(err: ValidationError, source: str) -> str:
    first = err.errors()[0]
    parts = tuple(first["loc"])
    loc = ".".join(str(p) for p in parts) or "<root>"
    if first["type"] == "extra_forbidden":
        return f"{source}: unknown setting '{loc}'" + _suggest_key(parts)
    if first["type"] == "section_rule":  # a cross-field rule: spell every key in full
        ctx, prefix = first["ctx"], "".join(f"{p}." for p in parts)
        message = first["msg"]
        if ctx["related"]:
            message = re.sub(rf"\b({'|'.join(ctx['related'])})\b", lambda m: prefix + m.group(1), message)
        return f"{source}: setting '{prefix}{ctx['key']}' = {_short(ctx['value'])}: {message}"
    info = _field_info(Settings, parts)
    allowed = allowed_range(info)
    text = f"{source}: setting '{loc}' = {_short(first.get('input'))}: {first['msg']}"
    return text + (f"; allowed range {allowed}" if allowed else "")


def settings_from_dict(data: dict, source: str = "settings") -> Settings:
    if too_deep(data, MAX_NESTING):
        raise ConfigError(f"{source}: settings nested deeper than {MAX_NESTING} levels (no setting needs more than a few)")
    try:
        return Settings.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation_error(err, source)) from None


def load_settings(
    path: str | Path | None = None,
    overrides: list[str] | dict | None = None,
    base_overrides: dict | None = None,
) -> Settings:
    """Defaults, updated by base_overrides (what a data source needs, e.g. fixed scale for
    a laser), by a YAML file, then by overrides.

    overrides: either a nested dict or 'dotted.key=value' strings (values parsed as YAML).
    """
    data: dict = Settings().model_dump()
    source = "defaults"
    if base_overrides:
        data = merge_nested(data, base_overrides)
    if path is not None:
        path = Path(path)
        source = str(path)
        try:
            loaded = load_yaml(path.read_text()) or {}
        except TooDeep as err:
            raise ConfigError(f"{path}: settings {err} (no setting needs more than a few)") from None
        except FileNotFoundError:
            raise ConfigError(f"config file not found: {path}") from None
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
            raise ConfigError(f"cannot read config file {path}: {err}".splitlines()[0]) from None
        if not isinstance(loaded, dict):
            raise ConfigError(f"{path}: top level must be a mapping")
        data = merge_nested(data, loaded)
    if isinstance(overrides, dict):
        data = merge_nested(data, overrides)
    elif overrides:
        for item in overrides:
            if "=" not in item:
                raise ConfigError(f"override '{item}' must look like dotted.key=value")
            key, raw = item.split("=", 1)
            try:
                value = load_yaml(raw)
            except TooDeep as err:
                raise ConfigError(f"override '{key.strip()}': value {err} (no setting needs more than a few)") from None
            except yaml.YAMLError:
                raise ConfigError(f"override '{item}': value is not valid YAML") from None
            data = merge_nested(data, dotted_to_nested(key.strip(), value))
        source = f"{source} + overrides"
    return settings_from_dict(data, source)


def dump_settings(settings: Settings) -> str:
    return yaml.safe_dump(settings.model_dump(), sort_keys=False)
