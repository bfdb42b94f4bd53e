"""Reading a GeoJSON plan (shapely; metres, a Point with a `radius` is a pillar): lines,
rings and polygons' rings; a coordinate system other than metres needs --scale, and
longitude/latitude is refused."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...errors import FloorplanError
from ...settings.documents import MAX_NESTING, real_number, too_deep
from .geometry import VectorGeometry


def read_geojson(path: Path, scale) -> VectorGeometry:
    from shapely.errors import ShapelyError
    from shapely.geometry import shape

    try:
        data = json.loads(path.read_text())
    except OSError as err:
        raise FloorplanError(f"cannot read GeoJSON floorplan {path}: {err.strerror or err}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise FloorplanError(f"{path}: not valid JSON ({err})") from None
    except RecursionError:
        raise FloorplanError(f"{path}: nested deeper than the JSON parser can follow (GeoJSON needs a few levels)") from None
    except ValueError as err:  # an integer of thousands of digits (Python's int-digits limit)
        raise FloorplanError(f"{path}: not usable JSON ({err})") from None
    if too_deep(data, MAX_NESTING):
        raise FloorplanError(f"{path}: nested deeper than {MAX_NESTING} levels (GeoJSON needs a few)")
    if not isinstance(data, dict) or not isinstance(data.get("type"), str):
        raise FloorplanError(f"{path}: not GeoJSON (expected an object with a 'type')")
    if data["type"] == "FeatureCollection":
        features = data.get("features")
        if features is None:
            features = []
        if not isinstance(features, list):
            raise FloorplanError(f"{path}: 'features' must be a list of features, got {type(features).__name__}")
    else:
        features = [data if data["type"] == "Feature" else {"geometry": data}]
    scale = _geojson_crs_scale(data, path, scale)
    geometry = VectorGeometry()

    def visit(geom, props, what):
        kind = geom.geom_type
        if kind in ("MultiLineString", "MultiPolygon", "GeometryCollection", "MultiPoint"):
            for part in geom.geoms:
                visit(part, props, what)
        elif kind == "LineString":
            geometry.add(np.asarray(geom.coords)[:, :2], closed=geom.is_ring, what=what)
        elif kind == "LinearRing":
            geometry.add(np.asarray(geom.coords)[:, :2], closed=True, what=what)
        elif kind == "Polygon":
            for ring in [geom.exterior, *geom.interiors]:
                geometry.add(np.asarray(ring.coords)[:, :2], closed=True, what=what)
        elif kind == "Point" and props.get("radius") is not None:
            geometry.add_circle(geom.x, geom.y, props["radius"], what)

    for k, feature in enumerate(features):
        what = f"{path}: feature {k}"
        if not isinstance(feature, dict):
            raise FloorplanError(f"{what} is a {type(feature).__name__}, not a GeoJSON object")
        if feature.get("geometry") is None:
            continue
        props = feature.get("properties")
        if props is None:
            props = {}
        if not isinstance(props, dict):
            raise FloorplanError(f"{what}: 'properties' must be an object, got {type(props).__name__}")
        _check_coordinate_types(feature["geometry"], what)
        try:
            with np.errstate(all="ignore"):  # NaN coordinates: refused below, not warned about by shapely
                geom = shape(feature["geometry"])
            visit(geom, props, what)
        except FloorplanError:
            raise
        except (ShapelyError, ValueError, TypeError, KeyError, AttributeError, IndexError, OverflowError) as err:
            raise FloorplanError(f"{what} has an invalid geometry ({type(err).__name__}: {err})".replace("\n", " ")) from None
    geometry = geometry.scaled(1.0 if scale is None else scale)
    points = np.vstack([*geometry.polylines, *geometry.rings, np.zeros((0, 2))])
    if scale is None and len(points) and np.abs(points).max() <= 180 and np.ptp(points, axis=0).max() < 0.05:
        raise FloorplanError(f"{path}: coordinates look like longitude/latitude; a floorplan needs metres (project it to a metric CRS, or pass --scale)")
    geometry.check_reach(path)
    return geometry


def _check_coordinate_types(geometry, what: str) -> None:
    """Every GeoJSON coordinate a JSON number: shapely would read "5" and true as 5.0 and
    1.0 without a word."""
    stack = [geometry]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            stack += [item[k] for k in ("coordinates", "geometries") if k in item]
        elif isinstance(item, list):
            for v in item:
                if isinstance(v, (list, dict)):
                    stack.append(v)
                elif real_number(v) is None:
                    raise FloorplanError(f"{what} has a coordinate {str(v)[:40]!r} that is not a number")


_GEOGRAPHIC_CRS = ("crs84", "epsg::4326", "epsg:4326", "epsg::4269", "epsg:4269", "epsg::4258", "epsg:4258")


def _geojson_crs_scale(data: dict, path: Path, scale):
    """The scale to read a GeoJSON with a (2008-style) `crs` member: this reader converts no
    coordinate system, so one that is not lon/lat (refused) needs --scale to say its unit."""
    crs = data.get("crs")
    if crs is None or scale is not None:
        return scale
    name = crs.get("properties", {}).get("name") if isinstance(crs, dict) and isinstance(crs.get("properties"), dict) else None
    label = str(name)[:80] if name is not None else str(crs)[:80]
    if any(g in label.lower() for g in _GEOGRAPHIC_CRS):
        raise FloorplanError(f"{path}: crs {label} is longitude/latitude; a floorplan needs metres (project it to a metric CRS)")
    raise FloorplanError(f"{path}: declares crs {label}, whose unit this reader cannot know (it converts no coordinate system): "
                         "pass --scale METRES_PER_UNIT (1 for metres, 0.3048 for feet, 0.3048006 for US survey feet)")
