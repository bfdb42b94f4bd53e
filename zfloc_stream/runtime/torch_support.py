"""The one guarded import of torch (the optional [torch] extra) and the choice of its device,
for everything that runs torch: the camera backbones and the torch scorer
(scoring.backend: torch). A low module of its own, so the estimation layer need not import
the backbones layer for them."""

from __future__ import annotations

from ..errors import BackboneError

TORCH_VERSION = "2.13.0"  # the build CI and the README install
INSTALL_HINT = f"pip install torch=={TORCH_VERSION} 'transformers>=4.57,<6' (the zfloc-stream[torch] extra)"  # one space: the CLI's one-line errors collapse runs of spaces


def require_torch(purpose: str):
    """torch, or a BackboneError that says exactly what to install. Imported here only, on
    first use: the package itself never needs torch."""
    try:
        import torch
    except ImportError as err:
        raise BackboneError(f"{purpose} needs the optional [torch] extra ({err}): install it with: {INSTALL_HINT}") from None
    return torch


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
