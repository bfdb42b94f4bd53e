"""Settings of the input sources: odometry interpolation, the dataset readers (Gibson,
Carmen, the simulator, ROS 2 bags), maps made from logs, the camera backbones."""

from __future__ import annotations

from pydantic import Field

from .base import Section, ordered
from .plans import VectorFloorplanSettings


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


class DatasetSettings(Section):
    ros2: Ros2Settings = Ros2Settings()
    vector_floorplan: VectorFloorplanSettings = VectorFloorplanSettings()
    odometry: OdometrySettings = OdometrySettings()
    gibson: GibsonSettings = GibsonSettings()
    carmen: CarmenSettings = CarmenSettings()
    mapping: MappingSettings = MappingSettings()
    sim: SimDatasetSettings = SimDatasetSettings()


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
