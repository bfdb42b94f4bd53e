"""Settings of the front end: gravity, the wall mask, the geometric labeller, the rolling BEV
and its scan matching (frontend/)."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from .base import Section, ordered, section_rule_error


# the BEV grid's largest half side in cells (memory: (2 x 2000)^2 cells per layer)
MAX_BEV_HALF_CELLS = 2000


class GravitySettings(Section):
    """Floor-plane fit (paper 3.1): the downward normal of the floor is gravity.

    Frames arriving before gravity is known wait in a bounded buffer; gravity is frozen
    once min_frames frames brought min_floor_points floor points, then the buffer is fused.
    """

    trust_odometry: bool = False  # VIO already gravity-aligned: take -z of odom as gravity
    min_floor_points: int = Field(300, ge=3, le=10_000_000)  # accumulated floor points needed before gravity is frozen
    min_frames: int = Field(2, ge=1, le=1000)  # frames contributing floor points before gravity is frozen
    max_points: int = Field(10000, ge=3, le=10_000_000)  # cap on accumulated floor points
    max_pending_frames: int = Field(20, ge=1, le=10_000)  # frames buffered while gravity is unknown (oldest dropped)

    _ordered = ordered(("min_floor_points", "max_points", "<="))


class WallMaskSettings(Section):
    """Gravity-aligned column filter on the wall mask (paper eqs. 1-5)."""

    enabled: bool = True


class LabellerSettings(Section):
    """Geometric labeller for frames without labels (gravity frame, depth normals)."""

    floor_tolerance: float = Field(0.08, gt=0, le=1)  # m, |height above floor| below this (and not vertical): floor
    wall_min_height: float = Field(0.3, ge=0, le=10)  # m above floor, lower vertical surfaces are clutter ("other")
    ceiling_min_height: float = Field(1.8, gt=0, le=10)  # m above floor, non-vertical surfaces higher than this: ceiling
    normal_step: int = Field(2, ge=1, le=100)  # px, finite-difference step for depth normals
    max_tilt_deg: float = Field(35.0, gt=0, le=90)  # bootstrap: floor normal within this of the camera's up axis

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
    free_threshold: float = Field(-0.3, ge=-100, le=100)  # log-odds below this: observed free space
    occupied_threshold: float = Field(0.0, ge=-100, le=100)  # log-odds above this: occupied
    wall_min_ratio: float = Field(0.5, ge=0, le=1)  # a wall cell: wall evidence in at least this fraction of the frames that hit it (bev_snapshot.WALL_MIN_OBSERVATIONS)
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
    scan_match_max_shift: float = Field(0.3, gt=0, le=100)  # m, a larger correction in one frame is refused (odometry is good over one frame)
    scan_match_max_angle_deg: float = Field(5.0, gt=0, le=180)
    # odometry errs in proportion to its motion: the bounds above grow by these fractions of
    # the step (m) and the turn since the last matched frame (frontend/scan_match.step_bounds)
    scan_match_shift_per_step: float = Field(0.2, ge=0, le=10)
    scan_match_angle_per_turn: float = Field(0.1, ge=0, le=10)

    _ordered = ordered(("free_threshold", "occupied_threshold"))

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
