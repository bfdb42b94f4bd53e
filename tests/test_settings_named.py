"""Every setting a person can set is named by some test (issue 42, "settings a person can
hold"): a setting no test names can change, or stop mattering, without anyone noticing.
A setting either has a test that shows what it does (a boundary test: the smallest input
on each side of the value) or is not a setting: algorithm-internal tuning is a named
constant next to the code that uses it (settings/retired.py lists those).

Named: the setting's own name, as a word, in a test module other than this one (the
config files list every setting and do not count; nor does a retired key's dotted name,
such as bev.free_margin, which names no setting of that name elsewhere)."""

import re
from pathlib import Path

from pydantic import BaseModel

from zfloc_stream.settings.loading import Settings
from zfloc_stream.settings.retired import RETIRED

TESTS = Path(__file__).resolve().parent


def setting_keys(model: BaseModel, prefix: tuple = ()) -> list[tuple[str, ...]]:
    """Every leaf setting of a settings model, as its dotted path's parts."""
    keys = []
    for name in type(model).model_fields:
        value = getattr(model, name)
        keys += setting_keys(value, prefix + (name,)) if isinstance(value, BaseModel) else [prefix + (name,)]
    return keys


def unnamed_settings() -> list[str]:
    text = "\n".join(p.read_text(encoding="utf-8") for p in sorted(TESTS.rglob("*.py")) if p.resolve() != Path(__file__).resolve())
    for retired in RETIRED:
        text = text.replace(retired, "")
    return [".".join(key) for key in setting_keys(Settings()) if not re.search(rf"\b{re.escape(key[-1])}\b", text)]


def test_every_setting_is_named_by_a_test():
    missing = unnamed_settings()
    print(f"{len(missing)} settings named by no test:", *missing, sep="\n  ")
    assert not missing, ("settings named by no test (give each a boundary test, or make it a constant with a "
                         "why-comment and list it in settings/retired.py): " + ", ".join(missing))
