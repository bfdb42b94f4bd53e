"""The qualitative figure: floorplan, aligned BEV, true and estimated trajectories."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .floorplan import Floorplan
    from .sim2 import Sim2


def save_overlay(
    path: str | Path,
    floorplan: Floorplan,
    estimated: np.ndarray,
    truth: np.ndarray | None = None,
    bev_wall_points: np.ndarray | None = None,
    alignment: Sim2 | None = None,
    title: str = "",
) -> Path:
    """estimated / truth: (N, 3) poses in the floorplan (rows of NaN where none)."""
    import matplotlib  # here, not at import: a CLI error must not wait ~0.5 s for it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    x0, y0 = floorplan.origin
    h, w = floorplan.occupied.shape
    res = floorplan.resolution
    fig, ax = plt.subplots(figsize=(8, 8 * h / max(w, 1) + 0.5))
    ax.imshow(
        np.where(floorplan.occupied, 0.15, 1.0),
        cmap="gray",
        vmin=0,
        vmax=1,
        origin="lower",
        extent=(x0, x0 + w * res, y0, y0 + h * res),
        interpolation="nearest",
    )
    if bev_wall_points is not None and alignment is not None and len(bev_wall_points):
        aligned = alignment.apply(bev_wall_points)
        ax.scatter(aligned[:, 0], aligned[:, 1], s=1.5, c="tab:orange", label="BEV walls (aligned)", lw=0)
    if truth is not None and len(truth):
        ax.plot(truth[:, 0], truth[:, 1], "-", c="tab:blue", lw=2, label="ground truth")
        ax.plot(truth[-1, 0], truth[-1, 1], "o", c="tab:blue")
    est = np.asarray(estimated, dtype=float).reshape(-1, 3)
    if np.isfinite(est).any():
        ax.plot(est[:, 0], est[:, 1], "-", c="tab:green", lw=1.5, label="estimate")
        last = est[np.isfinite(est[:, 0])][-1]
        ax.arrow(last[0], last[1], 0.8 * np.cos(last[2]), 0.8 * np.sin(last[2]), color="tab:green", width=0.08)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    ax.legend(loc="upper right", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
