"""Local refinement: the tracked mode's alignment refined on the recent frames' wall hits
alone (LM with the scale held, on the floorplan's face field), so the pose follows the
odometry's drift between rounds and the last metres the BEV fused weigh in.

A chain: each refinement starts from the last one accepted for the same mode, while that
explains the recent hits at least as well as the mode's own alignment (else from the
mode's, which the rounds keep fitting to the whole BEV). A step is accepted when it is finite, moves the recent hits' centre by at most
localizer.local_max_step metres per fused frame since the last refinement (drift is slow:
a jump is another place, which only a round may propose), stays within the mode's
pose-jump gate, and explains at least as many of the hits as where it started. A refused
step keeps the last accepted alignment; a new tracked mode starts a new chain from its own
alignment. Settings: LocalizerSettings
(`local_*`).

Metric odometry (localizer.odometry_scale "metric", estimator.scale_mode "prior"): a depth
network's depth is off by a factor about each camera while the odometry is metric, so the
mode's scale is the depth's, not the trajectory's. Each frame's hits are rescaled about its
own camera by the mode's scale over estimator.scale_prior (frame_hits), and the chain fits
an alignment at scale_prior to them: the trajectory maps at the plan's scale, and along a
corridor, where the hits do not fix the position along it, the pose no longer slides by
the depth's scale error of every metre walked.
"""

from __future__ import annotations

import numpy as np

from .field_fit import refine_batch
from ..plans.floorplan import Floorplan
from ..settings.estimation import EstimatorSettings
from ..settings.localizer import LocalizerSettings
from ..geometry.sim2 import Sim2
from .results import alignment_of, model_rows
from .scoring import floorplan_scorer


def explained_share(floorplan: Floorplan, alignment: Sim2, points: np.ndarray, distance: float) -> float:
    """Share of plane-frame wall points that the alignment puts within `distance` metres of
    a floorplan wall."""
    return float(np.mean(floorplan.distance(alignment.apply(points)) < distance))


class LocalRefinement:
    """The chain of local refinements of the tracked mode (see the module docstring)."""

    def __init__(self, floorplan: Floorplan, localizer: LocalizerSettings, estimator: EstimatorSettings):
        self.floorplan = floorplan
        self.settings = localizer
        self.estimator = estimator
        self.mode_id: int | None = None  # the mode the chain follows (None: no chain)
        self.alignment: Sim2 | None = None  # its last accepted local alignment
        self._frame = 0  # fused frames counted at the last refinement

    @property
    def metric_odometry(self) -> bool:
        """localizer.odometry_scale "metric" at a scale prior: the alignment's scale is the
        depth's, the trajectory maps at estimator.scale_prior (module docstring). At a free
        scale the plan's units are unknown too, so depth and trajectory share the one
        scale; at a fixed scale there is none to split."""
        return self.settings.odometry_scale == "metric" and self.estimator.scale_mode == "prior"

    def frame_hits(self, hits: np.ndarray, camera_xy, mode) -> np.ndarray:
        """A frame's wall hits as the reported alignment reads them: under metric odometry
        each hit rescaled about its camera by the mode's depth factor (its scale over
        estimator.scale_prior), else as fused."""
        if mode is None or not self.metric_odometry or not len(hits):
            return hits
        q = mode.alignment.s / self.estimator.scale_prior
        camera = np.asarray(camera_xy, dtype=float)
        return camera + q * (hits - camera)

    def alignment_of_mode(self, mode) -> Sim2:
        """What to report for the tracked mode: the chain's alignment when it follows that
        mode, else the mode's own."""
        return self.alignment if self.mode_id == mode.id else mode.alignment

    def update(self, best, recent_hits, frames_fused: int, recent_cameras=None, jumped=None) -> None:
        """One refinement of the tracked mode `best` (None: nothing tracked) on the recent
        frames' wall hits (plane frame, one array per frame; recent_cameras: each frame's
        camera position, needed under metric odometry). jumped: the tracker's pose-jump gate
        (HypothesisTracker.pose_jumped): a step beyond it of the mode's alignment at the
        latest camera is refused (None: no gate)."""
        cfg = self.settings
        metric = self.metric_odometry and recent_cameras is not None
        if metric:
            recent_hits = [self.frame_hits(h, c, best) for h, c in zip(recent_hits, recent_cameras)]
        hits = [h for h in recent_hits if len(h)]
        if cfg.local_frames == 0 or best is None or not hits:
            self._reset()
            return
        points = np.concatenate(hits)
        points = points[:: max(1, len(points) // cfg.local_max_points)]
        centre = points.mean(axis=0)
        continuing = self.mode_id == best.id
        own = best.alignment
        if metric:
            # the mode's alignment at the trajectory's scale, about the recent cameras
            # (where, fitted to hits seen from there, it maps the cameras right)
            anchor = np.mean(np.asarray(list(recent_cameras), dtype=float), axis=0)
            s = self.estimator.scale_prior
            own = Sim2(s, own.theta, own.apply(anchor) - s * own.R @ anchor)
        start = self.alignment if continuing else own
        # (a fixed-scale mode's s is 1 only up to the filter's round-off: keep it out)
        if continuing and not metric and self.estimator.scale_mode != "fixed" and start.s != best.alignment.s:
            # The local fit keeps the scale fixed (ten frames of hits barely observe it);
            # the rounds measure it on the whole BEV, so the chain takes the mode's scale,
            # about the recent hits' centre (where the local fit put them stays put).
            # Without this the chain kept its first scale forever (office seed 14: 1.015
            # against a true 1.044 for 90 frames, 0.1-0.25 m off).
            s = best.alignment.s
            start = Sim2(s, start.theta, start.apply(centre) - s * start.R @ centre)
        start_share = self._explained(start, points)
        own_share = self._explained(own, points) if continuing else start_share
        if own_share > start_share:
            # The chain goes on while it explains the recent hits at least as well as the
            # mode as the rounds leave it; else it starts again from the mode. Each step is
            # judged against where it started only, so on frames a plan explains little of
            # (0-10%: furniture, rooms it leaves out) a chain of accepted steps walked away
            # from the mode: intel 810 #100 on the one-face plan, the mode 0.05-0.5 m off the
            # truth for 70 frames while the chain, 35 deg turned, reported poses 1.5-4.8 m off.
            # (Not when the mode moved away from the chain: where the recent frames explain
            # nothing, e.g. orebro 0 #50 on the plan, the mode moved 0.7 m in a round that
            # found it nowhere, the chain stayed right.)
            start, continuing, start_share = own, False, own_share
        field = floorplan_scorer(self.floorplan, self.estimator.scoring).face_field
        refine = self.estimator.refine.model_copy(update={"outlier_distance": cfg.local_outlier_distance})
        local = alignment_of(refine_batch(field, points, model_rows([start]), refine, "fixed")[0])
        # a step from where it started (the drift of one round), never a jump elsewhere: nor
        # beyond the mode's pose-jump gate (the recent frames alone fit wrong places nearby
        # on a plan: belgioioso 0 #100, camera, one-face, a new chain 0.8 m from its mode)
        shift = float(np.linalg.norm(local.apply(centre) - start.apply(centre)))
        frames = max(1, frames_fused - self._frame)
        self._frame = frames_fused
        sensor = None if jumped is None or not recent_cameras else recent_cameras[-1]
        keep = (local.is_finite() and shift <= cfg.local_max_step * frames
                and self._explained(local, points) >= start_share
                and not (sensor is not None and jumped(own, local, sensor, best)))  # another place, by the tracker's gate
        if keep:
            self.mode_id, self.alignment = best.id, local
        elif not continuing:  # a refused step keeps the last accepted local alignment
            self._reset()

    def _explained(self, alignment: Sim2, points: np.ndarray) -> float:
        return explained_share(self.floorplan, alignment, points, self.settings.monitor_distance)

    def _reset(self) -> None:
        self.mode_id, self.alignment = None, None
