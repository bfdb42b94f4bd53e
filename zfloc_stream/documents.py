"""Checks on parsed user documents (YAML, JSON) before anything walks them: how deep they
nest, and whether a value is a real number (not a bool, not a string YAML happened to
read as a number).

Python's parsers and every recursive walker after them (pydantic, shapely, our own) fail
with a RecursionError thousands of lines long on a document nested a few hundred levels
deep; no floorplan or settings file needs more than a handful of levels, so a document
deeper than MAX_NESTING is refused by the loader with one line.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

# Deepest nesting a document may have. The deepest legitimate ones: GeoJSON MultiPolygon
# coordinates inside a Feature inside a FeatureCollection (~8 levels), settings (~6).
MAX_NESTING = 64


def nesting_depth(value, limit: int = MAX_NESTING) -> int:
    """Depth of nested lists / tuples / dicts (a scalar is 0), walked without recursion;
    stops counting once past `limit` (returns limit + 1)."""
    deepest = 0
    stack = [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, dict):
            children = item.values()
        elif isinstance(item, (list, tuple)):
            children = item
        else:
            continue
        depth += 1
        deepest = max(deepest, depth)
        if deepest > limit:
            return limit + 1
        stack.extend((child, depth) for child in children)
    return deepest


def too_deep(value, limit: int = MAX_NESTING) -> bool:
    return nesting_depth(value, limit) > limit


def real_number(value) -> float | None:
    """The value as a float when it is a real number (int, float, numpy number; not a bool,
    a string or a complex), else None. Non-finite values are returned as they are."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        return None
    try:
        return float(value)
    except (OverflowError, ValueError, TypeError):  # an int too large for a float
        return math.inf if value > 0 else -math.inf


__all__ = ["MAX_NESTING", "nesting_depth", "real_number", "too_deep"]
