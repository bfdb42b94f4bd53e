"""The qualitative figure: floorplan, aligned BEV, true and estimated trajectories.

The estimated path is coloured by the localizer's status at each frame (a stretch the
tracker called ambiguous or lost reads as such), the start of each path has a marker,
and every marker drawn has its legend entry. Where the reported estimate jumps (another
mode is reported, or the tracked one is re-anchored far away) the path is broken and the
landing marked: a line there would draw travel through walls that never happened."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..plans.floorplan import Floorplan
    from ..geometry.sim2 import Sim2


STATUS_COLOURS = {"initializing": "tab:gray", "tracking": "tab:green", "ambiguous": "tab:purple", "lost": "tab:red"}
# metres between where the previous frame's alignment puts this frame and where it is
# reported beyond which the step is a jump, not travel (local refinement moves centimetres)
JUMP_DISTANCE = 1.0


def jumps(estimated: np.ndarray, alignments, distance: float = JUMP_DISTANCE) -> np.ndarray:
    """(N,) bool: frame i's estimate jumped from the previous posed frame's. The frame's
    odometry-plane position (its alignment undone) is carried by the previous frame's
    alignment: travel lands where it is reported, a switch to another mode (or a far
    re-anchoring) does not. Frames without an alignment never count as jumps."""
    est = np.asarray(estimated, dtype=float).reshape(-1, 3)
    out = np.zeros(len(est), dtype=bool)
    previous = None
    for i, (pose, alignment) in enumerate(zip(est, alignments)):
        if alignment is None or not np.isfinite(pose).all():
            continue
        if previous is not None:
            plane = alignment.inverse().apply(pose[None, :2])
            out[i] = float(np.linalg.norm(previous.apply(plane)[0] - pose[:2])) > distance
        previous = alignment
    return out


def save_overlay(path: str | Path, floorplan: Floorplan, estimated: np.ndarray, truth: np.ndarray | None = None, **kwargs) -> Path:
    """The figure of overlay_figure written to path (PNG)."""
    fig = overlay_figure(floorplan, estimated, truth, **kwargs)
    path = Path(path)
    fig.savefig(path, dpi=110)
    _pyplot().close(fig)
    return path


def _pyplot():
    """matplotlib.pyplot on the Agg backend, imported on first use: a CLI error must not
    wait ~0.5 s for it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def overlay_figure(
    floorplan: Floorplan,
    estimated: np.ndarray,
    truth: np.ndarray | None = None,
    bev_wall_points: np.ndarray | None = None,
    alignment: Sim2 | None = None,
    title: str = "",
    statuses: list[str] | None = None,
    alignments: list | None = None,
):
    """estimated / truth: (N, 3) poses in the floorplan (rows of NaN where none); statuses:
    the status of each estimated frame (the path's colours; one colour without them);
    alignments: each frame's reported alignment (Sim2 or None), to break the path where
    the estimate jumps (see jumps)."""
    plt = _pyplot()
    from matplotlib.collections import LineCollection
    from matplotlib.lines import Line2D

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
    handles = []
    if bev_wall_points is not None and alignment is not None and len(bev_wall_points):
        aligned = alignment.apply(bev_wall_points)
        ax.scatter(aligned[:, 0], aligned[:, 1], s=1.5, c="tab:orange", lw=0)
        handles.append(Line2D([], [], ls="", marker="o", ms=3, c="tab:orange", label="BEV walls (aligned, last frame)"))
    if truth is not None and np.isfinite(truth[:, :2]).any():
        known = truth[np.isfinite(truth[:, :2]).all(axis=1)]
        ax.plot(known[:, 0], known[:, 1], "-", c="tab:blue", lw=2)
        handles.append(Line2D([], [], c="tab:blue", lw=2, label="ground truth"))
        ax.plot(known[0, 0], known[0, 1], "s", c="tab:blue", mfc="white", ms=8, mew=2)
        handles.append(Line2D([], [], ls="", marker="s", c="tab:blue", mfc="white", ms=8, mew=2, label="ground truth start"))
        ax.plot(known[-1, 0], known[-1, 1], "o", c="tab:blue", ms=7)
        handles.append(Line2D([], [], ls="", marker="o", c="tab:blue", ms=7, label="ground truth end"))
    est = np.asarray(estimated, dtype=float).reshape(-1, 3)
    posed = np.isfinite(est).all(axis=1)
    if posed.any():
        idx = np.flatnonzero(posed)
        status = list(statuses) if statuses is not None and len(statuses) == len(est) else ["tracking"] * len(est)
        jumped = jumps(est, alignments) if alignments is not None and len(alignments) == len(est) else np.zeros(len(est), bool)
        # One segment per pair of consecutive posed frames, in the colour of the later frame's
        # status; none into a frame whose estimate jumped there.
        pairs = [(a, b) for a, b in zip(idx[:-1], idx[1:]) if not jumped[b]]
        segments = [est[[a, b], :2] for a, b in pairs]
        colour = lambda s: STATUS_COLOURS.get(s, "tab:olive")  # noqa: E731 (a status added later still gets drawn)
        colours = [colour(status[b]) for _, b in pairs]
        if segments:
            ax.add_collection(LineCollection(segments, colors=colours, linewidths=1.8))
        if jumped.any():
            ax.plot(est[jumped, 0], est[jumped, 1], "x", c="black", ms=7, mew=1.5)
        present = {status[b] for _, b in pairs} or {status[idx[0]]}  # the colours drawn
        shown = [s for s in (*STATUS_COLOURS, *sorted(present - set(STATUS_COLOURS))) if s in present] if statuses is not None else []
        for s in shown:
            handles.append(Line2D([], [], c=colour(s), lw=1.8, label=f"estimate ({s})"))
        if not shown:
            handles.append(Line2D([], [], c="tab:green", lw=1.8, label="estimate"))
        first, last = est[idx[0]], est[idx[-1]]
        ax.plot(first[0], first[1], "^", c="black", mfc="yellow", ms=9)
        handles.append(Line2D([], [], ls="", marker="^", c="black", mfc="yellow", ms=9, label="estimate start (first pose)"))
        if jumped.any():
            handles.append(Line2D([], [], ls="", marker="x", c="black", ms=7, mew=1.5,
                                  label=f"estimate jumped here ({int(jumped.sum())}x: another place reported, not travel)"))
        ax.arrow(last[0], last[1], 0.8 * np.cos(last[2]), 0.8 * np.sin(last[2]), color="black", width=0.08)
        handles.append(Line2D([], [], ls="", marker=r"$\rightarrow$", c="black", ms=12, label="final estimated pose and heading"))
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")
    if handles:
        ax.legend(handles=handles, loc="upper right", fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig
