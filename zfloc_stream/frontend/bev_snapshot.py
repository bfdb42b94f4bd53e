"""A RollingBEV's grid frozen at one frame, and the one step that turns it into a
BevObservation: the cropped grids, the wall points, the free mask, the clearance f^v and
the primitives (lines; circles where the floorplan has pillars). Pure: the same snapshot
and rng give the same observation on any thread or process (a pipelined round runs it on
a worker)."""

from __future__ import annotations

import cv2
import numpy as np

from ..runtime import threads
from ..primitives.circle_fitting import circle_clusters, fit_circles
from ..settings.loading import Settings
from ..errors import InputError
from ..geometry.shapes import CircleSet, as_points
from ..observation import BevObservation
from ..primitives.extract import extract_lines
from . import bev_grids

# Frames that saw wall evidence in a cell before it can be a wall: 1, a wall seen once
# counts; the setting that filters clutter is bev.wall_min_ratio (was bev.wall_min_observations).
WALL_MIN_OBSERVATIONS = 1
# m, the observation is cropped to the known cells plus this margin: the free space and
# clearance around the outermost walls stay in the crop (was bev.crop_margin)
CROP_MARGIN = 0.5


def wall_cells(wall: np.ndarray, hits: np.ndarray, logodds: np.ndarray, b) -> np.ndarray:
    """Cells that are BEV walls: wall evidence often enough, mostly seen as wall rather
    than as clutter, and occupied (the observation and the scan matcher read the same)."""
    return (wall >= WALL_MIN_OBSERVATIONS) & (wall >= b.wall_min_ratio * hits) & (logodds > b.occupied_threshold)


class BevSnapshot:
    """The grid of a RollingBEV at one frame and how to turn it into a BevObservation.
    Pure: the same snapshot and rng give the same observation on any thread or process."""

    def __init__(self, logodds, wall, hits, seen, ix0: int, iy0: int, trajectory: np.ndarray, settings: Settings, stamp: int,
                 since: int = 0):
        """since: only cells a frame with this stamp or a later one touched (0: bev.memory_frames alone decides)."""
        self.logodds, self.wall, self.hits, self.seen, self.stamp, self.since = logodds, wall, hits, seen, stamp, since
        self.ix0, self.iy0 = ix0, iy0
        self.trajectory = trajectory
        self.settings = settings

    def observation(self, rng: np.random.Generator, circles: bool = True) -> BevObservation:
        """The cropped grids (known cells plus CROP_MARGIN), the wall points, the free
        mask, the clearance f^v and the primitives; circles=False skips the circles (no
        floorplan circle to match them: the pillar clustering is a round's largest
        primitive cost on a plan without pillars). The grid passes are compiled
        (bev_grids.py: the element-wise tests in two passes, the clearance in a third
        around OpenCV's exact distance transform), so no full-grid temporaries are built."""
        b = self.settings.bev
        n = self.logodds.shape[0]
        occupied, free_threshold = np.float32(b.occupied_threshold), np.float32(b.free_threshold)
        use_recent = bool(b.memory_frames) or self.since > 0
        oldest = max(self.stamp - b.memory_frames if b.memory_frames else 0, self.since - 1)
        grids = (self.logodds, self.wall, self.hits, self.seen)
        any_wall, r_lo, r_hi, c_lo, c_hi = bev_grids.known_extent(
            *grids, WALL_MIN_OBSERVATIONS, b.wall_min_ratio, occupied, use_recent, oldest)
        if not any_wall:
            raise InputError("BEV has no wall points yet")
        m = int(np.ceil(CROP_MARGIN / b.resolution))
        r0, r1 = max(r_lo - m, 0), min(r_hi + m + 1, n)
        c0, c1 = max(c_lo - m, 0), min(c_hi + m + 1, n)
        origin = np.array([(self.ix0 + c0) * b.resolution, (self.iy0 + r0) * b.resolution])
        free, not_occupied, points = bev_grids.crop_masks(
            *grids, r0, r1, c0, c1, WALL_MIN_OBSERVATIONS, b.wall_min_ratio, occupied, free_threshold,
            use_recent, oldest, origin[0], origin[1], b.resolution)
        prim = self.settings.primitives

        def free_clearance():
            distance = cv2.distanceTransform(not_occupied, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            return bev_grids.clearance(distance, free, b.resolution)

        # Three independent jobs on the round's threads (threads.py), longest first: the
        # circles' clustering takes no random numbers, so it runs beside the line
        # extraction, whose draws come first; the circle fits
        # draw after it. The same observation as one thread gives.
        clusters, lines, clearance = threads.run(lambda job: job(), [
            (lambda: circle_clusters(as_points(points), prim.circles)) if circles else (lambda: None),
            lambda: extract_lines(points, prim.lines, rng),
            free_clearance,
        ])
        found = fit_circles(clusters, prim.circles, rng) if circles else CircleSet.empty()
        return self._observation(points, origin, free, clearance, lines, found)

    def _observation(self, points, origin, free, clearance, lines, circles) -> BevObservation:
        return BevObservation(
            wall_points=points,
            origin=origin,
            resolution=self.settings.bev.resolution,
            free=free,
            clearance=clearance,
            lines=lines,
            circles=circles,
            trajectory=self.trajectory,
        )
