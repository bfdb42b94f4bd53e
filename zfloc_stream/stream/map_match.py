"""Does the map explain what the sensor sees?

A wrong map (another building, another floor, a plan that lacks the rooms) still has a
best place: the tracker's rules compare places with each other, so they can single one
out and report it `tracking`, with almost all of the weight, tens of metres off. What
separates right from wrong maps is a level: the share of the latest BEV's wall points
that lie within localizer.monitor_distance of a plan wall under the reported alignment
(on the shared buildings' own maps it stays well above tracking.min_explained_share; on
other buildings' maps it falls below it where the tracker would have said `tracking`:
docs/measurements/status.md).

Per frame the share goes to the status decision (the MAP_UNEXPLAINED rule of
tracking/status.py); per run, a run of at least MIN_JUDGED_FRAMES judged frames in which
no frame was `tracking` ends with a verdict: the map does not match, with the share of
frames it explained.
"""

from __future__ import annotations

import numpy as np

from ..estimation.local_refinement import explained_share

MIN_JUDGED_FRAMES = 10  # a run shorter than this (in frames with a pose and a BEV) gets no verdict
MAX_POINTS = 2000  # BEV wall points judged per frame (evenly subsampled)


class MapMatch:
    def __init__(self, floorplan, localizer_settings, tracking_settings):
        self.floorplan = floorplan
        self.distance = localizer_settings.monitor_distance
        self.min_points = localizer_settings.monitor_min_points
        self.min_share = tracking_settings.min_explained_share
        self.judged = 0  # frames with a pose and a BEV to judge
        self.explained = 0  # of those, frames whose share reached min_explained_share
        self.tracking = 0  # frames reported `tracking`
        # (alignment, observation, share) of the latest judged frame: between rounds and local
        # refinements every frame asks again with the same alignment and BEV (push's hot path)
        self._last: tuple | None = None

    def share(self, alignment, observation) -> float | None:
        """Share of the observation's wall points (plane frame) the alignment puts near a
        plan wall; None: nothing to judge (no pose, no BEV, too few wall points)."""
        points = None if observation is None else getattr(observation, "wall_points", None)
        if alignment is None or points is None or len(points) < self.min_points:
            return None
        last = self._last
        if last is not None and last[1] is observation and last[0] == alignment:  # Sim2: equal fields, equal share
            return last[2]
        share = explained_share(self.floorplan, alignment, np.asarray(points)[:: max(1, len(points) // MAX_POINTS)], self.distance)
        self._last = (alignment, observation, share)
        return share

    def note(self, share: float | None, status: str) -> None:
        """Count one reported frame."""
        self.tracking += status == "tracking"
        if share is not None:
            self.judged += 1
            self.explained += share >= self.min_share

    def verdict(self) -> str | None:
        """The run's warning when the map did not match what the sensor saw, else None."""
        if self.tracking or self.judged < MIN_JUDGED_FRAMES:
            return None
        counted = (f"{self.explained} of {self.judged} frames, {100.0 * self.explained / self.judged:.0f}%: "
                   f"tracking.min_explained_share = {self.min_share:g} of their wall points within {self.distance:g} m of a plan wall")
        if 2 * self.explained < self.judged:
            return (f"the map does not match what the sensor sees: no place in it explained the frames well enough to track "
                    f"(at the best place found it explained {counted}); is it the right building and floor?")
        # most frames fit, yet no place stood out: saying "no place explained them" would be
        # false (a plan of 100,000 scattered lines fits anything; a look-alike building fits too)
        return (f"the map does not match what the sensor sees well enough to single out one place: the best place found "
                f"explained {counted}, but others explained the frames about as well (places that look alike, clutter "
                f"that fits anywhere, or a look-alike building); is it the right building and floor?")
