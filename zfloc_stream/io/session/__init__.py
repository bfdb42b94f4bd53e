"""MCAP session logs (Foxglove-compatible): the sink, the source and replay.

- SessionWriter: logs every input frame and every Estimate of a run (writer.py).
- read_session: a session file (ours, or another tool's on the same topics) as settings,
  floorplan, input frames and the outputs logged per frame (reader.py).
- record_session: the localizer loop with logging, as every recorder should run it.
- replay: re-runs the engine on a session's inputs and compares or rewrites (replay.py).
Topics and schemas: schemas.py (docs/inputs.md table).
"""

from .reader import FrameRecord, LoggedOutputs, Session, read_session
from .record import record_session
from .schemas import BevGrid
from .writer import SessionWriter

__all__ = ["BevGrid", "FrameRecord", "LoggedOutputs", "Session", "SessionWriter", "read_session", "record_session"]
