"""What every settings section shares: the pydantic base (unknown keys and NaN refused,
numbers taken as numbers only) and the cross-field rule helpers (`ordered`,
`section_rule_error`), whose errors config.py words as one line naming the dotted key.

Every setting carries its allowed range where it is declared (pydantic Field
constraints: gt/ge/lt/le on numbers, min_length on lists and strings); a new setting gets
its bounds the same way: `name: float = Field(default, gt=0, le=10)  # unit, meaning`.
"""

from __future__ import annotations

import sys
import typing
from typing import Annotated

from pydantic import BaseModel, ConfigDict, model_validator
from pydantic_core import PydanticCustomError

from ..documents import text_number_hint


def _numeric(annotation) -> bool:
    """Whether a field (or a list's item) annotation is int or float."""
    if typing.get_origin(annotation) is Annotated:
        annotation = typing.get_args(annotation)[0]
    return annotation in (int, float)


def _number_problem(value) -> str | None:
    """Why a value given for a number setting is not one: pydantic would read True as 1,
    the text '5' as 5, and a subnormal float (4.9e-324) passes every `gt=0`."""
    if isinstance(value, bool):
        return "must be a number, not a boolean (true/false)"
    if isinstance(value, str):
        return f"must be a number, got text{text_number_hint(value)}: write the number itself"
    if isinstance(value, float) and value != 0 and abs(value) < sys.float_info.min:
        return f"is a subnormal number (below {sys.float_info.min:.3g}): no setting means anything that small"
    return None


class Section(BaseModel):
    # NaN or infinity is never a usable setting (a NaN threshold silently fails every comparison)
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    @model_validator(mode="before")
    @classmethod
    def numbers_are_numbers(cls, data):
        """Number settings take numbers only: no booleans, no text, no subnormals."""
        if not isinstance(data, dict):
            return data
        for name, info in cls.model_fields.items():
            if name not in data:
                continue
            value, annotation = data[name], info.annotation
            if _numeric(annotation):
                problem = _number_problem(value)
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
