"""Built-in procedural scenes, shipped as code and fully determined by (name, seed).

Each generator lays out rooms (corridors and halls are rooms too), connects them with
doors, adds round pillars and furniture, and hands the plan to `layout.build_walls`. The
resulting `Scene` keeps the geometry as primitives (for the 3D renderer) and as a 0.05 m
occupancy raster (the floorplan the localizer sees: walls and pillars, not furniture).

Registry: `SCENES` maps a name to its generator; `build_scene(name, seed=0)`.
"""

from __future__ import annotations

from ..errors import InputError
from .assembly import make_scene
from .generators import generate_apartment, generate_hall, generate_office, generate_offices, generate_rooms, generate_symmetric
from .scene import Scene

__all__ = ["SCENES", "Scene", "build_scene", "make_scene"]


SCENES = {
    "rooms": generate_rooms,
    "apartment": generate_apartment,
    "office": generate_office,
    "symmetric": generate_symmetric,
    "hall": generate_hall,
    "offices": generate_offices,
}


def build_scene(name: str, seed: int = 0) -> Scene:
    """Build a registered scene; same (name, seed) -> identical scene."""
    try:
        generator = SCENES[name]
    except (KeyError, TypeError):
        raise InputError(f"unknown scene '{name}'; known scenes: {', '.join(sorted(SCENES))}") from None
    return generator(int(seed))
