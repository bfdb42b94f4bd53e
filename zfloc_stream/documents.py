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
import re

import numpy as np
import yaml

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


class YamlLoader(yaml.SafeLoader):
    """PyYAML's safe loader read the way a person means a number: `1e-3` is a float (YAML
    1.1 wants a dot: `1e-3` would be text), while YAML 1.1's base-60 numbers
    (`12:30:45` = 45045) and leading-zero octals (`010` = 8) stay text, so a number field
    refuses them instead of taking a number nobody wrote."""


_OCTAL = re.compile(r"[-+]?0[0-7_]+")


def _int_or_text(loader, node):
    text = node.value
    if ":" in text or _OCTAL.fullmatch(text):
        return text
    return yaml.SafeLoader.construct_yaml_int(loader, node)


def _float_or_text(loader, node):
    return node.value if ":" in node.value else yaml.SafeLoader.construct_yaml_float(loader, node)


YamlLoader.add_constructor("tag:yaml.org,2002:int", _int_or_text)
YamlLoader.add_constructor("tag:yaml.org,2002:float", _float_or_text)
YamlLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float", re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"), list("-+0123456789")
)


def text_number_hint(value: str) -> str:
    """Why a YAML scalar that looks numeric stayed text (for error messages)."""
    if ":" in value:
        return " (YAML 1.1 reads it in base 60)"
    if _OCTAL.fullmatch(value):
        return " (YAML 1.1 reads it as octal)"
    return ""


def flow_depth(text: str) -> int:
    """Deepest nesting of YAML/JSON flow brackets ([ and {) in text, quoted text skipped:
    a cheap look before parsing, since PyYAML takes seconds to fail on thousands of levels."""
    depth = deepest = 0
    quote = None
    for ch in text:
        if quote is not None:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch in "[{":
            depth += 1
            deepest = max(deepest, depth)
        elif ch in "]}":
            depth = max(depth - 1, 0)
    return deepest


class TooDeep(ValueError):
    """A document nested deeper than MAX_NESTING (found before or while parsing)."""


def load_yaml(text: str):
    """YAML read with YamlLoader; TooDeep when it nests deeper than MAX_NESTING."""
    if flow_depth(text) > MAX_NESTING:
        raise TooDeep(f"nested deeper than {MAX_NESTING} levels")
    try:
        data = yaml.load(text, Loader=YamlLoader)
    except RecursionError:
        raise TooDeep("nested deeper than the YAML parser can follow") from None
    if too_deep(data):
        raise TooDeep(f"nested deeper than {MAX_NESTING} levels")
    return data


__all__ = ["MAX_NESTING", "TooDeep", "YamlLoader", "flow_depth", "load_yaml", "nesting_depth", "real_number", "text_number_hint", "too_deep"]
