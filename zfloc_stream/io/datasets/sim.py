"""Built-in simulated scenes: `sim:apartment,office` (names from zfloc_stream.sim.SCENES;
`sim:all` for every one).

The building layout is fixed by datasets.sim.scene_seed; the walk, the sensor noise and
the odometry drift are drawn from settings.seed, so a study's seeds are independent
repetitions in the same buildings. A sequence of datasets.sim.n_frames frames renders each
frame when it is read (zfloc_stream.sim.simulate), so a study chunk pays only for its own.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ...settings.loading import Settings
from ...errors import InputError
from .base import Sequence, register


@lru_cache(maxsize=8)
def _simulated(name: str, scene_seed: int, walk_seed: int, n_frames: int):
    """(scene, SimSequence); the sequence renders a frame when it is read, identically in
    any order, so a chunk costs only its own frames."""
    from ...sim import SimSettings, build_scene, simulate

    scene = build_scene(name, seed=scene_seed)
    return scene, simulate(scene, SimSettings(), seed=walk_seed, n_frames=n_frames)


def scene_sequence(name: str, settings: Settings) -> Sequence:
    cfg = settings.datasets.sim
    key = (name, cfg.scene_seed, settings.seed, cfg.n_frames)

    def frames(start: int, stop: int):
        simulated = _simulated(*key)[1]
        return (simulated[k] for k in range(start, stop))

    return Sequence(
        name=name,
        frame_source=frames,
        n_frames=cfg.n_frames,
        ground_truth=lambda: np.asarray(_simulated(*key)[1].poses, dtype=float),
        floorplan=lambda: _simulated(*key)[0].floorplan,
        source=f"sim:{name}",
    )


@register("sim")
def load_sim(args: str, settings: Settings) -> list[Sequence]:
    from ...sim import SCENES

    names = [n.strip() for n in args.split(",") if n.strip()]
    if names == ["all"]:
        names = list(SCENES)
    unknown = [n for n in names if n not in SCENES]
    if unknown or not names:
        raise InputError(f"unknown simulated scene(s) {', '.join(unknown) or '(none given)'} (known: {', '.join(SCENES)})")
    return [scene_sequence(n, settings) for n in names]
