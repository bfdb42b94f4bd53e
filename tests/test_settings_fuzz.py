"""Settings cannot crash a run: every leaf setting gets hostile values (0, negative, NaN,
infinity, huge, wrong type, plus seeded extras). Each value either ends in one ConfigError
line naming the key, or is accepted and then runs a short built-in scene to the end
without a traceback.

The default variant is mostly validation (>= 1,000 cases, a fraction of a second each);
only the distinct accepted settings run the scene, with a handful of frames. The `slow`
variant tries more values per setting."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pydantic import BaseModel

from benchmarks.inputs.hostile_plans import hostile_setting

from zfloc_stream.settings.loading import Settings, allowed_range, load_settings
from zfloc_stream.errors import ConfigError, FloorplanError
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.io.session import record_session
from zfloc_stream.sim import LaserSimSettings, SimSettings, build_scene, simulate, simulate_laser

FRAMES = 6  # a RANSAC round happens at frame 5 with the default every_k_frames
ALWAYS = (0, -1, float("nan"), math.inf, 1e300, "not-a-number")  # for every leaf setting
EXTRAS = (-1e300, -1e-9, 1e-12, 0.5, 2, 10**15, 2**63, True, [1, 2], {"x": 1}, None, "", "2L")


def leaves(model: BaseModel, prefix: str = "") -> dict[str, object]:
    """{dotted.key: FieldInfo} of every leaf setting."""
    out = {}
    for name, info in type(model).model_fields.items():
        value = getattr(model, name)
        if isinstance(value, BaseModel):
            out.update(leaves(value, f"{prefix}{name}."))
        else:
            out[f"{prefix}{name}"] = info
    return out


LEAVES = leaves(Settings())


def nested(key: str, value) -> dict:
    out = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def hostile_cases(seed: int, extras_per_leaf: int) -> list[tuple[str, object]]:
    rng = np.random.default_rng(seed)
    cases = []
    for key in LEAVES:
        cases += [(key, v) for v in ALWAYS]
        picks = rng.choice(len(EXTRAS), size=extras_per_leaf, replace=False)
        cases += [(key, EXTRAS[i]) for i in picks]
        # a seeded random magnitude on either side of zero (log-uniform 1e-12 .. 1e12)
        cases.append((key, float(rng.choice([-1, 1]) * 10 ** rng.uniform(-12, 12))))
    return cases


class ShortScenes:
    """A tiny camera walk (frontend and BEV settings) and a tiny laser walk (the rest), each
    run through the session recorder, so logging settings are exercised too."""

    def __init__(self):
        self.scene = build_scene("rooms", 0)
        self.camera = simulate(self.scene, SimSettings(width=48, height=36), seed=0, n_frames=FRAMES).frames
        self.laser = simulate_laser(self.scene, LaserSimSettings(), seed=0, n_frames=FRAMES).frames

    def run(self, key: str, settings: Settings, path) -> list:
        plan = Floorplan.from_occupancy(self.scene.occupied, self.scene.resolution, self.scene.origin, settings)
        frames = self.camera if key.startswith(("frontend.", "bev.")) else self.laser
        return record_session(path, plan, frames, settings)


def fuzz(cases, tmp_path) -> tuple[int, int]:
    accepted: dict[str, tuple[str, Settings]] = {}
    rejected = 0
    for key, value in cases:
        try:
            settings = load_settings(overrides=nested(key, value))
        except ConfigError as err:
            message = str(err)
            assert key in message and "\n" not in message, (key, value, message)
            rejected += 1
            continue
        accepted.setdefault(settings.model_dump_json(), (key, settings))
    scenes = ShortScenes()
    for i, (key, settings) in enumerate(accepted.values()):
        try:
            estimates = scenes.run(key, settings, tmp_path / f"case{i}.mcap")
        except FloorplanError as err:  # a plan budget (floorplan.max_cells...) too small for the scene
            assert key in str(err) and "\n" not in str(err), (key, str(err))
            continue
        assert len(estimates) == FRAMES, key
    return rejected, len(accepted)


def test_every_numeric_setting_has_both_bounds():
    """So a huge value is refused before it can allocate or loop: new settings must
    declare their range too (pydantic Field(default, gt/ge=..., lt/le=...))."""
    unbounded = []
    for key, info in LEAVES.items():
        if info.annotation in (int, float):
            text = allowed_range(info) or ""
            if not (text.startswith(("(", "[")) and text.split(" (")[0].endswith((")", "]"))):
                unbounded.append(key)
    assert not unbounded, f"settings without a lower and an upper bound: {unbounded}"


def test_settings_fuzz(tmp_path):
    cases = hostile_cases(seed=11, extras_per_leaf=1)
    assert len(cases) >= 1000
    rejected, ran = fuzz(cases, tmp_path)
    assert rejected + ran <= len(cases) and rejected > 0.8 * len(cases) and ran > 10


@pytest.mark.slow
def test_settings_fuzz_wide(tmp_path):
    cases = hostile_cases(seed=1011, extras_per_leaf=len(EXTRAS))
    fuzz(cases, tmp_path)


def fuzz_typed(seed: int, n: int) -> dict[str, int]:
    """n seeded `--set key=text` overrides as a user types them (booleans, base-60 and
    octal numbers, subnormals, text, nesting thousands deep): each is one ConfigError line
    naming its key, or is accepted with the value it spells (never a silent coercion)."""
    rng = np.random.default_rng(seed)
    keys = list(LEAVES)
    outcomes = {"refused": 0, "accepted": 0}
    for _ in range(n):
        override = hostile_setting(rng, keys)
        key, text = override.split("=", 1)
        try:
            settings = load_settings(overrides=[override])
        except ConfigError as err:
            message = str(err)
            assert "\n" not in message and (key in message or "nested deeper" in message), (override[:80], message)
            outcomes["refused"] += 1
            continue
        value = settings
        for part in key.split("."):
            value = getattr(value, part)
        if LEAVES[key].annotation in (int, float):  # a number setting holds a number that was written as one
            assert not isinstance(value, bool) and text.strip().lower() not in ("true", "false", "yes", "on") and ":" not in text, (override, value)
        outcomes["accepted"] += 1
    return outcomes


def test_typed_settings_fuzz():
    outcomes = fuzz_typed(seed=29, n=1200)
    assert outcomes["refused"] > 800 and outcomes["accepted"] > 20, outcomes


@pytest.mark.parametrize(
    "override, message",
    [
        ("seed=12:30:45", "setting 'seed' = '12:30:45': must be a number, got text (YAML 1.1 reads it in base 60)"),
        ("seed=010", "setting 'seed' = '010': must be a number, got text (YAML 1.1 reads it as octal)"),
        ("localizer.every_k_frames=true", "setting 'localizer.every_k_frames' = True: must be a number, not a boolean"),
        ("bev.resolution=true", "setting 'bev.resolution' = True: must be a number, not a boolean"),
        ("estimator.scale_prior=4.9e-324", "setting 'estimator.scale_prior' = 5e-324: is a subnormal number"),
        ("seed=" + "[" * 70 + "]" * 70, "nested deeper than 64 levels"),
        ("seed=" + "[" * 3000 + "]" * 3000, "override 'seed': value nested deeper than 64 levels"),
        ("localizer.every_k_frames=0", "setting 'localizer.every_k_frames' = 0: Input should be greater than or equal to 1; allowed range [1, 10000] (integer)"),
        ("tracking.gate_chi2=-5", "setting 'tracking.gate_chi2' = -5: Input should be greater than 0; allowed range (0, 1000000]"),
        ("estimator.ransac.iterations=0", "setting 'estimator.ransac.iterations' = 0"),
        ("primitives.lines.min_points=-3", "setting 'primitives.lines.min_points' = -3"),
        ("bev.logodds_hit=.nan", "setting 'bev.logodds_hit' = nan: Input should be a finite number; allowed range (0, 100]"),
        ("primitives.circles.min_radius=2", "setting 'primitives.circles.min_radius' = 2.0: must be less than primitives.circles.max_radius (1.0)"),
        ("primitives.circles.max_radius=0.05", "setting 'primitives.circles.min_radius' = 0.1: must be less than primitives.circles.max_radius (0.05)"),
        ("frontend.max_obstacle_height=0.05", "frontend.min_obstacle_height' = 0.1: must be less than frontend.max_obstacle_height"),
        ("bev.window_radius=99.5", "setting 'bev.window_radius' = 99.5: the grid would be 4020 cells wide, at most 4000"),
        ("tracking.birth_score_gap=[1]", "setting 'tracking.birth_score_gap' = [1]: Input should be a valid number"),
        ("study.thresholds=[0.5,-1]", "setting 'study.thresholds.1' = -1: Input should be greater than 0"),
    ],
)
def test_bad_value_is_one_line_naming_key_and_range(override, message):
    with pytest.raises(ConfigError) as info:
        load_settings(overrides=[override])
    assert message in str(info.value) and "\n" not in str(info.value)


def test_cli_with_a_bad_setting_is_one_line_exit_2(tmp_path, capsys):
    """The issue's reproduction: every_k_frames=0 was a ZeroDivisionError traceback."""
    from zfloc_stream.tools.cli import main

    code = main(["demo", "--frames", "3", "--out", str(tmp_path), "--no-progress", "--set", "localizer.every_k_frames=0"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "localizer.every_k_frames" in err[0] and "allowed range [1, 10000]" in err[0]
