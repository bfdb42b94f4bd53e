"""The two backbone interfaces and the guarded import of the [torch] extra with transformers.

A backbone turns a batch of RGB images (HxWx3 uint8, RGB order) into one array per image
at the image's own size, so its pixels line up with the camera intrinsics K:
- DepthBackbone: HxW float32 metric depth in metres (0 = no reading);
- SegmentationBackbone: HxW uint8 label codes of frames.py (0 unknown, 1 wall, 2 floor,
  3 ceiling, 4 other).
Anything with these methods works (a test double, an ONNX runtime); hf.py adapts the
Hugging Face transformers models.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..errors import BackboneError

# torch's guarded import and device choice live in torch_support (the torch scorer uses them
# too); re-exported here for the backbones and the localizer
from ..runtime.torch_support import INSTALL_HINT, TORCH_VERSION, choose_device, require_torch  # noqa: F401


class DepthBackbone(Protocol):
    name: str

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]: ...


class SegmentationBackbone(Protocol):
    name: str

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]: ...


def import_torch():
    """(torch, transformers), or a BackboneError that says exactly what to install."""
    torch = require_torch("RGB backbones")
    try:
        import transformers
    except ImportError as err:
        raise BackboneError(f"RGB backbones need the optional [torch] extra ({err}): install it with: {INSTALL_HINT}") from None
    return torch, transformers
