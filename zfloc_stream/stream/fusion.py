"""Fusion: one pushed frame into the rolling BEV, and its odometry step judged.

A camera frame with an RGB image only first gets depth (and labels) from the networks
(backbones.perception, made from settings.backbones when a frame first needs them: a
replay of a session whose frames carry depth never loads them). A frame that cannot be
fused is skipped with the reason: one bad frame never kills the stream. The odometry-jump
watch (odometry_jump.py) judges the step of each frame fused alone; after a jump the BEV
starts again from that frame (restart).
"""

from __future__ import annotations

import time

import numpy as np

from ..backbones.perception import Perception, needs_backbones
from ..errors import ZflocError
from ..frames import CameraFrame
from ..frontend.bev import RollingBEV
from ..settings.loading import Settings
from .odometry_jump import OdometryJumpWatch


class Fusion:
    def __init__(self, bev: RollingBEV, settings: Settings, perception: Perception | None = None):
        self.bev = bev
        self.settings = settings
        self.perception = perception
        self.jumps = OdometryJumpWatch(settings)  # odometry steps the sensor cannot have made
        self.frames_fused = 0
        self._bev_fused_before = 0  # RollingBEV.frames_fused before the latest add (judge_step)

    def fuse(self, frame, timings: dict) -> tuple[np.ndarray | None, str | None]:
        """Fuse one frame: its plane pose, or None and why it was skipped."""
        t0 = time.perf_counter()
        if self._wants_backbones(frame):
            frame = self._perceive(frame)
            timings["backbones"] = time.perf_counter() - t0
            t0 = time.perf_counter()
        if isinstance(frame, CameraFrame) and frame.depth is None:
            if self.perception is not None and self.perception.depth is not None:
                return None, f"depth network gave no depth within backbones.max_depth ({self.settings.backbones.max_depth} m)"
            return None, "camera frame has an RGB image but no depth (name a depth network: backbones.depth_model / run --depth-model)"
        try:
            self._bev_fused_before = self.bev.frames_fused
            self.bev.add(frame)
            plane_pose = np.asarray(self.bev.plane_pose(frame), dtype=float)
        except ZflocError as err:  # one bad frame never kills the stream
            return None, str(err)
        self.frames_fused += 1
        timings["fusion"] = time.perf_counter() - t0
        return plane_pose, None

    def judge_step(self, plane_pose: np.ndarray) -> tuple[str, str] | None:
        """The odometry-jump watch's verdict on this frame's step (odometry_jump.py):
        None, or (SUSPECT or JUMPED, why). Judged on a frame fused alone (a camera frame
        that waited for gravity is fused with the buffer: its step and hits are not its
        own), else recent motion starts again."""
        if self.bev.frames_fused != self._bev_fused_before + 1:
            self.jumps.restart(plane_pose)
            return None
        return self.jumps.judge(plane_pose, self.bev.last_known_hits, self.bev.last_contradiction, len(self.bev.last_wall_hits))

    def restart(self, frame) -> np.ndarray:
        """The odometry jumped: the BEV starts again from this frame (gravity stays), and so
        does the recent motion. Returns the frame's plane pose in the restarted map."""
        self.bev.clear_map()
        self.bev.add(frame)  # it was fused once already: the same frame cannot fail now
        plane_pose = np.asarray(self.bev.plane_pose(frame), dtype=float)
        self.jumps.restart(plane_pose)
        return plane_pose

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
