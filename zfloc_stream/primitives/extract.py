"""Line and circle primitives from 2D wall points (paper 3.1), one implementation for the
BEV and the floorplan.

Lines: seeded region growing. A random unused seed gives, by PCA on its neighbourhood, an
initial line; the line then collects every still-free point within `line_growing.INLIER_DISTANCE` of it
that is connected to the seed along the line (no gap longer than `gap`), is refitted by
total least squares and grows again until its support stops changing.

Circles: HDBSCAN clusters; per cluster a 3-point RANSAC circle, a least-squares refit, and
acceptance only if the inliers wrap far enough around the centre (angular coverage)
without long holes (angular continuity), which is what separates a pillar from a wall
fragment or a corner.

Both are compiled (line_growing.py, circle_fitting.py); this module is their entry point.
"""

from __future__ import annotations

import numpy as np

from . import circle_fitting
from . import line_growing
from ..settings.loading import CircleSettings, LineSettings
from ..geometry.shapes import CircleSet, LineSet, as_points, grid_subsample
from ..geometry.segment_pairs import deduplicate_lines

__all__ = ["as_points", "deduplicate_lines", "extract_circles", "extract_lines", "grid_subsample"]


def extract_lines(points, settings: LineSettings, rng: np.random.Generator) -> LineSet:
    """Line segments by seeded region growing; sorted by length, longest first.

    points: (N, 2) metres. Empty input gives an empty set; NaN/inf raise InputError."""
    return line_growing.extract_lines(as_points(points), settings, rng)


def extract_circles(points, settings: CircleSettings, rng: np.random.Generator) -> CircleSet:
    """Circles (pillars) in 2D wall points; empty input gives an empty set."""
    return circle_fitting.extract_circles(as_points(points), settings, rng)
