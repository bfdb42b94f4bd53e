"""Regenerate the sample sessions in this folder from built-in simulated scenes.

    .venv/bin/python replay/record_samples.py            # all samples
    .venv/bin/python replay/record_samples.py office-laser

Each sample is the default settings, a built-in scene and a seeded walk: the same code
version regenerates the same bits (the sessions contain no wall-clock data except the
stage timings inside /zfloc/status).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from zfloc_stream.settings.loading import Settings
from zfloc_stream.io.session import record_session
from zfloc_stream.sim import LaserSimSettings, SimSettings, build_scene, simulate, simulate_laser

HERE = Path(__file__).resolve().parent

# name: (scene, scene + walk seed, frames, sensor, simulator settings)
SAMPLES = {
    "apartment-camera": ("apartment", 0, 25, "camera", SimSettings()),
    "symmetric-camera-small": ("symmetric", 1, 30, "camera", SimSettings(width=80, height=60)),
    "office-laser": ("office", 1, 40, "laser", LaserSimSettings()),
}


def record(name: str) -> Path:
    scene_name, seed, n_frames, sensor, sim_settings = SAMPLES[name]
    scene = build_scene(scene_name, seed=seed)
    if sensor == "camera":
        frames = simulate(scene, sim_settings, seed=seed, n_frames=n_frames).frames
    else:
        frames = simulate_laser(scene, sim_settings, seed=seed, n_frames=n_frames).frames
    path = HERE / f"{name}.mcap"
    info = {"sample": name, "scene": scene_name, "seed": str(seed), "frames": str(n_frames), "sensor": sensor,
            "recorded_by": "replay/record_samples.py"}
    t0 = time.perf_counter()
    estimates = record_session(path, scene.floorplan, frames, Settings(), metadata=info)
    last = estimates[-1]
    print(f"{path.name}: {len(estimates)} frames, final status {last.status}, "
          f"{path.stat().st_size / 1e6:.2f} MB, {time.perf_counter() - t0:.1f} s")
    return path


if __name__ == "__main__":
    for sample in sys.argv[1:] or list(SAMPLES):
        record(sample)
