"""Front end: gravity from the floor, wall-mask refinement, geometric labeller, RollingBEV."""

from .bev import RollingBEV
from .gravity import GravityEstimator, plane_pose, rotation_from_up
from .labeller import label_frame
from .wallmask import refine_wall_mask, upright_rotation

__all__ = [
    "GravityEstimator",
    "RollingBEV",
    "label_frame",
    "plane_pose",
    "refine_wall_mask",
    "rotation_from_up",
    "upright_rotation",
]
