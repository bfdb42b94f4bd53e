"""What the vector readers produce: VectorGeometry (open polylines, closed rings, circles, in
metres) with its checks, and the limits every reader applies. Every coordinate is checked
finite (coordinates) as it is added."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import FloorplanError
from ...settings.documents import real_number
from ..raster_files import MAX_COORDINATE


VECTOR_SUFFIXES = (".dxf", ".svg", ".geojson", ".json")
ARC_CHORD = 0.05  # m, arcs and curves are flattened to chords deviating at most this much
CIRCLE_FIT_TOLERANCE = 0.02  # relative spread of a ring's vertex radii for it to be a circle
MIN_CIRCLE_VERTICES = 8
MAX_CURVE_CHORDS = 1_000_000  # a longer SVG curve (50 km at ARC_CHORD) is a unit mistake, not a wall
MIN_PLAN_SPAN = 1.0  # m: a drawing smaller than this either way is in another unit than declared


@dataclass
class VectorGeometry:
    """Drawing contents in metres: open polylines, closed rings, circles (cx, cy, r)."""

    polylines: list[np.ndarray] = field(default_factory=list)
    rings: list[np.ndarray] = field(default_factory=list)
    circles: list[tuple[float, float, float]] = field(default_factory=list)

    def add(self, points, closed: bool, what: str = "a shape") -> None:
        p = coordinates(points, what)
        if closed and len(p) > 1 and np.allclose(p[0], p[-1]):
            p = p[:-1]
        if len(p) >= 3 and closed:
            self.rings.append(p)
        elif len(p) >= 2:
            self.polylines.append(np.vstack([p, p[:1]]) if closed else p)

    def add_circle(self, x, y, r, what: str = "a circle") -> None:
        """A circle (centre, radius) in drawing units: finite, radius > 0."""
        cx, cy = coordinates([(x, y)], what)[0]
        radius = real_number(r)
        if radius is None or not (math.isfinite(radius) and radius > 0):
            raise FloorplanError(f"{what} has radius {r!r}: a radius must be a finite number > 0")
        self.circles.append((float(cx), float(cy), radius))

    def check_reach(self, source) -> None:
        """After scaling to metres: every coordinate within MAX_COORDINATE of 0."""
        shapes = [p for p in (*self.polylines, *self.rings) if len(p)]
        reach = max([0.0] + ([float(np.abs(np.concatenate(shapes)).max())] if shapes else [])
                    + [abs(x) + r for x, _, r in self.circles] + [abs(y) + r for _, y, r in self.circles])
        if not math.isfinite(reach) or reach > MAX_COORDINATE:
            raise FloorplanError(f"{source}: the drawing reaches {reach:.3g} m from 0 (more than {MAX_COORDINATE:.0e} m): "
                                 "a wrong unit, or a stray coordinate")

    def check_span(self, source, unit: str) -> None:
        """A floor is metres across: a drawing under MIN_PLAN_SPAN both ways was drawn in a
        larger unit than the one it is read in (metres under a millimetre header)."""
        points = np.vstack([*self.polylines, *self.rings, np.zeros((0, 2))])
        ends = [points.min(axis=0), points.max(axis=0)] if len(points) else []
        for x, y, r in self.circles:
            ends += [np.array([x - r, y - r]), np.array([x + r, y + r])]
        if not ends:
            return
        span = np.max(ends, axis=0) - np.min(ends, axis=0)
        if span.max() < MIN_PLAN_SPAN:
            raise FloorplanError(f"{source}: the drawing spans {span[0]:.3g} x {span[1]:.3g} m read in {unit}: too small for a floor; "
                                 "if it is drawn in another unit, pass --scale METRES_PER_UNIT (1 for metres)")

    def scaled(self, factor: float, flip_y: bool = False) -> VectorGeometry:
        s = np.array([factor, -factor if flip_y else factor])
        with np.errstate(over="ignore"):  # a coordinate scaled past float range: check_reach refuses it
            return VectorGeometry([p * s for p in self.polylines], [r * s for r in self.rings],
                                  [(x * s[0], y * s[1], r * factor) for x, y, r in self.circles])

    def is_empty(self) -> bool:
        return not (self.polylines or self.rings or self.circles)


def coordinates(points, what: str) -> np.ndarray:
    """(N, 2) float coordinates; FloorplanError naming `what` when they are not finite numbers."""
    try:
        with np.errstate(over="ignore"):
            p = np.asarray(points, dtype=float).reshape(-1, 2)
    except (TypeError, ValueError, OverflowError):
        raise FloorplanError(f"{what} has coordinates that are not pairs of numbers") from None
    if not np.isfinite(p).all():
        raise FloorplanError(f"{what} has a coordinate that is not a finite number ({_first_bad(p)})")
    return p


def _first_bad(p: np.ndarray) -> str:
    row = p[~np.isfinite(p).all(axis=1)][0]
    return f"({float(row[0])!r}, {float(row[1])!r})"
