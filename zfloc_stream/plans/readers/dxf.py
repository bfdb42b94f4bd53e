"""Reading a DXF drawing (ezdxf: LINE, LWPOLYLINE with bulges, POLYLINE, ARC, CIRCLE, also
inside INSERTs; units from $INSUNITS or --scale). A drawing of LINEs only is read from its
group codes directly (_dxf_lines_only), much faster than ezdxf for 100,000 wall pieces."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ...errors import FloorplanError
from ...settings.documents import MAX_NESTING, real_number
from .geometry import ARC_CHORD, VectorGeometry, coordinates


# Metres per unit of the $INSUNITS codes ezdxf names but cannot convert (exact definitions:
# 1 in = 0.0254 m; a US survey foot is 1200/3937 m).
_DXF_EXTRA_UNITS = {
    8: ("microinches", 0.0254e-6),
    9: ("mils", 0.0254e-3),
    21: ("US survey feet", 1200 / 3937),
    22: ("US survey inches", 100 / 3937),
    23: ("US survey yards", 3600 / 3937),
    24: ("US survey miles", 6336000 / 3937),
}



def _dxf_units(raw, path: Path, scale: float | None) -> float:
    """Metres per drawing unit: scale, else the header's $INSUNITS (raw: its value as read)."""
    import ezdxf.units

    if scale is not None:
        return scale
    code = real_number(raw)
    if code is None or not float(code).is_integer():
        raise FloorplanError(f"{path}: DXF header $INSUNITS = {raw!r} is not a unit code: pass --scale")
    code = int(code)
    if code == 0:
        warnings.warn(f"{path}: the DXF header gives no units ($INSUNITS = 0): taking drawing units as metres (--scale to change)", stacklevel=3)
        return 1.0
    if code in _DXF_EXTRA_UNITS:
        return _DXF_EXTRA_UNITS[code][1]
    try:
        return float(ezdxf.units.conversion_factor(code, ezdxf.units.M))
    except (KeyError, ValueError, IndexError, TypeError):
        try:
            name = f" ({ezdxf.units.unit_name(code)})"
        except (KeyError, ValueError, IndexError, TypeError):
            name = " (a code ezdxf does not know)"
        raise FloorplanError(f"{path}: DXF header $INSUNITS = {code}{name} is not a length unit this reader converts: pass --scale METRES_PER_UNIT") from None


def _dxf_expansion(doc, path: Path, max_entities: int) -> int:
    """Entities the model space expands to, every INSERT counted as its block's expansion
    (times its MINSERT grid), computed per block once, before anything is expanded:
    FloorplanError past max_entities, or for a block that contains itself."""
    counts: dict[str, int] = {}

    def count(entities, inside: tuple[str, ...]) -> int:
        total = 0
        for e in entities:
            if e.dxftype() != "INSERT":
                total += 1
                continue
            name = e.dxf.get("name", "")
            if len(inside) >= MAX_NESTING:
                raise FloorplanError(f"{path}: DXF blocks nested deeper than {MAX_NESTING} levels")
            if name in inside:
                raise FloorplanError(f"{path}: DXF block {name!r} contains itself (INSERT cycle through {' > '.join(inside)})")
            if name not in counts:
                block = doc.blocks.get(name)
                counts[name] = 0 if block is None else count(block, (*inside, name))
            grid = max(int(e.dxf.get("row_count", 1) or 1), 1) * max(int(e.dxf.get("column_count", 1) or 1), 1)
            total += 1 + grid * counts[name]
            if total > max_entities:
                raise FloorplanError(
                    f"{path}: the DXF expands to more than {max_entities:,} entities (block references nested in blocks): "
                    "a bomb, not a floor (--set datasets.vector_floorplan.max_entities=N raises the limit)")
        return total

    return count(doc.modelspace(), ())


_DXF_SECTIONS = {b"HEADER", b"CLASSES", b"TABLES", b"BLOCKS", b"ENTITIES", b"OBJECTS", b"THUMBNAILIMAGE", b"ACDSDATA"}


def _dxf_lines_only(path: Path) -> tuple[int, np.ndarray] | None:
    """A drawing whose model space holds LINEs only (a generated plan, an export of
    100,000 wall pieces), read from its group codes directly: ($INSUNITS, (N, 2, 2) start
    and end of every LINE in file order), what ezdxf's document and paths give for such a
    drawing (ezdxf takes ~9 s to build 100,000 entity objects; this scan ~0.5 s). None for
    anything else: a binary DXF, another entity in ENTITIES (INSERT, LWPOLYLINE, TEXT...),
    a paper-space entity, a LINE missing a coordinate or holding one that is not a finite
    number, a tag out of place: ezdxf then reads the file (and words any error)."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if data.startswith(b"AutoCAD Binary DXF"):
        return None
    lines = data.split(b"\n")
    if lines and not lines[-1].strip():
        lines.pop()
    if len(lines) % 2:
        return None
    try:
        codes = list(map(int, lines[0::2]))  # every group code an integer, or not a DXF this scan reads
    except ValueError:
        return None
    values = lines[1::2]
    n = len(codes)
    units = 0  # ezdxf's header.get("$INSUNITS", 0) for a header without it
    ends: list[float] = []
    try:
        i = 0
        while i < n:
            code, value = codes[i], values[i].strip()
            if code == 999:  # a comment
                i += 1
                continue
            if code != 0:
                return None
            if value == b"EOF":
                break
            if value != b"SECTION" or i + 1 >= n or codes[i + 1] != 2 or values[i + 1].strip() not in _DXF_SECTIONS:
                return None
            name = values[i + 1].strip()
            i += 2
            while i < n and not (codes[i] == 0 and values[i].strip() == b"ENDSEC"):
                code = codes[i]
                if name == b"HEADER" and code == 9 and values[i].strip() == b"$INSUNITS":
                    if i + 1 >= n or codes[i + 1] != 70:
                        return None
                    units = int(values[i + 1])
                    i += 2
                    continue
                if name == b"ENTITIES" and code == 0:
                    if values[i].strip() != b"LINE":
                        return None
                    point = {}
                    i += 1
                    while i < n and codes[i] != 0:
                        c = codes[i]
                        if c in (10, 20, 11, 21, 30, 31):
                            if c in point:
                                return None
                            point[c] = float(values[i])
                        elif c == 67 and int(values[i]) != 0:  # paper space: not the model space
                            return None
                        i += 1
                    if len(point) < 4 or any(c not in point for c in (10, 20, 11, 21)):
                        return None
                    ends += (point[10], point[20], point[11], point[21])
                    continue
                i += 1
            if i >= n:
                return None
            i += 1
        else:
            return None  # no EOF
    except (ValueError, OverflowError):
        return None
    segments = np.array(ends, dtype=float).reshape(-1, 2, 2)
    if len(segments) == 0 or not np.isfinite(segments).all():
        return None
    return units, segments


def read_dxf(path: Path, scale, layers, skip_layers, max_entities: int = 1_000_000) -> VectorGeometry:
    if not layers and not skip_layers:
        fast = _dxf_lines_only(path)
        if fast is not None:
            units, segments = fast
            factor = _dxf_units(units, path, scale)
            # as ezdxf's LINE paths, (start, end), scaled as VectorGeometry.scaled scales them (one product, not 100,000)
            with np.errstate(over="ignore"):  # a coordinate scaled past float range: check_reach refuses it
                geometry = VectorGeometry(polylines=list(segments * np.array([factor, factor])))
            return _dxf_checked(geometry, path, scale, units)
    import ezdxf
    from ezdxf import path as ezpath

    try:
        doc = ezdxf.readfile(path)
    except OSError as err:
        raise FloorplanError(f"cannot read DXF floorplan {path}: {err.strerror or err}") from None
    except ezdxf.DXFError as err:
        raise FloorplanError(f"{path}: not a valid DXF file ({err})") from None
    except Exception as err:  # noqa: BLE001 - ezdxf's parser raises StopIteration, ValueError... on damaged files
        raise FloorplanError(f"{path}: not a readable DXF file ({type(err).__name__}: {err})") from None
    units = doc.header.get("$INSUNITS", 0)
    factor = _dxf_units(units, path, scale)
    _dxf_expansion(doc, path, max_entities)  # also bounds the nesting: each level is an entity
    wanted = None if not layers else {name.lower() for name in layers}
    skipped = {name.lower() for name in skip_layers or ()}
    # a layer exists when the LAYER table names it or an entity sits on it (a table may
    # lack layers its entities use: ezdxf reads and audits such files clean)
    names = {layer.dxf.name for layer in doc.layers}
    names |= {e.dxf.get("layer", "0") for space in (doc.modelspace(), *doc.blocks) for e in space}
    known = {name.lower() for name in names}
    for option, asked in (("--layers", wanted or set()), ("--skip-layers", skipped)):
        missing = sorted(asked - known)
        if missing:
            raise FloorplanError(f"{path}: no layer(s) {', '.join(missing)} ({option}); "
                                 f"its layers: {', '.join(sorted(names, key=str.lower))}")
    geometry = VectorGeometry()
    chord = ARC_CHORD / factor

    def visit(entities, depth: int = 0):
        for e in entities:
            layer = e.dxf.get("layer", "0").lower()
            kind = e.dxftype()
            what = f"{path}: DXF {kind} (handle {e.dxf.get('handle', '?')})"
            try:
                if kind == "INSERT":  # a block reference: its entities, placed (counted and cycle-free: _dxf_expansion)
                    visit(e.virtual_entities(), depth + 1)
                    continue
                if (wanted is not None and layer not in wanted) or layer in skipped:
                    continue
                if kind == "CIRCLE":
                    c = e.dxf.center
                    geometry.add_circle(c.x, c.y, e.dxf.radius, what)
                elif kind in ("LINE", "LWPOLYLINE", "POLYLINE", "ARC"):
                    for v in _dxf_defining_points(e):  # NaN / inf would hang or break the flattening
                        coordinates([v], what)
                    p = ezpath.make_path(e)
                    points = [(v.x, v.y) for v in p.flattening(distance=chord)]
                    geometry.add(points, closed=kind in ("LWPOLYLINE", "POLYLINE") and bool(e.is_closed), what=what)
            except FloorplanError:
                raise
            except (ValueError, OverflowError, ZeroDivisionError, TypeError, ArithmeticError, ezdxf.DXFError) as err:
                raise FloorplanError(f"{what} cannot be read ({type(err).__name__}: {err})".replace("\n", " ")) from None

    visit(doc.modelspace())
    return _dxf_checked(geometry.scaled(factor), path, scale, units)


def _dxf_checked(geometry: VectorGeometry, path: Path, scale, units) -> VectorGeometry:
    """The drawing in metres, checked: within reach of 0, and (units from the header, not
    --scale) spanning at least a metre in the declared unit."""
    geometry.check_reach(path)
    if scale is None:
        geometry.check_span(path, _dxf_unit_name(units))
    return geometry


def _dxf_unit_name(raw) -> str:
    """The header's unit ($INSUNITS: raw), as the span check names it."""
    import ezdxf.units

    code = int(real_number(raw) or 0)
    if code in _DXF_EXTRA_UNITS:
        return f"{_DXF_EXTRA_UNITS[code][0]} ($INSUNITS = {code})"
    try:
        return f"{ezdxf.units.unit_name(code)} ($INSUNITS = {code})"
    except (KeyError, ValueError, IndexError, TypeError):
        return f"$INSUNITS = {code}"


def _dxf_defining_points(e) -> list[tuple[float, float]]:
    """The coordinates (and radii, as points) an entity is defined by."""
    kind = e.dxftype()
    if kind == "LINE":
        return [(e.dxf.start.x, e.dxf.start.y), (e.dxf.end.x, e.dxf.end.y)]
    if kind == "ARC":
        r, a0, a1 = e.dxf.radius, e.dxf.start_angle, e.dxf.end_angle
        return [(e.dxf.center.x, e.dxf.center.y), (r, a0), (a1, r if r > 0 else float("nan"))]
    if kind == "LWPOLYLINE":
        return [(x, y) for x, y, *_ in e.get_points("xyb")] + [(b, 0.0) for *_, b in e.get_points("xyb")]
    if kind == "POLYLINE":
        return [(v.dxf.location.x, v.dxf.location.y) for v in e.vertices]
    return []
