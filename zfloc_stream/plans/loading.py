"""Any floorplan file, by its kind: the one entry point for loading a plan.

Raster maps (a ROS map YAML and its image, a plain image, a Gibson map) are floorplan.py's;
vector drawings (DXF, SVG, GeoJSON) and the YAML a session writes for one (`vector:` key)
are vector.py's, which builds on floorplan.py. This module sits above both, so
neither imports the other's way up.
"""

from __future__ import annotations

from pathlib import Path

from ..settings.loading import Settings
from .floorplan import Floorplan
from .raster_files import MAP_YAML_SUFFIXES, read_map_yaml
from .vector import VECTOR_SUFFIXES, load_vector_floorplan, load_vector_yaml


def load_floorplan(
    path,
    resolution: float | None = None,
    origin=None,
    settings: Settings | None = None,
    flip_y: bool = True,
    gibson: bool = False,
) -> Floorplan:
    """A ROS map_server YAML (+ image), a plan YAML naming a vector drawing, a DXF / SVG /
    GeoJSON drawing, a plain image with resolution and origin (row 0 = largest y unless
    flip_y=False; dark pixels are walls), or with gibson=True a Gibson(t)/F3Loc map.png."""
    path = Path(path)
    suffix = path.suffix.lower()
    if not gibson and suffix in VECTOR_SUFFIXES:
        return load_vector_floorplan(path, settings)
    if not gibson and suffix in MAP_YAML_SUFFIXES and resolution is None and origin is None:
        meta = read_map_yaml(path)
        if isinstance(meta, dict) and "vector" in meta:  # a vector plan (as written into sessions)
            return load_vector_yaml(path, meta, settings)
        return Floorplan.from_map_yaml(path, settings, meta)
    return Floorplan.load(path, resolution, origin, settings, flip_y, gibson)
