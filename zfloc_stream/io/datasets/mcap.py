"""Recorded MCAP sessions (ours or another tool's on the topics of docs/inputs.md):
`mcap:/runs/a.mcap,/runs/b.mcap`.

Frames, their ground truth (/groundtruth/pose, NaN where absent) and the floorplan come
from the file; a session that carries no floorplan uses `map.yaml` beside it when there
is one. Laser sessions get a fixed scale (a laser measures metres); RGB-only camera
sessions a metric prior (their depth comes from a network, metric to about 10%).

Counting the frames and collecting their ground truth takes one pass over the file that
decodes only the small topics (the session's frame index: session/reader.py); the same
index then lets `frames(start, stop)` read only the chunks that hold those frames.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...settings.loading import Settings
from ..drops import DropCounter
from ...errors import InputError
from ...frames import LaserFrame
from .base import Sequence, register

SIBLING_FLOORPLAN = "map.yaml"


def session_sequence(path, settings: Settings, floorplan=None, salvage: bool = False) -> Sequence:
    """salvage: read a truncated or damaged file as far as its intact chunks go."""
    from ...plans.loading import load_floorplan as load_plan
    from ..session import read_session

    path = Path(path)
    session = read_session(path, salvage=salvage, settings=settings)
    index = session.frame_index()
    if index is not None:
        truth, kinds = index.ground_truth, set(index.kinds)
    else:  # no chunk index (a file from another tool): read it once, frame by frame
        truth, kinds = [], set()
        for frame in session.frames():
            gt = frame.ground_truth
            truth.append(np.full(3, np.nan) if gt is None else np.asarray(gt, dtype=float)[:3])
            kinds.add("laser" if isinstance(frame, LaserFrame) else "rgb" if frame.depth is None else "depth")
    if not len(truth):
        raise InputError(f"{path}: the session holds no input frame")
    laser, rgb_only = "laser" in kinds, "rgb" in kinds

    def frames(start: int, stop: int):
        reader = session.fresh()  # shares the index; its own problem list
        drops, seen = DropCounter(str(path)), 0
        for frame in reader.frames(start, stop):
            seen = _report(reader.problems, seen, drops)
            yield frame
        _report(reader.problems, seen, drops)
        drops.summary()

    sibling = path.parent / SIBLING_FLOORPLAN  # the floorplan of a session that carries none

    def load_floorplan():
        if session.floorplan is not None:
            return session.floorplan
        if sibling.is_file():
            return load_plan(sibling, settings=settings)
        raise InputError(f"{path} carries no floorplan and there is no {SIBLING_FLOORPLAN} beside it: pass --floorplan")

    sequence = Sequence(
        name=path.stem if path.stem != "session" else path.parent.name,
        frame_source=frames,
        n_frames=len(truth),
        ground_truth=np.array(truth),
        floorplan=floorplan if floorplan is not None else load_floorplan,
        settings_overrides={"estimator": {"scale_mode": "fixed" if laser else "prior"}} if laser or rgb_only else {},
        source=f"mcap:{path}",
        needs_depth_network=rgb_only,
    )
    from ..session.schemas import INPUT_TOPICS

    sequence.topics = {t.rsplit("/", 1)[-1]: t for t in INPUT_TOPICS if session.topics is None or t in session.topics}
    if floorplan is None:
        if session.floorplan_files:
            sequence.floorplan_source = "the one the session carries"
        elif sibling.is_file():
            sequence.floorplan_source = f"{sibling}, beside the input (the session carries none; --floorplan names another)"
    return sequence


def _report(problems: list[str], seen: int, drops: DropCounter) -> int:
    """Warn about the reader's problems noted since the last call; returns how many there are."""
    for problem in problems[seen:]:
        drops.note_problem(problem)
    return len(problems)


@register("mcap")
def load_mcap(args: str, settings: Settings) -> list[Sequence]:
    return [session_sequence(p, settings) for p in args.split(",") if p]
