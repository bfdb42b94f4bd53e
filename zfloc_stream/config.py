"""Typed settings: one pydantic model per stage, composed into Settings.

Every number the algorithm uses has a name here; configs/default.yaml is the dump of
these defaults (a test keeps the two identical). Unknown keys are errors, so a typo in a
config file fails loudly instead of being ignored.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from .errors import ConfigError

SolverName = Literal["3L", "2L", "2C", "LC"]
ScaleMode = Literal["free", "prior", "fixed"]


class Section(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class LineSettings(Section):
    """Seeded region growing (paper 3.1)."""

    neighbourhood_radius: float = 0.25  # m, PCA neighbourhood of a seed
    min_seed_neighbours: int = 3  # fewer free points around a seed: it is noise
    local_radius: float = 2.0  # m, a line first grows inside this window around its seed (speed)
    inlier_distance: float = 0.05  # m, orthogonal distance to grow a line
    gap: float = 0.3  # m, largest gap along a line before it is split
    max_grow_iterations: int = 20  # refit/regrow rounds per seed (usually converges in 2-4)
    converge_tolerance: float = 0.001  # m, growth stops once a refit moves the line less than this
    min_points: int = 8
    min_length: float = 0.5  # m
    dedup_angle_deg: float = 5.0  # near-duplicate suppression
    dedup_offset: float = 0.15  # m


class CircleSettings(Section):
    """HDBSCAN clustering + 3-point RANSAC + angular checks (paper 3.1)."""

    min_cluster_size: int = 10
    hdbscan_min_samples: int = 2  # small: a thin pillar ring has few points per neighbourhood (larger values drop arc points as noise)
    ransac_iterations: int = 100
    inlier_distance: float = 0.03  # m
    min_radius: float = 0.1  # m
    max_radius: float = 1.0  # m
    min_inlier_ratio: float = 0.8
    min_coverage_deg: float = 120.0  # 2*pi minus the largest angular gap
    max_gap_deg: float = 30.0  # angular continuity: consecutive gaps below this...
    min_span_deg: float = 90.0  # ...over a contiguous span at least this long
    group_link_distance: float = 0.15  # m, points closer than this are one group; groups wider than a pillar are skipped
    refit_rounds: int = 2  # least-squares refit + inlier re-selection rounds
    refit_iterations: int = 10  # Gauss-Newton steps per refit


class PrimitiveSettings(Section):
    lines: LineSettings = LineSettings()
    circles: CircleSettings = CircleSettings()


class FloorplanSettings(Section):
    neighbour_distance: float = 6.0  # m, lines closer than this are spatial neighbours (3L pruning)
    wall_sample_spacing: float = 0.2  # m, floorplan wall pixels used by Cv are subsampled to this (a ratio: 0.2 m is plenty, 16x cheaper than 0.05)
    line_point_spacing: float = 0.025  # m, wall-face pixels are subsampled to this before line extraction
    image_wall_threshold: float = 0.5  # plain images: occupancy (255 - v) / 255 above this is wall


class SolverSettings(Section):
    pool: list[SolverName] = ["3L", "2L", "2C", "LC"]
    normal_consistency: float = 0.95  # tau_p: |cos(R n_i, n'_i)| required of the non-anchor lines (3L, 2L) before solving
    scale_prior_ggd_shape: float = 4.0  # 2L: generalised Gaussian noise on the metric scale
    scale_prior_prob: float = 0.8  # P(|eps| <= scale_prior_window * s) = this
    scale_prior_window: float = 0.1
    min_scale: float = 0.5  # models outside [min_scale, max_scale] are discarded
    max_scale: float = 2.0
    parallel_angle_deg: float = 10.0  # lines closer than this in direction count as parallel (degenerate)
    min_baseline: float = 0.3  # m (BEV units): 2C centres, or an LC centre and its line, closer than this are degenerate
    singular_tolerance: float = 1e-9  # relative determinant below which a linear solve is degenerate
    radius_tolerance: float = 0.5  # 2C/LC: model rejected when r_floorplan / (s r_bev) leaves [1/(1+x), 1+x]


class ScoringSettings(Section):
    tau_c: float = 0.1  # m, consistency threshold (paper)
    tau_v: float = 0.2  # m, violation threshold (paper)
    sparse_spacing: float = 0.25  # m, spacing of BEV line samples for the coarse pass
    max_sparse_points: int = 128  # ...widened so the coarse pass uses about this many points at most
    top_k: int = 50  # hypotheses re-ranked with the full score
    distinct_translation: float = 0.5  # m, hypotheses closer than this (and distinct_angle) are one
    distinct_angle_deg: float = 10.0
    chunk_size: int = 1_000_000  # (hypotheses x points) elements per vectorised block: bounds memory
    wall_bucket_size: float = 2.0  # m, Cv fetches floorplan wall points by buckets of this size (speed only)


class RefineSettings(Section):
    huber_delta: float = 0.1  # m
    max_evaluations: int = 30  # residual evaluations per hypothesis (converges in ~10)
    top_n: int = 10  # hypotheses refined (in one vectorised batch)
    max_points: int = 1000  # BEV wall points used by the refinement (evenly thinned)
    tolerance: float = 1e-4  # stop: relative cost decrease, step or gradient below this
    initial_damping: float = 1e-3  # Levenberg-Marquardt lambda at the start
    damping_factor: float = 10.0  # lambda divided by this after a good step, multiplied after a bad one


class RansacSettings(Section):
    iterations: int = 500  # BEV minimal samples per localization (solver drawn at random per sample)
    tracking_iterations: int = 150  # fewer fresh samples while one mode is tracked
    max_hypotheses: int = 10  # ranked distinct hypotheses returned
    match_fraction: float = 0.03  # each BEV minimal sample meets this fraction (>= 1) of its pruned floorplan matches


class EstimatorSettings(Section):
    scale_mode: ScaleMode = "free"
    solvers: SolverSettings = SolverSettings()
    scoring: ScoringSettings = ScoringSettings()
    refine: RefineSettings = RefineSettings()
    ransac: RansacSettings = RansacSettings()


class GravitySettings(Section):
    """Floor-plane fit (paper 3.1): the downward normal of the floor is gravity.

    Frames arriving before gravity is known wait in a bounded buffer; gravity is frozen
    once min_frames frames brought min_floor_points floor points, then the buffer is fused.
    """

    trust_odometry: bool = False  # VIO already gravity-aligned: take -z of odom as gravity
    min_floor_points: int = 300  # accumulated floor points needed before gravity is frozen
    min_frames: int = 2  # frames contributing floor points before gravity is frozen
    points_per_frame: int = 1000  # floor points kept per frame (random subsample)
    max_points: int = 10000  # cap on accumulated floor points
    ransac_iterations: int = 100  # 3-point plane hypotheses
    inlier_distance: float = 0.03  # m, point-to-plane distance of a floor inlier
    refine_iterations: int = 3  # PCA re-fits on the inliers of the previous fit
    max_pending_frames: int = 20  # frames buffered while gravity is unknown (oldest dropped)
    floor_height_smoothing: float = 0.2  # EMA factor of a frame's floor height (tracks slow z drift)


class WallMaskSettings(Section):
    """Gravity-aligned column filter on the wall mask (paper eqs. 1-5)."""

    enabled: bool = True
    tau_d: float = 0.3  # m (paper's tau_d): a non-wall pixel deeper than median + tau_d drops the column
    segment_gap: float = 0.1  # m, depth gap that splits a column's wall pixels into segments...
    segment_gap_per_m: float = 0.01  # ...plus this much per metre of depth (noise grows with depth)
    min_forward_depth: float = 0.05  # m, points closer than this to the upright image plane are not warped


class LabellerSettings(Section):
    """Geometric labeller for frames without labels (gravity frame, depth normals)."""

    floor_tolerance: float = 0.08  # m, |height above floor| below this (and not vertical): floor
    vertical_normal_max_z: float = 0.35  # |n_z| below this: a vertical surface
    wall_min_height: float = 0.3  # m above floor, lower vertical surfaces are clutter ("other")
    ceiling_min_height: float = 1.8  # m above floor, non-vertical surfaces higher than this: ceiling
    normal_step: int = 2  # px, finite-difference step for depth normals
    max_tilt_deg: float = 35.0  # bootstrap: floor normal within this of the camera's up axis
    bootstrap_min_below: float = 0.5  # m, bootstrap floor candidates lie this far below the camera


class FrontendSettings(Section):
    gravity: GravitySettings = GravitySettings()
    wall_mask: WallMaskSettings = WallMaskSettings()
    labeller: LabellerSettings = LabellerSettings()
    pixel_stride: int = 0  # camera pixels used: every pixel_stride-th row and column (0: automatic)...
    target_pixels: int = 12000  # ...automatic: stride = max(1, floor(sqrt(H * W / target_pixels)))
    max_depth: float = 10.0  # m, depth readings beyond this are ignored
    min_obstacle_height: float = 0.1  # m above floor: lower non-floor points do not occupy
    max_obstacle_height: float = 2.0  # m above floor: higher points do not occupy (ceiling, lamps)


class BevSettings(Section):
    """Rolling log-odds BEV in the gravity-aligned odometry plane (scrolling fixed-size grid)."""

    resolution: float = 0.05  # m per cell
    window_radius: float = 15.0  # m, cells farther than this from the sensor are dropped
    recenter_distance: float = 1.0  # m, the grid scrolls when the sensor leaves this box around its centre
    logodds_hit: float = 0.85  # added to a cell holding an obstacle point (once per frame)
    logodds_free: float = -0.4  # added to a cell crossed by a ray (once per frame)
    logodds_min: float = -2.0  # clamp, so old evidence can be overturned
    logodds_max: float = 3.5
    free_threshold: float = -0.3  # log-odds below this: observed free space
    occupied_threshold: float = 0.0  # log-odds above this: occupied
    wall_min_observations: int = 1  # frames that saw wall evidence in a cell before it is a wall point
    wall_min_ratio: float = 0.5  # ...and at least this fraction of the frames that hit the cell
    min_wall_points_per_cell: int = 3  # camera: wall points one frame must put in a cell to count (laser: 1)
    free_margin: float = 0.1  # m, rays stop this short of the obstacle they hit
    azimuth_bin_deg: float = 0.5  # camera free space: one ray per azimuth bin
    crop_margin: float = 0.5  # m, observation is cropped to the known cells plus this margin
    trajectory_length: int = 10000  # plane poses kept (bounded memory)


class TrackingSettings(Section):
    """Filter bank over the alignment, state anchored at the sensor (see tracking.py)."""

    # random-walk drift per round: variance grows with frames elapsed and metres travelled
    process_translation_std_per_frame: float = 0.01  # m per sqrt(frame), implied sensor position
    process_angle_deg_per_frame: float = 0.1  # deg per sqrt(frame)
    process_log_scale_per_frame: float = 0.001  # per sqrt(frame)
    process_translation_std_per_m: float = 0.05  # m per sqrt(m travelled)
    process_angle_deg_per_m: float = 1.0  # deg per sqrt(m travelled)
    process_log_scale_per_m: float = 0.01  # per sqrt(m travelled)
    # one refined RANSAC hypothesis, expressed at the sensor (also a new mode's covariance)
    measurement_translation_std: float = 0.15  # m
    measurement_angle_deg: float = 2.0
    measurement_log_scale: float = 0.02
    gate_chi2: float = 13.28  # Mahalanobis^2 gate, chi2(4 dof) at 99%
    # weights = softmax(weight_gain * running score); running score = EMA of fresh scores
    score_smoothing: float = 0.3  # EMA factor of a fresh score (or unobserved_score on a miss)
    unobserved_score: float = 0.0  # score a mode gets in a round where nothing matches it
    weight_gain: float = 15.0
    # births, pruning, merging
    birth_min_score: float = 0.3  # an unmatched hypothesis starts a mode only above this...
    birth_ratio: float = 0.8  # ...and above this fraction of the round's best score
    prune_weight: float = 0.001
    max_modes: int = 8
    merge_translation: float = 0.3  # m, implied sensor positions closer than this...
    merge_angle_deg: float = 5.0  # ...and headings closer than this...
    merge_log_scale: float = 0.05  # ...and log scales closer than this: one mode
    # status
    min_score: float = 0.3  # best running score below this: too little evidence
    confirm_rounds: int = 2  # matches before a mode can be tracked / make things ambiguous
    ambiguity_ratio: float = 0.5  # a second confirmed mode with weight >= this * best: ambiguous
    lost_score_ratio: float = 0.5  # fresh score below this * running score is a collapse...
    lost_rounds: int = 2  # ...and this many consecutive collapses of the tracked mode: lost
    confident_rounds: int = 5  # rounds of tracking one mode before confidently_tracking


class LocalizerSettings(Section):
    every_k_frames: int = 5  # a RANSAC round every k fused frames
    min_wall_points: int = 100  # BEV wall cells needed before the first round
    min_primitives: int = 3  # lines + circles needed before the first round
    # Per-frame consistency monitor: while tracking, each fused frame's wall points are
    # checked against the tracked alignment; a run of inconsistent frames means the
    # odometry jumped (or the device was carried away): the map is cleared and the status
    # becomes lost, which triggers a full global search.
    monitor_distance: float = 0.3  # m, a wall point within this of a floorplan wall is consistent
    monitor_min_consistency: float = 0.05  # fraction of consistent points below which a frame is inconsistent (a jump gives ~0)
    monitor_min_points: int = 30  # frames with fewer wall points are not judged
    monitor_max_points: int = 400  # wall points checked per frame (subsampled)
    monitor_frames: int = 4  # consecutive inconsistent frames that declare the track lost


class LoggingSettings(Section):
    """MCAP session logs (zfloc_stream/session): what is written, how it is chunked, and
    how files from other tools are read. Never affects the estimates."""

    compression: Literal["zstd", "lz4", "none"] = "zstd"  # per-chunk compression
    chunk_size: int = 1048576  # bytes; a chunk is closed once its records exceed this...
    chunk_max_frames: int = 10  # ...or after this many frames: bounds what a crash loses
    bev_every_n_frames: int = 10  # publish /zfloc/bev every n frames (0 = never)
    background: bool = True  # compress + write on a worker thread (the caller only serializes)
    max_pending_batches: int = 4  # batches (2 per frame) queued for the worker; a crash loses them too
    foreign_scan_range_min: float = 0.01  # m, LaserScan without zfloc range metadata
    foreign_scan_range_max: float = 100.0  # m
    success_distance: float = 1.0  # m, replay summary: SR@1m as in the paper...
    success_last_frames: int = 10  # ...every one of the final frames within the distance


class OdometrySettings(Section):
    """Synthetic odometry for logs whose poses are ground truth (Gibson(t), Carmen): the
    localizer only ever sees relative motion, re-expressed from a random odom origin."""

    noise: float = 0.0  # drift fraction: per-step translation noise std = noise * step length (0 = exact relative motion)
    heading_noise_per_m: float = 0.05  # rad per metre travelled, scaled by noise (heading drift from translation)
    origin_extent: float = 50.0  # m, odom origin drawn uniformly in [-extent, extent]^2, heading uniform


class GibsonSettings(Section):
    """Gibson(t) (F3Loc release): 40 z-depths per frame become a small synthetic depth image.
    Camera and wall heights are not in the data; these are assumptions (documented in gibson.py)."""

    image_rows: int = 30  # synthesised rows for 40 columns (the 640x480 camera's aspect)
    focal_fraction: float = 0.375  # fx / image width (F3Loc's F_W): ~106 deg horizontal fov
    camera_height: float = 1.0  # m above the floor (assumed)
    wall_height: float = 2.6  # m, floor to ceiling (assumed)
    map_resolution: float = 0.01  # m per map.png pixel
    split: str = "test"  # split.yaml entry used when a spec names none


class CarmenSettings(Section):
    flaser_fov_deg: float = 180.0  # FLASER: n beams spread over this...
    flaser_start_deg: float = -90.0  # ...starting here (counter-clockwise from forward)
    max_range: float = 80.0  # m, FLASER readings at or beyond this are no-returns (SICK reports 81.83)
    min_range: float = 0.01  # m, shorter readings are no-returns
    heldout_margin: int = 25  # scans: a study window's map leaves out [start - margin, stop + margin)


class MappingSettings(Section):
    """map-from-log: log-odds occupancy from scans with known poses."""

    resolution: float = 0.05  # m per cell
    logodds_hit: float = 0.85  # added to a cell holding a beam end (once per scan)
    logodds_free: float = -0.4  # added to a cell crossed by a beam (once per scan)
    occupied_threshold: float = 0.0  # log-odds above this: wall (more hit evidence than free)
    free_range: float = 15.0  # m, beams (and no-returns) clear free space up to this range
    free_margin: float = 0.1  # m, a beam clears free space only up to this short of its return
    padding: float = 1.0  # m of unknown margin around the mapped area


class SimDatasetSettings(Section):
    n_frames: int = 300  # frames simulated per built-in scene
    scene_seed: int = 0  # building layout (the walk and noise follow settings.seed)


class DatasetSettings(Section):
    odometry: OdometrySettings = OdometrySettings()
    gibson: GibsonSettings = GibsonSettings()
    carmen: CarmenSettings = CarmenSettings()
    mapping: MappingSettings = MappingSettings()
    sim: SimDatasetSettings = SimDatasetSettings()


class StudySettings(Section):
    """SR-vs-length studies (F3Loc protocol)."""

    eval_frames: int = 10  # success/RMSE look at this many final frames of a chunk
    thresholds: list[float] = [1.0, 0.5]  # m, success thresholds reported (<= counts as success)
    max_chunks_per_sequence: int = 20  # consecutive non-overlapping chunks kept per sequence and length
    connect_timeout_s: float = 10.0  # s, waiting for a remote dask scheduler (--scheduler)


class BackboneSettings(Section):
    """Pretrained networks for plain RGB cameras (zfloc_stream/backbones, extra [torch]).
    A model is a local folder or a Hugging Face hub id; empty = not used. Depth from a
    depth camera always wins over network depth."""

    depth_model: str = ""  # e.g. depth-anything/Depth-Anything-V2-Metric-Indoor-Small-hf (metric depth)
    seg_model: str = ""  # e.g. nvidia/segformer-b0-finetuned-ade-512-512 (ADE20K classes)
    download: bool = False  # fetch a hub id that is not in the local Hugging Face cache (off: never touch the network)
    device: str = "auto"  # auto (CUDA when present, else CPU), cpu, cuda, cuda:N
    half_on_gpu: bool = True  # float16 weights and inputs on a GPU (CPU always float32)
    batch_size: int = Field(default=4, ge=1)  # frames per network call (latency: a batch waits for its last frame)
    max_depth: float = 10.0  # m, network depth beyond this is dropped (0 = no reading): far indoor depth is unreliable
    # classes of the segmenter, matched by name in the model's id2label (case-insensitive,
    # each 'a;b' or 'a, b' name split into synonyms); every other class is 'other'
    wall_classes: list[str] = ["wall", "door", "double door", "screen door", "windowpane", "window", "column", "pillar"]
    floor_classes: list[str] = ["floor", "flooring", "rug", "carpet", "carpeting", "mat"]
    ceiling_classes: list[str] = ["ceiling"]
    unknown_classes: list[str] = ["unlabeled", "unlabelled", "background", "void"]


class Settings(Section):
    seed: int = 0
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
    backbones: BackboneSettings = BackboneSettings()


def _merge(base: dict, update: dict) -> dict:
    out = dict(base)
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


def _dotted_to_nested(key: str, value) -> dict:
    out: dict = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def _format_validation_error(err: ValidationError, source: str) -> str:
    first = err.errors()[0]
    loc = ".".join(str(p) for p in first["loc"]) or "<root>"
    if first["type"] == "extra_forbidden":
        return f"{source}: unknown setting '{loc}'"
    return f"{source}: setting '{loc}': {first['msg']}"


def settings_from_dict(data: dict, source: str = "settings") -> Settings:
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
        data = _merge(data, base_overrides)
    if path is not None:
        path = Path(path)
        source = str(path)
        try:
            loaded = yaml.safe_load(path.read_text()) or {}
        except FileNotFoundError:
            raise ConfigError(f"config file not found: {path}") from None
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
            raise ConfigError(f"cannot read config file {path}: {err}".splitlines()[0]) from None
        if not isinstance(loaded, dict):
            raise ConfigError(f"{path}: top level must be a mapping")
        data = _merge(data, loaded)
    if isinstance(overrides, dict):
        data = _merge(data, overrides)
    elif overrides:
        for item in overrides:
            if "=" not in item:
                raise ConfigError(f"override '{item}' must look like dotted.key=value")
            key, raw = item.split("=", 1)
            try:
                value = yaml.safe_load(raw)
            except yaml.YAMLError:
                raise ConfigError(f"override '{item}': value is not valid YAML") from None
            data = _merge(data, _dotted_to_nested(key.strip(), value))
        source = f"{source} + overrides"
    return settings_from_dict(data, source)


def dump_settings(settings: Settings) -> str:
    return yaml.safe_dump(settings.model_dump(), sort_keys=False)
