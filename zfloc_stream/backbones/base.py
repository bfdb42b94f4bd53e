"""The two backbone interfaces and the one guarded import of the optional [torch] extra.

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

TORCH_VERSION = "2.13.0"  # the build CI and the README install
INSTALL_HINT = f"pip install torch=={TORCH_VERSION} 'transformers>=4.57,<6'  (the zfloc-stream[torch] extra)"


class DepthBackbone(Protocol):
    name: str

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]: ...


class SegmentationBackbone(Protocol):
    name: str

    def predict(self, images: list[np.ndarray]) -> list[np.ndarray]: ...


def require_torch(purpose: str):
    """torch, or a BackboneError that says exactly what to install. Imported here only, on
    first use: the package itself never needs torch."""
    try:
        import torch
    except ImportError as err:
        raise BackboneError(f"{purpose} needs the optional [torch] extra ({err}): install it with: {INSTALL_HINT}") from None
    return torch


def import_torch():
    """(torch, transformers), or a BackboneError that says exactly what to install."""
    torch = require_torch("RGB backbones")
    try:
        import transformers
    except ImportError as err:
        raise BackboneError(f"RGB backbones need the optional [torch] extra ({err}): install it with: {INSTALL_HINT}") from None
    return torch, transformers


def choose_device(torch, wanted: str, setting: str = "backbones.device"):
    """'auto' -> CUDA when present, else CPU; 'cpu', 'cuda', 'cuda:N' as given."""
    if wanted == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(wanted)
    except (RuntimeError, ValueError):
        raise BackboneError(f"{setting} '{wanted}' is not a device (auto, cpu, cuda, cuda:N)") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise BackboneError(f"{setting} is '{wanted}' but torch sees no CUDA GPU (use auto or cpu)")
    return device
