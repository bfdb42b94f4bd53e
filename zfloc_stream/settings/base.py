"""What every settings section shares: the pydantic base (unknown keys and NaN refused,
numbers taken as numbers only) and the cross-field rule helpers (`ordered`,
`section_rule_error`), whose errors loading.py words as one line naming the dotted key.

Every setting carries its allowed range where it is declared (pydantic Field
constraints: gt/ge/lt/le on numbers, min_length on lists and strings); a new setting gets
its bounds the same way: `name: float = Field(default, gt=0, le=10)  # unit, meaning`.
"""

from __future__ import annotations

import sys
import typing
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, model_validator
from pydantic_core import PydanticCustomError

from .documents import text_number_hint


def _plain(annotation):
    """A field (or a list's item) annotation without its Annotated metadata."""
    return typing.get_args(annotation)[0] if typing.get_origin(annotation) is Annotated else annotation


def _numeric(annotation) -> bool:
    """Whether a field (or a list's item) annotation is int or float."""
    return _plain(annotation) in (int, float)


def _number_problem(value) -> str | None:
    """Why a value given for a number setting is not one: pydantic would read True as 1,
    the text '5' as 5, bytes (YAML's !!binary) as digits, and a subnormal float (4.9e-324)
    passes every `gt=0`."""
    if isinstance(value, (bool, np.bool_)):
        return "must be a number, not a boolean (true/false)"
    if isinstance(value, str):
        return f"must be a number, got text{text_number_hint(value)}: write the number itself"
    if isinstance(value, (bytes, bytearray)):  # pydantic reads b"12" as 12; lists etc. it refuses itself, with the range
        return f"must be a number, got {_kind(value)}"
    if isinstance(value, float) and value != 0 and abs(value) < sys.float_info.min:
        return f"is a subnormal number (below {sys.float_info.min:.3g}): no setting means anything that small"
    return None


def _bool_problem(value) -> str | None:
    """Why a value given for an on/off setting is not true or false: pydantic would read
    0, -0.0, "off" and "no" as False."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, str):
        return "must be true or false, got text: write true or false without quotes"
    return f"must be true or false, got {_kind(value)}"


def _kind(value) -> str:
    """A value's kind in a user's words (never its contents: it may come from any file)."""
    if isinstance(value, (bool, np.bool_)):
        return "a boolean"
    if isinstance(value, (int, float, np.integer, np.floating)):
        return "a number"
    if isinstance(value, (bytes, bytearray)):
        return "binary data"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    return f"a {type(value).__name__} value"


class Section(BaseModel):
    # NaN or infinity is never a usable setting (a NaN threshold silently fails every comparison)
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def numbers_are_numbers(cls, data):
        """Number settings take numbers only (no booleans, no text, no subnormals) and
        on/off settings take true or false only."""
        if not isinstance(data, dict):
            return data
        for name, info in cls.model_fields.items():
            if name not in data:
                continue
            value, annotation = data[name], info.annotation
            if _numeric(annotation):
                problem = _number_problem(value)
            elif _plain(annotation) is bool:
                problem = _bool_problem(value)
            elif typing.get_origin(annotation) is list and _numeric(typing.get_args(annotation)[0]) and isinstance(value, list):
                problem = next((f"item {i} {p}" for i, p in ((i, _number_problem(v)) for i, v in enumerate(value)) if p), None)
            else:
                continue
            if problem is not None:
                raise section_rule_error(name, value, problem, ())
        return data


def section_rule_error(key: str, value: object, message: str, related: tuple[str, ...]) -> PydanticCustomError:
    """A cross-field rule broken in a section: `key` (the field reported) and the `related`
    fields named in `message` are spelled in full (dotted) by the error formatter."""
    return PydanticCustomError("section_rule", message, {"key": key, "value": value, "related": related})


def ordered(*pairs: tuple[str, str] | tuple[str, str, str]):
    """A section validator: for each (low, high) pair of field names, low < high
    (low <= high where the pair ends with "<=")."""

    def check(section):
        for low, high, *how in pairs:
            a, b = getattr(section, low), getattr(section, high)
            if not (a <= b if how == ["<="] else a < b):
                relation = "at most" if how == ["<="] else "less than"
                raise section_rule_error(low, a, f"must be {relation} {high} ({b})", (high,))
        return section

    return model_validator(mode="after")(check)
