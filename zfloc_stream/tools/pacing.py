"""Pacing a run to its input's clock (`--realtime`, `--rate X`): a recorded log plays as
fast as the localizer goes (a 910-frame laser log in 17 s); paced, each frame is handed
on no earlier than its timestamp says, scaled by the rate, so a live viewer watches the
run as the robot moved.

    for frame in paced(frames, rate=2.0):   # twice real time
        ...

Frame i is due at start + (t_i - t_0) / rate, start being when the first frame came: a
frame that comes late (slow source, slow round) is handed on at once and the schedule
is kept, not shifted, so the run catches up afterwards. Stamps that go backwards wait
for nothing (the schedule follows the latest stamp seen).
"""

from __future__ import annotations

import math
import time

from .cli_support import print_warning

CLOCK, SLEEP = time.monotonic, time.sleep  # the defaults, looked up when a Pacer is made
LONG_WAIT = 10.0  # seconds: a wait this long is said once, so a gap in a log does not look like a hang


class Pacer:
    def __init__(self, rate: float = 1.0, clock=None, sleep=None, warn=print_warning):
        """rate: times real time (> 0). clock() -> seconds and sleep(seconds): the module's
        CLOCK and SLEEP (time.monotonic, time.sleep) unless given; tests inject a fake clock."""
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be a positive number, got {rate}")
        self.rate = rate
        self._clock = clock or CLOCK
        self._sleep = sleep or SLEEP
        self._warn = warn
        self._origin: tuple[float, float] | None = None  # (first stamp, clock then)
        self._latest = -math.inf
        self._said_long = False

    def wait(self, stamp: float, index: int | None = None) -> float:
        """Sleep until the frame stamped `stamp` is due; returns the seconds slept."""
        now = self._clock()
        if self._origin is None:
            self._origin = (stamp, now)
            self._latest = stamp
            return 0.0
        self._latest = max(self._latest, stamp)
        first, start = self._origin
        delay = start + (self._latest - first) / self.rate - now
        if delay <= 0:
            return 0.0
        if delay >= LONG_WAIT and not self._said_long:
            self._said_long = True
            at = "" if index is None else f" at frame {index}"
            self._warn(f"paced run: the input's clock jumps{at}, waiting {delay:.1f} s (long waits are said once)")
        self._sleep(delay)
        return delay


def paced(frames, rate: float = 1.0, clock=None, sleep=None):
    """The frames, each handed on when its timestamp is due (see Pacer)."""
    pacer = Pacer(rate, clock, sleep)
    for index, frame in enumerate(frames):
        pacer.wait(frame.timestamp, index)
        yield frame
