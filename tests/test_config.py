from pathlib import Path

import pytest
import yaml

from zfloc_stream.config import Settings, load_settings
from zfloc_stream.errors import ConfigError

ROOT = Path(__file__).resolve().parents[1]


def test_default_yaml_names_every_setting_with_its_default():
    on_disk = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    assert on_disk == Settings().model_dump()


def test_every_config_file_loads():
    for path in sorted((ROOT / "configs").glob("*.yaml")):
        load_settings(path)


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
