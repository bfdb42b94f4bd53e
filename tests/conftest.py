"""Shared test helpers.

Helpers that more than one test file needs live in helper modules beside the tests, never in
a test module (importing a test file from another couples them and re-collects nothing):

    plan_helpers     a small synthetic building and a BEV observation of it (scoring, RANSAC)
    laser_helpers    simulated 2D laser walks and Carmen logs written from them
    session_helpers  stand-in estimates, fake and real-engine MCAP sessions
    ros2_bag         rosbag2 MCAP writers
    draw_helpers     a synthetic solver workload (BEV lines, a cluttered floorplan)
    localizer_helpers  running a Localizer: odometry jumps, overrides, estimates as bytes

Inputs the benchmarks build too live once, in benchmarks/ (imported as `benchmarks.…`; the
repository root is on pytest's pythonpath, pyproject.toml):

    benchmarks/inputs/session_frames    random camera and laser frames
    benchmarks/inputs/hostile_sessions  sessions written out of order or otherwise odd
    benchmarks/inputs/random_backbones  RGB frames, sessions and toy networks for the backbones
    benchmarks/inputs/box_world         camera sequences with known walls (gravity, wall mask, BEV)
    benchmarks/inputs/hostile_plans     hostile floorplans and settings
    benchmarks/inputs/plan_bombs        large or malicious vector plans
    benchmarks/inputs/batch_trial       the batch-localization scenario
    benchmarks/shared_data              where ../shared/data lies (beside the checkout, else /work/shared/data)
    benchmarks/evaluation/plan_drawing  a raster map redrawn as an architect's plan

This conftest puts the tests folder on sys.path (whatever pytest's import mode), so test
files import them by name.
"""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
