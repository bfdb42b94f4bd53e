"""Stand-in estimates and written sessions for the session tests (the frames they write:
benchmarks/inputs/session_frames.py)."""

from __future__ import annotations

import numpy as np

from zfloc_stream.settings.loading import Settings
from zfloc_stream.estimate import Alternative, Estimate
from zfloc_stream.io.session import SessionWriter
from zfloc_stream.geometry.sim2 import Sim2


def fake_estimate(index: int, timestamp: float) -> Estimate:
    """A deterministic stand-in for a localizer output (statuses, NaN score, alternatives)."""
    rng = np.random.default_rng(1000 + index)
    if index == 0:
        return Estimate(0, timestamp, "initializing", None, None, None, float("nan"), skipped="no walls yet")
    a = Sim2(rng.uniform(0.8, 1.2), rng.uniform(-3, 3), rng.normal(size=2))
    b = Sim2(rng.uniform(0.8, 1.2), rng.uniform(-3, 3), rng.normal(size=2))
    alts = (Alternative(a, rng.normal(size=3), 0.7, 0.55), Alternative(b, rng.normal(size=3), 0.3, 0.41))
    status = ("tracking", "ambiguous", "lost")[index % 3]
    return Estimate(index, timestamp, status, alts[0].pose, np.diag(rng.uniform(0.01, 0.1, 3)), a, 0.55, alts, {"fusion": 0.001 * index})


def write_fake_session(path, frames, settings: Settings | None = None, floorplan=None, estimates: bool = True):
    """Log frames (+ fake estimates); returns the frames as logged."""
    logged = []
    with SessionWriter(path, settings or Settings(), floorplan, metadata={"source": "test"}) as log:
        for i, frame in enumerate(frames):
            f = log.write_frame(i, frame)
            logged.append(f)
            if estimates:
                log.write_estimate(fake_estimate(i, f.timestamp))
    return logged


def record_laser_session(path, n_frames: int = 30, settings: Settings | None = None, scene: str = "rooms", seed: int = 0):
    """Run the real localizer on a simulated 2D laser walk and log it (as the CLI does).
    Returns the estimates."""
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.sim.raycast2d import RangeSensor2D
    from zfloc_stream.runtime.rng import make_rng
    from zfloc_stream.sim import build_scene
    from zfloc_stream.sim.trajectory import random_walk

    settings = settings or Settings()
    plan = build_scene(scene, seed).floorplan
    walk = random_walk(build_scene(scene, seed), make_rng(seed, "walk"), n_frames)
    sensor = RangeSensor2D(n_beams=180, range_noise=0.01)
    localizer = Localizer(plan, settings)
    estimates = []
    with SessionWriter(path, settings, plan, metadata={"source": f"laser walk in {scene}"}) as log:
        for i, p in enumerate(walk):
            frame = log.write_frame(i, sensor.frame(plan, p, p, 0.1 * i, make_rng(seed, "scan", i)))
            est = localizer.push(frame)
            log.write_estimate(est, localizer)
            estimates.append(est)
    return estimates
