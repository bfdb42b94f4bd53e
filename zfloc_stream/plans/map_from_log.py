"""map-from-log: an occupancy map rasterised from laser scans with known poses.

Log-odds per cell, one update per scan: cells crossed by a beam (stopped `free_margin`
short of its return; no-returns clipped to `free_range`) get `logodds_free`; cells holding
a beam end (a real return, any range) get `logodds_hit`. A cell is a wall when its
log-odds exceed `occupied_threshold`. Frame ranges can be left out, which gives a held-out
map for a window: the walls it shows come from other passes.

Beams are drawn as line segments (one cv2.polylines call per scan, in a crop around it),
not as a filled scan polygon: a polygon's chords between neighbouring beam ends run along
walls seen at grazing angles and would erase them.
"""

from __future__ import annotations

from collections.abc import Sequence as Seq

import cv2
import numpy as np

from ..settings.loading import MappingSettings, Settings
from ..errors import InputError

SUBPIXEL_BITS = 4  # cv2.polylines fixed-point precision


def _included(n_scans: int, exclude: Seq[tuple[int, int]]) -> np.ndarray:
    keep = np.ones(n_scans, dtype=bool)
    for start, stop in exclude:
        keep[max(int(start), 0) : max(int(stop), 0)] = False
    return keep


def parse_exclude(text: str, option: str = "--exclude") -> tuple[int, int]:
    """'A:B' -> (A, B): scans A (included) to B (excluded), 0-based, in file order (also
    `run --scans`, the window such a held-out map leaves out)."""
    try:
        a, b = (int(v) for v in text.split(":"))
    except ValueError:
        raise InputError(f"{option} '{text}' must look like START:STOP (scan indices, STOP excluded)") from None
    if a < 0 or b <= a:
        raise InputError(f"{option} '{text}': need 0 <= START < STOP")
    return a, b


def rasterize_scans(
    poses: np.ndarray,
    ranges: list[np.ndarray],
    angle_min: np.ndarray,
    angle_increment: np.ndarray,
    max_range: np.ndarray,
    cfg: MappingSettings,
    min_range: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Log-odds grid (H, W), row 0 = smallest y, and its origin (x, y), from scans
    (sensor poses (N, 3) in the map frame, beams as in a LaserFrame)."""
    res = cfg.resolution
    hits, fans = [], []  # per scan: beam ends that hit; sensor + free-space ends of every beam
    for pose, r, a0, da, rmax in zip(poses, ranges, angle_min, angle_increment, max_range):
        r = np.asarray(r, dtype=float)
        angles = pose[2] + a0 + da * np.arange(r.size)
        finite = np.isfinite(r)
        valid = finite & (r >= min_range) & (r < rmax)
        # free space stops free_margin short of a return, so grazing beams of other scans
        # do not erase thin walls; no-returns clear up to free_range
        reach = np.where(valid, r - cfg.free_margin, np.where(finite, r, rmax))
        reach = np.clip(reach, 0.0, cfg.free_range)
        direction = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        fans.append(np.vstack([pose[:2], pose[:2] + reach[:, None] * direction]))
        hits.append(pose[:2] + r[valid, None] * direction[valid])
    if not fans:
        raise InputError("map-from-log: no scan left to map (every scan excluded?)")
    every = np.vstack(fans + hits)
    lo = np.floor((every.min(axis=0) - cfg.padding) / res) * res
    hi = every.max(axis=0) + cfg.padding
    width, height = (np.ceil((hi - lo) / res).astype(int) + 1).tolist()
    logodds = np.zeros((height, width), dtype=np.float32)
    scale = 1 << SUBPIXEL_BITS
    for fan, hit in zip(fans, hits):
        # pixel coordinates: cell (row, col) centre sits at integer (col, row) for cv2
        px = (fan - lo) / res - 0.5
        c0, r0 = np.maximum(np.floor(px.min(axis=0)).astype(int) - 1, 0)
        c1, r1 = np.minimum(np.ceil(px.max(axis=0)).astype(int) + 2, [width, height])
        free = np.zeros((r1 - r0, c1 - c0), dtype=np.uint8)
        local = np.round((px - [c0, r0]) * scale).astype(np.int32)
        beams = np.stack([np.broadcast_to(local[0], local[1:].shape), local[1:]], axis=1)  # (n, 2, 2)
        cv2.polylines(free, list(beams), isClosed=False, color=1, thickness=1, lineType=cv2.LINE_8, shift=SUBPIXEL_BITS)
        cells = np.floor((hit - lo) / res).astype(int)
        rows, cols = cells[:, 1], cells[:, 0]
        inside = (rows >= r0) & (rows < r1) & (cols >= c0) & (cols < c1)
        free[rows[inside] - r0, cols[inside] - c0] = 0  # a hit cell is not also free this scan
        logodds[r0:r1, c0:c1] += cfg.logodds_free * free
        flat = np.unique(rows * width + cols)
        logodds.ravel()[flat] += cfg.logodds_hit
    return logodds, lo


def map_from_log(log, exclude: Seq[tuple[int, int]] = (), settings: Settings | None = None, resolution: float | None = None):
    """Floorplan rasterised from a CarmenLog (or anything with poses, ranges, angle_min,
    angle_increment, max_range), leaving out scans in the [start, stop) ranges of exclude."""
    from .floorplan import Floorplan

    settings = settings if settings is not None else Settings()
    logodds, origin, res = log_odds_map(log, exclude, settings, resolution)
    name = f"{getattr(log, 'path', 'log')}".rsplit("/", 1)[-1]
    return Floorplan.from_occupancy(logodds > settings.datasets.mapping.occupied_threshold, res, origin,
                                    settings=settings, name=name)


def log_odds_map(log, exclude: Seq[tuple[int, int]] = (), settings: Settings | None = None,
                 resolution: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(log-odds grid, origin, resolution) that map_from_log thresholds, cropped to its
    walls (+ padding) as the floorplan is: cells below 0 are free space the scans saw."""
    settings = settings if settings is not None else Settings()
    cfg = settings.datasets.mapping
    if resolution is not None:
        if not (np.isfinite(resolution) and resolution > 0):
            raise InputError(f"map resolution must be positive, got {resolution}")
        cfg = cfg.model_copy(update={"resolution": float(resolution)})
    keep = _included(len(log.ranges), exclude)
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        raise InputError("map-from-log: every scan is excluded")
    logodds, origin = rasterize_scans(
        log.poses[idx],
        [log.ranges[i] for i in idx],
        log.angle_min[idx],
        log.angle_increment[idx],
        log.max_range[idx],
        cfg,
        min_range=settings.datasets.carmen.min_range,
    )
    occupied = logodds > cfg.occupied_threshold
    if not occupied.any():
        raise InputError("map-from-log: no wall was observed in the scans kept")
    # crop to the walls (+ padding): far free space carries nothing a floorplan uses
    pad = int(np.ceil(cfg.padding / cfg.resolution))
    rows, cols = np.nonzero(occupied)
    r0, c0 = max(rows.min() - pad, 0), max(cols.min() - pad, 0)
    logodds = logodds[r0 : rows.max() + pad + 1, c0 : cols.max() + pad + 1]
    return logodds, origin + cfg.resolution * np.array([c0, r0]), cfg.resolution
