"""Retired settings (settings/retired.py): algorithm-internal tuning that became named
constants. Each constant has exactly the retired default (value and type, so behaviour is
unchanged bit for bit); config files and session logs that still name a retired key load,
silently where the value is the constant's, with one warning where it is not; a --set
override of one is an error that says what the value is now."""

import importlib
import warnings
from pathlib import Path

import pytest
import yaml

from zfloc_stream.errors import ConfigError
from zfloc_stream.io.session import read_session
from zfloc_stream.settings.loading import Settings, load_settings
from zfloc_stream.settings.retired import RETIRED, RetiredSettingWarning, drop_retired
from zfloc_stream.tools.cli_support import install_warning_format

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = sorted((ROOT / "replay").glob("*.mcap"))


def _constant(home: str):
    module, name = home.split(":")
    return getattr(importlib.import_module(module), name)


@pytest.mark.parametrize("key", sorted(RETIRED))
def test_each_retired_key_is_a_constant_with_the_old_default(key):
    fixed, home = RETIRED[key]
    constant = _constant(home)
    assert constant == fixed and type(constant) is type(fixed), (key, home, constant)
    section = Settings().model_dump()
    for part in key.split(".")[:-1]:
        section = section[part]
    assert key.split(".")[-1] not in section, f"{key} is retired but still a setting"


def test_retired_keys_are_not_in_the_default_config():
    text = yaml.safe_load((ROOT / "configs" / "default.yaml").read_text())
    assert drop_retired(text, "default.yaml") == text


def _config(tmp_path, text: str) -> Path:
    path = tmp_path / "old.yaml"
    path.write_text(text)
    return path


def test_a_config_naming_a_retired_key_at_its_constant_loads_silently(tmp_path):
    path = _config(tmp_path, "bev:\n  crop_margin: 0.5\n  resolution: 0.05\nprimitives:\n  lines:\n  "
                             "  min_seed_neighbours: 3\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_settings(path) == Settings()


def test_a_config_setting_a_retired_key_otherwise_warns_once_and_is_not_applied(tmp_path):
    path = _config(tmp_path, "estimator:\n  refine:\n    huber_delta: 0.2\n    max_evaluations: 12\n")
    with pytest.warns(RetiredSettingWarning) as record:
        settings = load_settings(path)
    assert len(record) == 1
    text = str(record[0].message)
    assert "estimator.refine.huber_delta=0.2 is ignored" in text and "fixed at 0.1 (HUBER_DELTA)" in text
    assert settings.estimator.refine.max_evaluations == 12  # the rest of the file applies
    assert settings == load_settings(overrides=["estimator.refine.max_evaluations=12"])
    # printed by the command-line tools as one `warning:` line
    install_warning_format()
    line = warnings.formatwarning(record[0].message, record[0].category, record[0].filename, record[0].lineno)
    assert line.startswith("warning: ") and line.count("\n") == 1


def test_an_override_of_a_retired_key_says_it_is_fixed():
    with pytest.raises(ConfigError, match=r"'bev.free_margin' is no longer a setting: fixed at 0.1 \(FREE_MARGIN"):
        load_settings(overrides=["bev.free_margin=0.2"])


def test_dropping_leaves_the_callers_tree_alone():
    tree = {"bev": {"crop_margin": 0.7, "resolution": 0.05}, "seed": 1}
    with pytest.warns(RetiredSettingWarning):
        kept = drop_retired(tree, "x")
    assert kept == {"bev": {"resolution": 0.05}, "seed": 1}
    assert tree == {"bev": {"crop_margin": 0.7, "resolution": 0.05}, "seed": 1}
    assert drop_retired({"bev": 3}, "x") == {"bev": 3}  # not a section: left for validation to refuse


@pytest.mark.parametrize("path", SAMPLES, ids=[p.stem for p in SAMPLES])
def test_the_replay_samples_read_without_a_warning(path):
    """A sample recorded when the retired keys were settings names them at the values the
    constants now hold; one recorded since names none: either way it reads (and replays)
    without a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_session(path).settings is not None


def test_a_replay_sample_from_before_the_retirement_logs_retired_keys():
    """office-laser.mcap was recorded when crop_margin and huber_delta were settings: the
    test above reads such a log, not only logs written since."""
    session = read_session(next(p for p in SAMPLES if p.stem == "office-laser"))
    assert "crop_margin" in session.settings_yaml and "huber_delta" in session.settings_yaml


def test_a_log_that_set_a_retired_key_otherwise_says_the_replay_may_differ(tmp_path, monkeypatch):
    from session_helpers import write_fake_session

    from benchmarks.inputs.session_frames import laser_frames
    from zfloc_stream.io.session import writer

    def dump_with_an_old_key(settings):
        data = settings.model_dump()
        data["bev"]["scan_match_min_gain"] = 0.3
        return yaml.safe_dump(data, sort_keys=False)

    monkeypatch.setattr(writer, "dump_settings", dump_with_an_old_key)
    path = tmp_path / "old.mcap"
    write_fake_session(path, laser_frames(2))
    with pytest.warns(RetiredSettingWarning) as record:
        session = read_session(path)
    assert len(record) == 1
    assert "the log set bev.scan_match_min_gain=0.3, now fixed at 0.2 (MIN_GAIN); the replay may differ" in str(record[0].message)
    assert session.settings == Settings()
