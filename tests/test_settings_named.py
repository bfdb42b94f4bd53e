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

# Settings not yet named by a test: the user-facing sections whose boundary tests are being
# written (issue 42). This list may only shrink: a setting that gains a test leaves it (the
# test below fails while it is still listed), and no setting may join it.
NOT_YET_NAMED = {
    "estimator.scoring.violation_weight",
    "estimator.scoring.wall_bucket_size",
    "estimator.ransac.guided_modes",
    "estimator.ransac.guided_distance",
    "estimator.ransac.guided_angle_deg",
    "localizer.local_every_k_frames",
    "prior.gate_sigmas",
    "prior.seed_step",
    "prior.seed_angle_step_deg",
    "prior.max_seeds",
    "prior.contradiction_gap",
    "prior.doubt_gap",
    "prior.contradiction_rounds",
    "prior.release_rounds",
    "logging.foreign_scan_range_min",
    "logging.foreign_scan_range_max",
    "logging.success_distance",
    "logging.success_last_frames",
    "datasets.ros2.max_odometry_gap",
    "datasets.vector_floorplan.solid_max_width",
    "datasets.odometry.heading_noise_per_m",
    "datasets.odometry.translation_floor",
    "datasets.odometry.heading_floor_deg",
    "datasets.odometry.origin_extent",
    "datasets.gibson.focal_fraction",
    "datasets.gibson.map_resolution",
    "datasets.carmen.flaser_fov_deg",
    "datasets.carmen.flaser_start_deg",
    "datasets.carmen.min_range",
    "datasets.carmen.heldout_margin",
    "datasets.mapping.logodds_free",
    "datasets.mapping.free_range",
    "datasets.mapping.free_margin",
    "datasets.sim.scene_seed",
    "study.eval_frames",
    "study.max_chunks_per_sequence",
    "study.connect_timeout_s",
    "backbones.seg_model",
    "backbones.half_on_gpu",
    "backbones.floor_classes",
    "backbones.ceiling_classes",
    "backbones.unknown_classes",
}


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
    new = sorted(set(missing) - NOT_YET_NAMED)
    print(f"{len(missing)} settings named by no test:", *missing, sep="\n  ")
    assert not new, ("settings named by no test (give each a boundary test, or make it a constant with a "
                     "why-comment and list it in settings/retired.py): " + ", ".join(new))
    named = sorted(NOT_YET_NAMED - set(missing))
    assert not named, "named by a test now: remove from NOT_YET_NAMED: " + ", ".join(named)
