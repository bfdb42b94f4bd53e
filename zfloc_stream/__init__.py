"""zfloc-stream: online zero-shot floorplan localization."""

from .config import Settings, load_settings
from .errors import ZflocError
from .estimate import Alternative, Estimate
from .floorplan import Floorplan
from .frames import CameraFrame, LaserFrame
from .localizer import Localizer
from .sim2 import Sim2

__all__ = [
    "Alternative", "CameraFrame", "Estimate", "Floorplan", "LaserFrame", "Localizer", "Settings", "Sim2",
    "ZflocError", "load_settings",
]
__version__ = "0.1.0"
