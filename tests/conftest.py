"""Shared test helpers.

Helpers that more than one test file needs live in helper modules beside the tests, never in
a test module (importing a test file from another couples them and re-collects nothing):

    plan_helpers     a small synthetic building and a BEV observation of it (scoring, RANSAC)
    laser_helpers    simulated 2D laser walks and Carmen logs written from them
    session_helpers  fake and real-engine MCAP sessions
    backbone_helpers RGB frames and sessions for the camera backbones
    frontend_scene   camera sequences with known walls (gravity, wall mask, BEV)
    ros2_bag         rosbag2 MCAP writers
    fuzz_inputs      hostile floorplans and settings
    draw_helpers     a synthetic solver workload (BEV lines, a cluttered floorplan)
    localizer_helpers  running a Localizer: odometry jumps, overrides, estimates as bytes
    shared_data      where ../shared/data lies (beside the checkout, else /work/shared/data)

This conftest puts the tests folder on sys.path (whatever pytest's import mode), so test
files import them by name.
"""

import sys
from pathlib import Path

_HERE = str(Path(__file__).resolve().parent)
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)
