"""Run the localizer over frames and log the session: the loop every recorder shares.

    estimates = record_session("session.mcap", floorplan, frames, settings)

Each frame is logged first and the frame *as logged* is pushed, so `zfloc-replay --check`
reproduces the run bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path

from ...settings.loading import Settings
from ...estimate import Estimate
from .writer import SessionWriter


def record_session(
    path: str | Path,
    floorplan,
    frames: Iterable,
    settings: Settings,
    metadata: dict[str, str] | None = None,
    on_estimate: Callable[[Estimate], None] | None = None,
) -> list[Estimate]:
    from ...stream.localizer import Localizer  # the engine is only needed here

    estimates: list[Estimate] = []
    with Localizer(floorplan, settings) as localizer, SessionWriter(path, settings, floorplan, metadata=metadata) as log:
        for index, frame in enumerate(frames):
            frame = log.write_frame(index, frame)
            est = localizer.push(frame)
            log.write_estimate(est, localizer)
            estimates.append(est)
            if on_estimate is not None:
                on_estimate(est)
    return estimates
