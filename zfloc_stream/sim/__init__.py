"""3D scene simulator: built-in scenes, depth/label rendering, trajectories, sensor noise."""

from .from_floorplan import build_scene_from_floorplan
from .layout import Connection, Room, snap
from .render import camera_pose, intrinsics, render
from .scenes import SCENES, build_scene
from .scenes import Scene, make_scene
from .simulator import (LaserSequence, LaserSimSettings, SimSequence, SimSettings, drift_odometry, simulate,
                        simulate_laser)
from .trajectory import WalkSettings, plan_path, random_walk, trajectory_through

__all__ = [
    "SCENES", "Connection", "LaserSequence", "LaserSimSettings", "Room", "Scene", "SimSequence", "SimSettings",
    "WalkSettings", "build_scene", "build_scene_from_floorplan", "camera_pose", "drift_odometry", "intrinsics", "make_scene", "plan_path",
    "random_walk", "render", "simulate", "simulate_laser", "snap", "trajectory_through",
]
