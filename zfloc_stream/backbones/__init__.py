"""Pretrained networks for plain RGB cameras: metric depth and wall/floor/ceiling labels.

Needs the optional [torch] extra (torch, transformers), imported only when a backbone is
made; without it, asking for one raises a BackboneError that says what to install.
"""

from .base import INSTALL_HINT, DepthBackbone, SegmentationBackbone, import_torch
from .labels import class_codes
from .perception import Perception, needs_backbones

__all__ = ["INSTALL_HINT", "DepthBackbone", "Perception", "SegmentationBackbone", "class_codes", "import_torch", "needs_backbones"]
