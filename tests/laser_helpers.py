"""Simulated 2D laser walks and the Carmen logs written from them (the real-building and
CLI tests' shared inputs)."""

import numpy as np

from zfloc_stream.sim import LaserSimSettings, build_scene, simulate_laser

LASER = LaserSimSettings(fov_deg=180.0, n_beams=180, max_range=10.0)


def laser_run(scene_name: str, n_frames: int, seed: int = 0):
    scene = build_scene(scene_name, seed=seed)
    return scene, simulate_laser(scene, LASER, seed=seed, n_frames=n_frames)


def write_carmen(path, seq, stamp_digits: int) -> None:
    """FLASER lines (180 beams over 180 deg from -90, the Carmen default) whose timestamps
    are printed with few digits, so neighbouring scans share a stamp, as in real logs."""
    lines = []
    for k, frame in enumerate(seq.frames):
        x, y, theta = frame.ground_truth
        ranges = np.where(frame.valid, frame.ranges, 81.83)
        stamp = f"{1e6 + 0.2 * k:.{stamp_digits}g}"
        lines.append(" ".join(["FLASER", str(len(ranges)), *(f"{r:.3f}" for r in ranges),
                               f"{x:.4f}", f"{y:.4f}", f"{theta:.5f}", "0", "0", "0", stamp, "host", stamp]))
    path.write_text("\n".join(lines) + "\n")
