"""A raster map redrawn as an architect's plan: straight wall segments, no clutter.

    segments = draw_plan(floorplan)                      # (N, 2, 2) metres, one line per wall
    write_plan_dxf(segments, "plan.dxf")                 # LINEs in metres, loaded by the vector path
    write_plan_dxf(two_faces(segments, 0.2, (free, origin, res)), "plan.dxf")  # both faces of each wall

What a plan holds and a map made by the sensor does not: walls only. So the map's wall
cells are cleaned of blobs smaller than `min_blob` (furniture, people, scan noise), wall
segments are fitted to the rest with OpenCV's probabilistic Hough transform (segments of at
least `min_length`, pixel gaps shorter than `max_gap` bridged, so door openings stay gaps),
the parallel duplicates a thick wall gives are merged (vector_floorplan.merge_collinear, then
primitives.deduplicate_lines) and pieces still shorter than `min_length` dropped. Walls the
fit misses stay missing: a plan drawn from a map is an imperfect plan, as real ones are.

Used by benchmarks/evaluation/eval_real.py --plan-style to localize against plans of real buildings
(the Carmen logs' held-out maps) instead of the maps themselves; nothing in the package
needs it, so it lives beside its one user (tests/test_plan_drawing.py loads it by path).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from zfloc_stream.settings.loading import LineSettings
from zfloc_stream.plans.floorplan import Floorplan, blob_spans
from zfloc_stream.geometry.shapes import LineSet
from zfloc_stream.primitives.extract import deduplicate_lines
from zfloc_stream.plans.vector import merge_collinear


def _samples(count: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(owner, k): count[i] samples of segment i, each with its segment and its index
    0..count[i]-1 along it."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(len(owner)) - np.repeat(np.cumsum(count) - count, count)


def _support(walls: np.ndarray, cols_rows: np.ndarray) -> np.ndarray:
    """(N,) share of each pixel segment's points (one per pixel) on or next to a wall pixel."""
    near = ndimage.binary_dilation(walls, structure=np.ones((3, 3), dtype=bool))
    length = np.linalg.norm(cols_rows[:, 1] - cols_rows[:, 0], axis=1)
    count = np.ceil(length).astype(np.int64) + 1
    owner, k = _samples(count)
    t = k / np.repeat(np.maximum(count - 1, 1), count)
    p = np.rint(cols_rows[owner, 0] + t[:, None] * (cols_rows[owner, 1] - cols_rows[owner, 0])).astype(np.int64)
    on = near[np.clip(p[:, 1], 0, walls.shape[0] - 1), np.clip(p[:, 0], 0, walls.shape[1] - 1)]
    return np.bincount(owner, weights=on, minlength=len(cols_rows)) / count


def draw_plan(floorplan: Floorplan, min_length: float = 0.5, min_blob: float = 0.6, max_gap: float = 0.25,
              merge_offset: float = 0.1, votes: float = 0.3, min_support: float = 0.85) -> np.ndarray:
    """(N, 2, 2) wall segments in metres fitted to the floorplan's wall cells.

    min_length: shortest wall drawn (m); min_blob: blobs whose bounding box is smaller
    than this (m), pixels up to max_gap apart joined, are clutter; max_gap: wall pixels this far apart (m) along a segment are
    one wall, larger openings (doors) stay open; merge_offset: parallel pieces this close
    (m) are one wall (a thick wall's several Hough lines); votes: the Hough accumulator
    threshold as a length (m) of wall pixels on the line; min_support: the share of a
    segment's length that must run on wall pixels (the Hough transform also joins
    scattered clutter into lines)."""
    res = floorplan.resolution
    # clutter: blobs smaller than min_blob once pixels up to max_gap apart are joined (a wall
    # seen from afar is a dotted line of single cells; a chair leg or a person is a speck)
    reach = max(int(round(max_gap / res / 2)), 1)
    joined = ndimage.binary_dilation(floorplan.occupied, structure=np.ones((2 * reach + 1,) * 2, dtype=bool))
    labels, span = blob_spans(joined)
    keep = span - 2 * reach >= min_blob / res
    keep[0] = False
    walls = floorplan.occupied & keep[labels]
    if not walls.any():
        return np.zeros((0, 2, 2))
    found = cv2.HoughLinesP(walls.astype(np.uint8) * 255, 1, np.pi / 360, max(int(round(votes / res)), 2),
                            minLineLength=max(min_length / res, 2.0), maxLineGap=max_gap / res)
    if found is None:
        return np.zeros((0, 2, 2))
    cols_rows = found.reshape(-1, 2, 2).astype(float)  # (col, row) pixel centres
    cols_rows = cols_rows[_support(walls, cols_rows) >= min_support]  # no lines across scattered clutter
    segs = floorplan.origin + (cols_rows + 0.5) * res
    segs = merge_collinear(segs, angle_deg=3.0, offset=merge_offset, gap=max_gap)
    segs = segs[np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) >= min_length]
    if not len(segs):
        return segs
    dedup = LineSettings(dedup_angle_deg=3.0, dedup_offset=merge_offset + res)
    return deduplicate_lines(LineSet.from_endpoints(segs), dedup).endpoints.copy()


def two_faces(segments: np.ndarray, thickness: float, seen_free=None) -> np.ndarray:
    """Each wall drawn as its two faces, thickness apart, as plans draw walls: (2N, 2, 2).

    A segment drawn from a map lies on the surface the sensor saw. seen_free = (free,
    origin, resolution), the map's free cells (bool, row 0 at the smallest y): a wall seen
    from one side (half the probes 0.1-0.3 m off it land on free cells) keeps its segment
    as that face and gets its other face thickness behind it, on the side the sensor never
    saw; a wall seen from both sides, which the map shows as one line, is thin: faces one
    map cell apart. Without seen_free, or for a wall seen from neither side, the faces lie
    thickness/2 either side of the segment: the face toward a room then lies inside the
    open space the sensor saw ("two-face-centred" plans)."""
    segs = np.asarray(segments, dtype=float).reshape(-1, 2, 2)
    d = segs[:, 1] - segs[:, 0]
    n = np.stack([-d[:, 1], d[:, 0]], axis=1) / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    plus_face = np.full(len(segs), 0.5 * thickness)  # offset of the face on the +n side
    minus_face = np.full(len(segs), -0.5 * thickness)  # and of the face on the -n side
    if seen_free is not None and len(segs):
        free, origin, res = seen_free
        plus, minus = (_free_share(segs, sign * n, free, np.asarray(origin, dtype=float), res) >= 0.5 for sign in (1, -1))
        plus_face[plus & ~minus], minus_face[plus & ~minus] = 0.0, -thickness
        plus_face[minus & ~plus], minus_face[minus & ~plus] = thickness, 0.0
        plus_face[plus & minus], minus_face[plus & minus] = 0.5 * res, -0.5 * res
    return np.concatenate([segs + plus_face[:, None, None] * n[:, None, :], segs + minus_face[:, None, None] * n[:, None, :]])


def _free_share(segs: np.ndarray, n: np.ndarray, free: np.ndarray, origin: np.ndarray, res: float,
                depths=(0.1, 0.2, 0.3), spacing: float = 0.1) -> np.ndarray:
    """Per segment, the share of probes `depths` metres off its middle 80% (every `spacing`
    m) along n that land on free cells."""
    length = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1)
    count = np.maximum(np.ceil(0.8 * length / spacing).astype(np.int64), 1)
    owner, k = _samples(count)
    t = 0.1 + 0.8 * (k + 0.5) / np.repeat(count, count)
    along = segs[owner, 0] + t[:, None] * (segs[owner, 1] - segs[owner, 0])
    hits = np.zeros(len(segs))
    for depth in depths:
        p = along + depth * n[owner]
        col = np.floor((p[:, 0] - origin[0]) / res).astype(np.int64)
        row = np.floor((p[:, 1] - origin[1]) / res).astype(np.int64)
        inside = (row >= 0) & (row < free.shape[0]) & (col >= 0) & (col < free.shape[1])
        on = np.zeros(len(p), dtype=bool)
        on[inside] = free[row[inside], col[inside]]
        hits += np.bincount(owner, weights=on, minlength=len(segs))
    return hits / (len(depths) * count)


def write_plan_dxf(segments: np.ndarray, path) -> Path:
    """The segments as LINE entities on layer WALLS, in metres ($INSUNITS 6)."""
    import ezdxf

    path = Path(path)
    doc = ezdxf.new(units=6)
    doc.layers.add("WALLS")
    msp = doc.modelspace()
    for a, b in np.asarray(segments, dtype=float).reshape(-1, 2, 2):
        msp.add_line((float(a[0]), float(a[1])), (float(b[0]), float(b[1])), dxfattribs={"layer": "WALLS"})
    doc.saveas(path)
    return path


__all__ = ["draw_plan", "two_faces", "write_plan_dxf"]
