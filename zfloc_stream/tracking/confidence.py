"""Estimate.confidence: how likely the reported pose is within 1 m of the truth, on any map.

A caller thresholds one number instead of reading the status; the number must mean the same
thing on the right map and on a wrong one (another building, another floor). It is the
product of the evidence the localizer already has for the frame's pose:

    confidence = weight * confirmation * map_fit(explained)

- weight: the reported mode's share of the filter bank's weight (against the other places
  the rounds found in this map);
- confirmation: its hits / the rounds it needs to be tracked (at most 1);
- map_fit (policy.map_fit): does this map explain what the sensor sees at all? A linear
  ramp in the share of the latest BEV's wall points the map explains under the pose (map_match.py): 0 at
  min_explained_share - confidence_share_band, 1/2 at min_explained_share (where the
  MAP_UNEXPLAINED rule withholds `tracking`), 1 at min_explained_share +
  confidence_share_band; 1 while nothing is judged (no BEV yet).

and then, from the status decision:

- 0 on a frame whose own evidence contradicts its pose (status.contradicts: its wall hits
  unexplained, a pose jump, a running kidnap test, a doubted odometry step), and on a `lost`
  frame: the mode it tracked stopped explaining the data (or was dropped), and whatever is
  reported now has not earned any trust;
- below dominance_weight (strictly) unless the decision vouches for the pose (status.vouches:
  `tracking`, or a preview of a bank that would be): a mode the round did not single out
  can carry almost all of the weight and be wrong. The other way round, a `tracking` frame
  whose weight times map_fit is at most dominance_weight is not `tracking`
  (MAP_UNEXPLAINED, policy.map_vouches): a threshold at dominance_weight on the confidence
  and the status `tracking` select the same frames.

Why the map's fit: weight and confirmation compare the places of one map with each other,
so on another building's map the best place can hold all of the weight (up to 0.9 on
`initializing` frames 20-50 m off). Only a level tells right from wrong maps, and the
explained share is the one the localizer has. Measured on the shared data (eval_real.py
--json, benchmarks/evaluation/calibration.py), the band chosen on the laser windows (right
maps and every other building's map) as the narrowest at which no wrong-map frame reached
0.9 and frames >= 0.7 were 99% within 1 m (two windows per log and length on every other
log's map); checked on data it was not chosen on: the camera windows and the camera
sessions on other buildings' maps (no frame >= 0.9), the other six laser windows per log
and length on every other map (10 of 26,400 frames >= 0.9, where a corridor of one
building looks like another's: the map explained all of the frames), the built-in scenes
on their own and on another scene's map (none): docs/measurements/status.md.
"""

from __future__ import annotations

import math

from .policy import map_fit
from .status import Decision, vouches
from ..estimate import Status
from ..settings.tracking import TrackingSettings


def frame_confidence(weight: float, confirmation: float, explained: float | None, decision: Decision,
                     contradicted: bool, s: TrackingSettings) -> float:
    """The frame's confidence (the module's docstring): weight and confirmation of the
    reported mode, the map's fit, the status decision and whether the frame's evidence
    contradicts the pose."""
    if contradicted or decision.status is Status.LOST:
        return 0.0
    confidence = float(weight * min(1.0, confirmation) * map_fit(explained, s))
    # a frame the status does not vouch for stays strictly below dominance_weight, so a caller's
    # `confidence >= dominance_weight` takes only frames that are `tracking` (or a preview's)
    return confidence if vouches(decision) else min(confidence, math.nextafter(s.dominance_weight, 0.0))
