"""Tables built once per floorplan object (the scorer's grids, the RANSAC tuples, the
correlative mask and its spectrum): kept beside the floorplan, weakly, so they go when it
goes; a table whose key (the settings it was built with) changed is rebuilt. An object
that cannot be weakly referenced gets its tables built every time."""

from __future__ import annotations

import weakref
from collections.abc import Callable, Hashable
from typing import TypeVar

T = TypeVar("T")

_TABLES: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()  # floorplan -> {name: (key, table)}


def cached_per_floorplan(floorplan, name: Hashable, key: Hashable, build: Callable[[], T]) -> T:
    """The table `name` of this floorplan, built by build() unless it was built with the
    same key."""
    try:
        tables = _TABLES.setdefault(floorplan, {})
    except TypeError:  # not weak-referenceable / hashable: no caching
        return build()
    hit = tables.get(name)
    if hit is not None and hit[0] == key:
        return hit[1]
    table = build()
    tables[name] = (key, table)
    return table
