from pathlib import Path

import pytest
import yaml

from zfloc_stream.config import Settings, load_settings
from zfloc_stream.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_default_yaml_names_every_setting_with_its_default():
    on_disk = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    assert on_disk == Settings().model_dump()


def _leaves(tree, prefix=()):
    """{("estimator", "solvers", "pool"): value} for every setting a nested dict names."""
    out = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(_leaves(value, prefix + (key,)))
        else:
            out[prefix + (key,)] = value
    return out


@pytest.mark.parametrize("path", sorted((ROOT / "configs").glob("*.yaml")), ids=lambda p: p.name)
def test_every_config_file_loads_as_it_says(path):
    """Each shipped file loads, every setting it names has the file's value, every other
    setting keeps its default, and a file other than default.yaml changes something."""
    written = _leaves(yaml.safe_load(path.read_text()) or {})
    loaded, defaults = _leaves(load_settings(path).model_dump()), _leaves(Settings().model_dump())
    assert written, f"{path.name} names no setting"
    for key, value in written.items():
        assert loaded[key] == value, (path.name, ".".join(key))
    assert {k: v for k, v in loaded.items() if k not in written} == {k: v for k, v in defaults.items() if k not in written}
    if path.name != "default.yaml":
        assert any(defaults[k] != v for k, v in written.items()), f"{path.name} only repeats defaults"


def test_dotted_overrides_are_parsed_as_yaml():
    s = load_settings(overrides=["estimator.ransac.iterations=42", "seed=7"])
    assert s.estimator.ransac.iterations == 42 and s.seed == 7


@pytest.mark.parametrize(
    "override, fragment",
    [
        (["estimator.ransac.iterationz=3"], "unknown setting 'estimator.ransac.iterationz'"),
        (["seed=abc"], "setting 'seed'"),
        (["noequals"], "dotted.key=value"),
    ],
)
def test_bad_overrides_raise_config_error(override, fragment):
    with pytest.raises(ConfigError, match=fragment):
        load_settings(overrides=override)


def test_missing_and_malformed_config_files(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_settings(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("- a list\n")
    with pytest.raises(ConfigError, match="mapping"):
        load_settings(bad)
