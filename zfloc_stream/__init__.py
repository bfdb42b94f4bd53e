"""zfloc-stream: online zero-shot floorplan localization."""

from .config import Settings, load_settings
from .errors import ZflocError
from .sim2 import Sim2

__all__ = ["Settings", "Sim2", "ZflocError", "load_settings"]
__version__ = "0.1.0"
