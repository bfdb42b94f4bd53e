"""Checks on user documents (YAML, JSON) before anything walks them: that the file is a
regular file of a sane size (a FIFO blocks forever, /dev/zero never ends), how deep they
nest, how many nodes they expand to (YAML aliases share one node; a walker expands each use),
and whether a value is a real number (not a bool, not a string YAML happened to read as a
number).

Python's parsers and every recursive walker after them (pydantic, shapely, our own) fail
with a RecursionError thousands of lines long on a document nested a few hundred levels
deep; no floorplan or settings file needs more than a handful of levels, so a document
deeper than MAX_NESTING is refused by the loader with one line.
"""

from __future__ import annotations

import math
import numbers
import os
import re
import stat
from pathlib import Path

import numpy as np
import yaml

# Deepest nesting a document may have. The deepest legitimate ones: GeoJSON MultiPolygon
# coordinates inside a Feature inside a FeatureCollection (~8 levels), settings (~6).
MAX_NESTING = 64

# Most nodes a YAML document may expand to, each use of an alias counted in full (what a
# validator or a merge walks). A settings file has ~400, a map YAML ~10; a "billion laughs"
# file of 100 bytes expands to 10^9 and took minutes to refuse.
MAX_EXPANDED_NODES = 100_000

# Largest settings / map YAML file read (bytes). configs/default.yaml is 7 KB; PyYAML parses
# ~100 KB/s here, so this bounds the parse to a few seconds.
MAX_YAML_BYTES = 256 * 1024


class DocumentRefused(ValueError):
    """A user document refused before or right after parsing; the message names the
    problem, never the document's contents."""


class TooDeep(DocumentRefused):
    """A document nested deeper than MAX_NESTING (found before or while parsing)."""


class TooLarge(DocumentRefused):
    """A document (or its file) over a size or expansion limit."""


def _children(item):
    if isinstance(item, dict):
        return list(item.values())
    if isinstance(item, (list, tuple)):
        return list(item)
    return None


def document_extent(value) -> tuple[float, float]:
    """(depth, expanded node count) of nested lists / tuples / dicts (a scalar: (0, 1)).
    Shared sub-documents (YAML aliases) are walked once and counted at every use; a
    document that contains itself is infinitely deep and large. Iterative: no recursion
    limit."""
    memo: dict[int, tuple[float, float]] = {}
    open_ids: set[int] = set()
    stack = [(value, False)]
    while stack:
        item, children_done = stack.pop()
        kids = _children(item)
        if kids is None:
            continue
        key = id(item)
        if children_done:
            open_ids.discard(key)
            depth, nodes = 1.0, 1.0
            for kid in kids:
                kid_depth, kid_nodes = memo.get(id(kid), (0.0, 1.0)) if _children(kid) is not None else (0.0, 1.0)
                depth, nodes = max(depth, kid_depth + 1), nodes + kid_nodes
            memo[key] = (depth, nodes)
            continue
        if key in memo:
            continue
        if key in open_ids:  # reached again while its own children are open: a cycle
            return math.inf, math.inf
        open_ids.add(key)
        stack.append((item, True))
        stack.extend((kid, False) for kid in kids if _children(kid) is not None)
    return memo.get(id(value), (0.0, 1.0))


def nesting_depth(value, limit: int = MAX_NESTING) -> int:
    """Depth of nested lists / tuples / dicts (a scalar is 0); limit + 1 when deeper than
    `limit` (or self-containing)."""
    depth = document_extent(value)[0]
    return limit + 1 if depth > limit else int(depth)


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
    (`12:30:45` = 45045), leading-zero octals (`010` = 8), hexadecimal (`0x10` = 16) and
    binary (`0b11`) stay text, so a number field refuses them instead of taking a number
    nobody meant."""


_OCTAL = re.compile(r"[-+]?0[0-7_]+")
_HEX_OR_BINARY = re.compile(r"[-+]?0[xXbB][0-9a-fA-F_]+")


def _int_or_text(loader, node):
    text = node.value
    if ":" in text or _OCTAL.fullmatch(text) or _HEX_OR_BINARY.fullmatch(text):
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
    if _HEX_OR_BINARY.fullmatch(value):
        return " (YAML 1.1 reads it as hexadecimal or binary)"
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


def load_yaml(text: str):
    """YAML read with YamlLoader; TooDeep when it nests deeper than MAX_NESTING, TooLarge
    when it is over MAX_YAML_BYTES or expands (aliases included) past MAX_EXPANDED_NODES."""
    if len(text) > MAX_YAML_BYTES:
        raise TooLarge(f"{len(text)} characters, over the {MAX_YAML_BYTES}-byte limit for a YAML document")
    if flow_depth(text) > MAX_NESTING:
        raise TooDeep(f"nested deeper than {MAX_NESTING} levels")
    try:
        data = yaml.load(text, Loader=YamlLoader)
    except RecursionError:
        raise TooDeep("nested deeper than the YAML parser can follow") from None
    depth, nodes = document_extent(data)
    if depth > MAX_NESTING:
        raise TooDeep(f"nested deeper than {MAX_NESTING} levels")
    if nodes > MAX_EXPANDED_NODES:
        raise TooLarge(
            f"expands to more than {MAX_EXPANDED_NODES} values (YAML aliases counted at each use): no settings or map file needs that many"
        )
    return data


def yaml_problem(err: yaml.YAMLError) -> str:
    """A parser error as 'PROBLEM at line L, column C', without the quoted lines PyYAML adds
    (they are the file's contents, which an error never echoes)."""
    problem = getattr(err, "problem", None) or "cannot be parsed"
    mark = getattr(err, "problem_mark", None)
    return f"{problem} at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else problem


def read_document_text(path: str | Path, max_bytes: int = MAX_YAML_BYTES) -> str:
    """A user document's text, read only when it is a regular file of at most max_bytes in
    UTF-8: a FIFO would block forever and /dev/zero never ends. FileNotFoundError when it
    does not exist; DocumentRefused (the path's problem, never its contents) otherwise."""
    path = Path(path)
    info = os.stat(path)  # FileNotFoundError passes through: callers word "not found" their way
    if stat.S_ISDIR(info.st_mode):
        raise DocumentRefused("is a folder, not a file")
    if not stat.S_ISREG(info.st_mode):
        raise DocumentRefused("is not a regular file (a pipe, socket or device): give a file")
    if info.st_size > max_bytes:
        raise TooLarge(f"is {info.st_size} bytes, over the {max_bytes}-byte limit for this kind of file")
    try:
        with open(path, "rb") as f:
            data = f.read(max_bytes + 1)  # the file may have grown since the stat
    except OSError as err:
        raise DocumentRefused(f"cannot be read: {err.strerror or type(err).__name__}") from None
    if len(data) > max_bytes:
        raise TooLarge(f"is over the {max_bytes}-byte limit for this kind of file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise DocumentRefused(f"is not UTF-8 text (byte {err.start} cannot be decoded)") from None


__all__ = [
    "MAX_EXPANDED_NODES",
    "MAX_NESTING",
    "MAX_YAML_BYTES",
    "DocumentRefused",
    "TooDeep",
    "TooLarge",
    "YamlLoader",
    "document_extent",
    "flow_depth",
    "load_yaml",
    "nesting_depth",
    "read_document_text",
    "real_number",
    "text_number_hint",
    "too_deep",
    "yaml_problem",
]
