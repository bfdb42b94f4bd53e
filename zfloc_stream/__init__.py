"""zfloc-stream: online zero-shot floorplan localization.

The public names are imported on first use (PEP 562), so a command line that only parses
its arguments (`zfloc-stream --help`, a usage error) never imports scipy, scikit-learn or
numba.
"""

from importlib import import_module

_PUBLIC = {
    "Settings": ".settings.loading", "load_settings": ".settings.loading", "ZflocError": ".errors",
    "Alternative": ".estimate", "Estimate": ".estimate", "Floorplan": ".plans.floorplan", "CameraFrame": ".frames",
    "LaserFrame": ".frames", "Localizer": ".stream.localizer", "Sim2": ".geometry.sim2", "load_floorplan": ".plans.loading",
}

__all__ = sorted(_PUBLIC)
__version__ = "0.1.0"


def __getattr__(name: str):
    if name not in _PUBLIC:
        raise AttributeError(f"module 'zfloc_stream' has no attribute {name!r}")
    value = getattr(import_module(_PUBLIC[name], __name__), name)
    globals()[name] = value  # once: later lookups skip this function
    return value


def __dir__():
    return sorted(set(globals()) | set(_PUBLIC))
