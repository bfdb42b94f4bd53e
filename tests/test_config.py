from pathlib import Path

import pytest
import yaml

from zfloc_stream.settings.loading import Settings, load_settings
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


# Issue 44: hostile settings files and values (one line each, nothing echoed, fast).
ALIAS_BOMB = "a: &a [x,x,x,x,x,x,x,x,x,x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{','.join(['*' + chr(97 + i)] * 10)}]\n" for i in range(8)
)


def test_alias_bombs_are_refused_without_expanding_them(tmp_path):
    path = tmp_path / "bomb.yaml"
    path.write_text(ALIAS_BOMB)
    with pytest.raises(ConfigError, match="expands to more than"):
        load_settings(path)
    flow = "{" + ALIAS_BOMB.strip().replace("\n", ", ") + "}"
    with pytest.raises(ConfigError, match="expands to more than"):
        load_settings(None, [f"seed={flow}"])


def test_self_containing_yaml_is_refused():
    with pytest.raises(ConfigError, match="nested deeper"):
        load_settings(None, ["seed=&a [*a]"])


@pytest.mark.parametrize("special", ["/dev/zero", "fifo", "folder"])
def test_config_that_is_not_a_regular_file_is_refused_at_once(tmp_path, special):
    import os

    if special == "fifo":
        path = tmp_path / "fifo"
        os.mkfifo(path)
    elif special == "folder":
        path = tmp_path
    else:
        path = Path(special)
    with pytest.raises(ConfigError) as err:
        load_settings(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_oversized_config_is_refused_before_parsing(tmp_path):
    path = tmp_path / "big.yaml"
    path.write_text("".join(f"k{i}: {i}\n" for i in range(100_000)))
    with pytest.raises(ConfigError, match="byte limit"):
        load_settings(path)


def test_errors_never_echo_a_foreign_files_contents(tmp_path):
    path = tmp_path / "shadow"
    path.write_text("root:$6$secrethash:19000:0:99999:7:::\ndaemon:*:19000:0:99999:7:::\n")
    with pytest.raises(ConfigError) as err:
        load_settings(path)
    message = str(err.value).replace(str(path), "PATH")
    assert "secrethash" not in message and "root" not in message
    path.write_text("estimator:\n  foo: [1, 2\n secret_value: 3\n")
    with pytest.raises(ConfigError) as err:
        load_settings(path)
    assert "secret_value" not in str(err.value) and "line 3" in str(err.value)


@pytest.mark.parametrize("value", ["0", "-0.0", "'off'", "'no'", "1", "!!binary aGVsbG8="])
def test_on_off_settings_take_true_or_false_only(value):
    with pytest.raises(ConfigError, match="must be true or false"):
        load_settings(None, [f"logging.background={value}"])
    assert load_settings(None, ["logging.background=false"]).logging.background is False


@pytest.mark.parametrize("value", ["0x10", "0b11", "!!binary MTY="])
def test_integer_settings_refuse_hex_binary_and_bytes(value):
    with pytest.raises(ConfigError, match="must be a number"):
        load_settings(None, [f"seed={value}"])
