"""Settings of the floorplan and of the vector-plan loader (plans/floorplan.py, plans/vector.py)."""

from __future__ import annotations

from pydantic import Field

from .base import Section


class FloorplanSettings(Section):
    neighbour_distance: float = Field(6.0, gt=0, le=1000)  # m, lines closer than this are spatial neighbours (3L pruning)
    image_wall_threshold: float = Field(0.5, ge=0, le=1)  # plain images: occupancy (255 - v) / 255 above this is wall
    max_triplets: int = Field(2_000_000, ge=1, le=1_000_000_000)  # 3L table rows (~80 B each while built); a cluttered map past this keeps each line's nearest neighbours only, for its 3L and 2L tables (real maps: <= 0.5 M)
    # Memory and load-time budget of one plan: the cells the estimator keeps. A plan with
    # more cells is pooled (a coarse cell is wall where any of its cells is) by the smallest
    # whole factor that fits, with a warning; the estimator's search grid over its extent
    # (estimator.correlative.cell) must fit too: a wrong resolution or unit blows that up.
    # Peak memory while a plan is built is ~60 bytes per kept cell (docs/robustness.md).
    max_cells: int = Field(25_000_000, ge=1, le=2_000_000_000)
    # Cells read before pooling (an image: its size is read from the file's header): ~2-3
    # bytes each while decoded; 400 M is a 1 x 1 km floor at 0.05 m.
    max_image_cells: int = Field(400_000_000, ge=1, le=4_000_000_000)


class VectorFloorplanSettings(Section):
    """DXF / SVG / GeoJSON floorplans: lines and circles come from the vectors; the
    occupancy raster (distance field, Cv) is drawn from them at this resolution."""

    resolution: float = Field(0.05, ge=0.005, le=10)  # m per raster cell
    wall_thickness: float = Field(0.1, gt=0, le=10)  # m, a wall drawn as a line is rasterised this thick
    solid_max_width: float = Field(0.6, ge=0, le=100)  # m, closed shapes narrower than this (2 area / perimeter) are solid (walls, columns); wider ones (rooms) are outlines
    margin: float = Field(1.0, ge=0, le=1000)  # m of free border around the drawing
    # Cells of the drawing at `resolution` over its extent: larger drawings are refused (a wrong
    # unit scale, usually; 1 km x 1 km is 400 M). One over floorplan.max_cells is drawn on
    # coarser cells (the lines stay the drawing's own).
    max_cells: int = Field(400_000_000, ge=1, le=1_000_000_000)
    # Drawn entities a plan may expand to, counted before anything is expanded: DXF
    # entities with every block reference (INSERT) counted as its block's expansion, SVG
    # elements with every <use> counted as what it references (a few nested blocks of 10
    # references each are 1e6 or 1e8 entities: a bomb, not a floor).
    max_entities: int = Field(1_000_000, ge=1, le=1_000_000_000)
