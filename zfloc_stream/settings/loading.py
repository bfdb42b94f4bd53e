"""Typed settings: one pydantic model per stage (the sections live in settings/, one module
per part of the package: estimation, plans, frontend, tracking, localizer, inputs,
tooling), composed here into Settings, loaded from YAML and overrides, and dumped.

Every number the algorithm uses has a name in a section; configs/default.yaml is the dump
of these defaults (a test keeps the two identical). Unknown keys are errors, so a typo in a
config file fails loudly instead of being ignored.

Every setting carries its allowed range where it is declared (pydantic Field
constraints: gt/ge/lt/le on numbers, min_length on lists and strings; NaN and infinity
are refused everywhere), and pairs that must be ordered (min < max) are checked by
`ordered(...)` in their section. A value outside its range is one ConfigError line that
names the dotted key, the value and the allowed range. A new setting gets its bounds the
same way: `name: float = Field(default, gt=0, le=10)  # unit, meaning`.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel, Field, ValidationError

from .documents import MAX_NESTING, DocumentRefused, TooDeep, load_yaml, read_document_text, too_deep, yaml_problem
from ..errors import ConfigError
from .base import Section
from .retired import RETIRED, drop_retired
from .estimation import (  # noqa: F401 - re-exported: callers import every section from here
    LineSettings,
    CircleSettings,
    PrimitiveSettings,
    SolverSettings,
    ScoringSettings,
    RefineSettings,
    RansacSettings,
    CorrelativeSettings,
    EstimatorSettings,
    SolverName,
    ScaleMode,
)
from .plans import (  # noqa: F401 - re-exported: callers import every section from here
    FloorplanSettings,
    VectorFloorplanSettings,
)
from .frontend import (  # noqa: F401 - re-exported: callers import every section from here
    GravitySettings,
    WallMaskSettings,
    LabellerSettings,
    FrontendSettings,
    BevSettings,
    MAX_BEV_HALF_CELLS,
)
from .tracking import (  # noqa: F401 - re-exported: callers import every section from here
    TrackingSettings,
)
from .localizer import (  # noqa: F401 - re-exported: callers import every section from here
    LocalizerSettings,
)
from .prior import (  # noqa: F401 - re-exported: callers import every section from here
    PriorSettings,
)
from .inputs import (  # noqa: F401 - re-exported: callers import every section from here
    OdometrySettings,
    GibsonSettings,
    CarmenSettings,
    MappingSettings,
    SimDatasetSettings,
    Ros2Settings,
    DatasetSettings,
    BackboneSettings,
)
from .tooling import (  # noqa: F401 - re-exported: callers import every section from here
    LoggingSettings,
    StudySettings,
    ReplaySettings,
)


class Settings(Section):
    seed: int = Field(0, ge=0, le=2**63 - 1)
    floorplan: FloorplanSettings = FloorplanSettings()
    primitives: PrimitiveSettings = PrimitiveSettings()
    estimator: EstimatorSettings = EstimatorSettings()
    frontend: FrontendSettings = FrontendSettings()
    bev: BevSettings = BevSettings()
    tracking: TrackingSettings = TrackingSettings()
    localizer: LocalizerSettings = LocalizerSettings()
    prior: PriorSettings = PriorSettings()
    logging: LoggingSettings = LoggingSettings()
    datasets: DatasetSettings = DatasetSettings()
    study: StudySettings = StudySettings()
    replay: ReplaySettings = ReplaySettings()
    backbones: BackboneSettings = BackboneSettings()


def merge_nested(base: dict, update: dict) -> dict:
    """base updated by update, key by key at every depth (neither is changed)."""
    out = dict(base)
    for key, value in update.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = merge_nested(out[key], value)
        else:
            out[key] = value
    return out


def dotted_to_nested(key: str, value) -> dict:
    """"a.b.c", v -> {"a": {"b": {"c": v}}} (a --set override as a settings tree)."""
    out: dict = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def _field_info(model: type[BaseModel], loc: tuple) -> Any:
    """The FieldInfo a validation error location points to (None past a list index)."""
    info = None
    for part in loc:
        if not isinstance(part, str) or model is None or part not in model.model_fields:
            return None
        info = model.model_fields[part]
        model = info.annotation if isinstance(info.annotation, type) and issubclass(info.annotation, BaseModel) else None
    return info


def allowed_range(info) -> str | None:
    """'(0, 10]', '[1, 1000] (integer)', 'at least 1 item'... from a field's constraints."""
    if info is None:
        return None
    c = {type(m).__name__: m for m in info.metadata}
    lo = ("(", c["Gt"].gt) if "Gt" in c else ("[", c["Ge"].ge) if "Ge" in c else None
    hi = (")", c["Lt"].lt) if "Lt" in c else ("]", c["Le"].le) if "Le" in c else None
    if lo and hi:
        text = f"{lo[0]}{_bound(lo[1])}, {_bound(hi[1])}{hi[0]}"
    elif lo:
        text = f"{'>' if lo[0] == '(' else '>='} {_bound(lo[1])}"
    elif hi:
        text = f"{'<' if hi[0] == ')' else '<='} {_bound(hi[1])}"
    elif "MinLen" in c:
        return f"at least {c['MinLen'].min_length} item(s)"
    else:
        return None
    return text + (" (integer)" if info.annotation is int else "")


def _suggest_key(parts: tuple) -> str:
    """' (did you mean 'a.b.c'?)' for an unknown key: the nearest field of its section."""
    import difflib

    info = _field_info(Settings, parts[:-1]) if len(parts) > 1 else None
    model = Settings if len(parts) == 1 else getattr(info, "annotation", None)
    if not (isinstance(model, type) and issubclass(model, BaseModel)) or not isinstance(parts[-1], str):
        return ""
    match = difflib.get_close_matches(parts[-1], list(model.model_fields), n=1, cutoff=0.6)
    return f" (did you mean '{'.'.join(str(p) for p in (*parts[:-1], match[0]))}'?)" if match else ""


def _bound(v: float) -> str:
    return str(v) if isinstance(v, int) else f"{v:.10g}"


def _short(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


# What a setting's name looks like; a key unlike it is never echoed in an error.
_SETTING_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,63}")


def _format_validation_error(err: ValidationError, source: str) -> str:
    first = err.errors()[0]
    parts = tuple(first["loc"])
    loc = ".".join(str(p) for p in parts) or "<root>"
    if first["type"] == "extra_forbidden":
        if not all(isinstance(p, int) or _SETTING_NAME.fullmatch(p) for p in parts):
            # not a name any setting could have: the file is likely not a settings file at
            # all (say /etc/shadow), and its keys are its contents: never echo them
            return f"{source}: has a key that is not a setting name (is it a settings file? see configs/default.yaml)"
        if loc in RETIRED:  # named by an override or a caller's dict (files and logs drop them)
            fixed, home = RETIRED[loc]
            return f"{source}: '{loc}' is no longer a setting: fixed at {fixed!r} ({home.split(':')[1]} in {home.split(':')[0]})"
        return f"{source}: unknown setting '{loc}'" + _suggest_key(parts)
    if first["type"] == "section_rule":  # a cross-field rule: spell every key in full
        ctx, prefix = first["ctx"], "".join(f"{p}." for p in parts)
        message = first["msg"]
        if ctx["related"]:
            message = re.sub(rf"\b({'|'.join(ctx['related'])})\b", lambda m: prefix + m.group(1), message)
        return f"{source}: setting '{prefix}{ctx['key']}' = {_short(ctx['value'])}: {message}"
    info = _field_info(Settings, parts)
    allowed = allowed_range(info)
    text = f"{source}: setting '{loc}' = {_short(first.get('input'))}: {first['msg']}"
    return text + (f"; allowed range {allowed}" if allowed else "")


def settings_from_dict(data: dict, source: str = "settings") -> Settings:
    if too_deep(data, MAX_NESTING):
        raise ConfigError(f"{source}: settings nested deeper than {MAX_NESTING} levels (no setting needs more than a few)")
    try:
        return Settings.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format_validation_error(err, source)) from None


def load_settings(
    path: str | Path | None = None,
    overrides: list[str] | dict | None = None,
    base_overrides: dict | None = None,
) -> Settings:
    """Defaults, updated by base_overrides (what a data source needs, e.g. fixed scale for
    a laser), by a YAML file, then by overrides.

    overrides: either a nested dict or 'dotted.key=value' strings (values parsed as YAML).
    """
    data: dict = Settings().model_dump()
    source = "defaults"
    if base_overrides:
        data = merge_nested(data, base_overrides)
    if path is not None:
        path = Path(path)
        source = str(path)
        try:
            loaded = load_yaml(read_document_text(path)) or {}
        except TooDeep as err:
            raise ConfigError(f"{path}: settings {err} (no setting needs more than a few)") from None
        except DocumentRefused as err:
            raise ConfigError(f"config file {path} {err}" if str(err).startswith("is ") else f"config file {path}: {err}") from None
        except FileNotFoundError:
            raise ConfigError(f"config file not found: {path}") from None
        except OSError as err:
            raise ConfigError(f"cannot read config file {path}: {err.strerror or type(err).__name__}") from None
        except yaml.YAMLError as err:
            raise ConfigError(f"config file {path} is not valid YAML: {yaml_problem(err)}") from None
        if not isinstance(loaded, dict):
            raise ConfigError(f"{path}: top level must be a mapping")
        data = merge_nested(data, drop_retired(loaded, str(path)))
    if isinstance(overrides, dict):
        data = merge_nested(data, overrides)
    elif overrides:
        for item in overrides:
            if "=" not in item:
                raise ConfigError(f"override '{item}' must look like dotted.key=value")
            key, raw = item.split("=", 1)
            try:
                value = load_yaml(raw)
            except TooDeep as err:
                raise ConfigError(f"override '{key.strip()}': value {err} (no setting needs more than a few)") from None
            except DocumentRefused as err:
                raise ConfigError(f"override '{key.strip()}': value {err}") from None
            except yaml.YAMLError:
                raise ConfigError(f"override '{item}': value is not valid YAML") from None
            data = merge_nested(data, dotted_to_nested(key.strip(), value))
        source = f"{source} + overrides"
    return settings_from_dict(data, source)


def dump_settings(settings: Settings) -> str:
    return yaml.safe_dump(settings.model_dump(), sort_keys=False)
