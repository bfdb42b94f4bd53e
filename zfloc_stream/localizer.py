"""The streaming localizer: one object an embedded loop feeds one frame at a time.

    loc = Localizer(floorplan, settings)
    for frame in frames:
        est = loc.push(frame)

Each push fuses the frame into the rolling BEV. Every k frames a round runs: primitives
are extracted, the live modes are re-scored and refined first (warm start), fresh minimal
samples are drawn (fewer while one mode is confidently tracked, a full global search while
initializing or lost), and the tracker updates its modes. Between rounds the pose is the
current best alignment applied to the frame's odometry-plane pose, so every frame has one.
"""

from __future__ import annotations

import time

import numpy as np

from .backbones.perception import Perception, needs_backbones
from .config import Settings
from .errors import ZflocError
from .estimate import Estimate
from .estimation import localize
from .floorplan import Floorplan
from .frames import CameraFrame, LaserFrame
from .frontend.bev import RollingBEV
from .rng import make_rng
from .tracking import HypothesisTracker


class Localizer:
    def __init__(self, floorplan: Floorplan, settings: Settings | None = None, perception: Perception | None = None):
        """perception: the networks for RGB-only camera frames; by default made from
        settings.backbones when the first such frame arrives (a replay of a session whose
        frames carry depth never loads them)."""
        self.settings = settings or Settings()
        self.perception = perception
        self.floorplan = floorplan
        self.bev = RollingBEV(self.settings)
        self.tracker = HypothesisTracker(self.settings.tracking)
        self.frames_pushed = 0
        self.frames_fused = 0
        self.last_result = None  # LocalizationResult of the latest round, for logging
        self.last_observation = None  # BevObservation of the latest round, for overlays
        self._inconsistent_frames = 0  # consecutive frames the tracked alignment does not explain
        self._force_global = False  # the monitor asks the next round for a full global search

    # ------------------------------------------------------------------------------
    def push(self, frame: CameraFrame | LaserFrame) -> Estimate:
        index = self.frames_pushed
        self.frames_pushed += 1
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        if self._wants_backbones(frame):
            frame = self._perceive(frame)
            timings["backbones"] = time.perf_counter() - t0
            t0 = time.perf_counter()
        if isinstance(frame, CameraFrame) and frame.depth is None:
            if self.perception is not None and self.perception.depth is not None:
                reason = f"depth network gave no depth within backbones.max_depth ({self.settings.backbones.max_depth} m)"
            else:
                reason = "camera frame has an RGB image but no depth (name a depth network: backbones.depth_model / run --depth-model)"
            return self._estimate(index, frame.timestamp, None, timings, skipped=reason)
        try:
            self.bev.add(frame)
            plane_pose = np.asarray(self.bev.plane_pose(frame), dtype=float)
        except ZflocError as err:  # one bad frame never kills the stream
            stamp = getattr(frame, "timestamp", float("nan"))
            return self._estimate(index, stamp, None, timings, skipped=str(err))
        self.frames_fused += 1
        timings["fusion"] = time.perf_counter() - t0
        self._monitor()

        round_skipped = None
        if self.frames_fused % self.settings.localizer.every_k_frames == 0:
            round_skipped = self._round(index, plane_pose, timings)
        return self._estimate(index, frame.timestamp, plane_pose, timings, round_skipped=round_skipped)

    def _wants_backbones(self, frame) -> bool:
        """Does a network have work on this frame? Asked of the perception when there is
        one, else of the settings (which would make one)."""
        if self.perception is not None:
            return self.perception.wants(frame)
        return needs_backbones(frame, self.settings.backbones)

    def _perceive(self, frame: CameraFrame) -> CameraFrame:
        """Network depth / labels for one frame. A model that cannot be loaded raises
        (BackboneError): that is the run's setup, not one bad frame."""
        if self.perception is None:
            self.perception = Perception.from_settings(self.settings.backbones)
        return frame if self.perception is None else self.perception.complete([frame])[0]

    # ------------------------------------------------------------------------------
    def _round(self, index: int, plane_pose: np.ndarray, timings: dict) -> str | None:
        """Extract primitives, estimate (warm-started), update the tracker. A BEV with too
        little evidence, or an estimator error, skips the round: the status stays as it is
        (initializing at first) and the reason is returned for the frame's Estimate."""
        cfg = self.settings
        t0 = time.perf_counter()
        try:
            obs = self.bev.observation(make_rng(cfg.seed, "primitives", index))
        except ZflocError as err:
            timings["primitives"] = time.perf_counter() - t0
            return f"primitive extraction failed: {err}"
        timings["primitives"] = time.perf_counter() - t0
        lacking = self._lacking_evidence(obs)
        if lacking:
            return lacking
        self.last_observation = obs
        tracked = self.tracker.confidently_tracking and not self._force_global
        self._force_global = False
        iterations = cfg.estimator.ransac.tracking_iterations if tracked else cfg.estimator.ransac.iterations
        try:
            result = localize(
                self.floorplan,
                obs,
                cfg.estimator,
                make_rng(cfg.seed, "ransac", index),
                scale_prior=cfg.estimator.scale_prior,
                warm_start=self.tracker.warm_start(),
                iterations=iterations,
                global_search=not tracked,
            )
        except ZflocError as err:
            return f"estimator error: {err}"
        self.last_result = result
        for key, value in result.timings.items():
            timings[key] = value
        t0 = time.perf_counter()
        self.tracker.update(result.hypotheses, plane_pose[:2], index)
        timings["tracking"] = time.perf_counter() - t0
        return None

    def _monitor(self) -> None:
        """Watch each fused frame against the tracked alignment (see LocalizerSettings)."""
        cfg = self.settings.localizer
        points = self.bev.last_wall_hits
        if self.tracker.status != "tracking" or len(points) < cfg.monitor_min_points:
            return
        points = points[:: max(1, len(points) // cfg.monitor_max_points)]
        distances = self.floorplan.distance(self.tracker.best.alignment.apply(points))
        consistent = np.mean(distances < cfg.monitor_distance) >= cfg.monitor_min_consistency
        self._inconsistent_frames = 0 if consistent else self._inconsistent_frames + 1
        if self._inconsistent_frames >= cfg.monitor_frames:
            self._inconsistent_frames = 0
            self._force_global = True

    def _lacking_evidence(self, obs) -> str | None:
        """Why the BEV is too thin for a round (None when it is enough)."""
        cfg = self.settings.localizer
        walls, primitives = len(obs.wall_points), len(obs.lines) + len(obs.circles)
        if walls < cfg.min_wall_points:
            return f"too little evidence: {walls} wall points < localizer.min_wall_points = {cfg.min_wall_points}"
        if primitives < cfg.min_primitives:
            return f"too little evidence: {primitives} lines/circles < localizer.min_primitives = {cfg.min_primitives}"
        return None

    # ------------------------------------------------------------------------------
    def _estimate(self, index, timestamp, plane_pose, timings, skipped=None, round_skipped=None) -> Estimate:
        status = self.tracker.status
        best = self.tracker.best
        if best is None or plane_pose is None:
            pose = cov = alignment = None
            score = float("nan")
        else:
            alignment = best.alignment
            pose = np.array(alignment.apply_pose(*plane_pose))
            cov = self.tracker.pose_covariance(plane_pose[:2], plane_pose[2], mode=best)
            score = float(best.score)
        alternatives = () if plane_pose is None else self.tracker.estimate_alternatives(plane_pose[:2], plane_pose[2])
        return Estimate(index, float(timestamp), status, pose, cov, alignment, score, alternatives, timings, skipped, round_skipped)
