"""Reading an SVG drawing (svgelements; `scale` metres per user unit, y flipped up): paths,
shapes and their curves as chords within ARC_CHORD, circles kept as circles; <use>
references counted before anything is expanded."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import IntegrationWarning

from ...errors import FloorplanError
from ...settings.documents import MAX_NESTING
from .geometry import ARC_CHORD, MAX_CURVE_CHORDS, VectorGeometry, coordinates


def _svg_expansion(path: Path, max_entities: int) -> int:
    """Elements the SVG expands to, every <use> counted as what it references (per id
    once), before svgelements expands anything: FloorplanError past max_entities or for a
    <use> that references itself. expat refuses entity bombs and reads no external entity."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except OSError as err:
        raise FloorplanError(f"cannot read SVG floorplan {path}: {err.strerror or err}") from None
    except (ET.ParseError, ValueError, RecursionError) as err:
        raise FloorplanError(f"{path}: not a readable SVG file ({type(err).__name__}: {err})") from None
    by_id = {e.get("id"): e for e in root.iter() if e.get("id")}
    counts: dict[int, int] = {}
    href_keys = ("href", "{http://www.w3.org/1999/xlink}href")

    def count(element, inside: tuple[int, ...]) -> int:
        key = id(element)
        if key in counts:
            return counts[key]
        if key in inside:
            raise FloorplanError(f"{path}: an SVG <use> references an element that contains it (a cycle)")
        if len(inside) > 4 * MAX_NESTING:
            raise FloorplanError(f"{path}: SVG elements nested deeper than {4 * MAX_NESTING} levels (with <use> references)")
        total = 1
        for child in element:
            total += count(child, (*inside, key))
        if element.tag.rsplit("}", 1)[-1] == "use":
            ref = next((element.get(k) for k in href_keys if element.get(k)), "")
            target = by_id.get(ref[1:]) if ref.startswith("#") else None
            if target is not None:
                total += count(target, (*inside, key))
        if total > max_entities:
            raise FloorplanError(f"{path}: the SVG expands to more than {max_entities:,} elements (<use> of groups of <use>): "
                                 "a bomb, not a floor (--set datasets.vector_floorplan.max_entities=N raises the limit)")
        counts[key] = total
        return total

    return count(root, ())


def read_svg(path: Path, scale, max_entities: int = 1_000_000) -> VectorGeometry:
    import svgelements as se

    if scale is None:
        raise FloorplanError(f"{path}: an SVG floorplan has no real-world unit: pass --scale METRES_PER_UNIT (e.g. 0.01 when 1 unit = 1 cm)")
    _svg_expansion(path, max_entities)
    try:
        svg = se.SVG.parse(str(path), reify=True)
    except OSError as err:
        raise FloorplanError(f"cannot read SVG floorplan {path}: {err.strerror or err}") from None
    except Exception as err:  # noqa: BLE001 - svgelements raises XML and value errors of many kinds
        raise FloorplanError(f"{path}: not a readable SVG file ({type(err).__name__}: {err})") from None
    if not isinstance(svg, se.SVG):  # a damaged file parses to a bare element, or to nothing
        raise FloorplanError(f"{path}: not an SVG drawing (no <svg> root element)")
    geometry = VectorGeometry()
    with warnings.catch_warnings():
        # svgelements measures curves by numerical integration, which warns on extreme values
        # (refused below by their own checks): not the user's business
        warnings.simplefilter("ignore", IntegrationWarning)
        _svg_elements(svg, se, path, scale, geometry)
    geometry = geometry.scaled(scale, flip_y=True)
    geometry.check_reach(path)
    return geometry


def _svg_elements(svg, se, path: Path, scale: float, geometry: VectorGeometry) -> None:
    for k, element in enumerate(svg.elements()):
        what = f"{path}: SVG element {k} <{type(element).__name__.lower()}>"
        try:
            round_shape = isinstance(element, se.Circle) or (isinstance(element, se.Ellipse) and abs(element.rx - element.ry) < 1e-9 * max(element.rx, 1))
            m = element.transform if isinstance(element, se.Shape) else None
            similar = m is not None and abs(m.a - m.d) <= 1e-9 * (abs(m.a) + abs(m.b)) and abs(m.b + m.c) <= 1e-9 * (abs(m.a) + abs(m.b))
            mirrored = m is not None and abs(m.a + m.d) <= 1e-9 * (abs(m.a) + abs(m.b)) and abs(m.b - m.c) <= 1e-9 * (abs(m.a) + abs(m.b))
            if round_shape and (similar or mirrored):  # a circle stays a circle: its centre and radius moved
                centre = m.point_in_matrix_space((element.cx, element.cy))
                geometry.add_circle(centre.x, centre.y, element.rx * math.sqrt(abs(m.a * m.d - m.b * m.c)), what)
            elif isinstance(element, se.Shape):
                # reify leaves a rotation or skew on rects and ellipses: abs() applies it (a
                # copy of every segment: a path reify has already placed is read as it is)
                placed = isinstance(element, se.Path) and element.transform.is_identity()
                for sub in (element if placed else abs(se.Path(element))).as_subpaths():
                    sub = se.Path(sub)
                    points, closed = [], False
                    for seg in sub:
                        if isinstance(seg, se.Move):
                            points.append((seg.end.x, seg.end.y))
                        elif isinstance(seg, se.Close):
                            closed = True
                        elif isinstance(seg, se.Line):
                            points.append((seg.end.x, seg.end.y))
                        else:  # curves: enough chords for ARC_CHORD at this scale
                            coordinates([(seg.start.x, seg.start.y), (seg.end.x, seg.end.y)], what)
                            chords = seg.length() * scale / (4 * ARC_CHORD)
                            if not math.isfinite(chords) or chords > MAX_CURVE_CHORDS:
                                raise FloorplanError(f"{what}: a curve {seg.length() * scale:.3g} m long: not a wall of one floor")
                            n = max(int(math.ceil(chords)), 2)
                            points += [(q.x, q.y) for q in (seg.point(t) for t in np.linspace(0, 1, n + 1)[1:])]
                    geometry.add(points, closed, what)
        except FloorplanError:
            raise
        except (ValueError, OverflowError, ZeroDivisionError, TypeError, ArithmeticError, AttributeError) as err:
            raise FloorplanError(f"{what} cannot be read ({type(err).__name__}: {err})".replace("\n", " ")) from None
