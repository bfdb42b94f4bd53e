"""3D scene simulator: built-in scenes, depth/label rendering, trajectories, sensor noise."""

from .scenes import SCENES, Scene, build_scene

__all__ = ["SCENES", "Scene", "build_scene"]
