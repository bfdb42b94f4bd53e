"""Frames a run drops are never dropped silently: each cause is warned about once (with
where it first happened), every drop is counted, and the counts are summed up at the end.

    drops = DropCounter("session.mcap")
    drops.note("depth contains inf", "t=12.5")   # warns the first time only
    drops.summary()                              # warns '3 frames dropped: ...' when any
"""

from __future__ import annotations

import re
import warnings
from collections import Counter


class FrameDropWarning(UserWarning):
    """A frame was dropped (the first one of its cause; the rest are counted)."""


_WHERE = re.compile(r"^(t=[-0-9.e+]+): (?:frame dropped: )?")
_LOG_TIME = re.compile(r" \(log time \d+\)$")


class DropCounter:
    def __init__(self, source: str):
        self.source = source
        self.counts: Counter[str] = Counter()
        self.other: set[str] = set()  # causes of other problems already warned about

    def note(self, cause: str, where: str = "") -> None:
        self.counts[cause] += 1
        if self.counts[cause] == 1:
            at = f" (first at {where}; further ones are counted)" if where else " (further ones are counted)"
            warnings.warn(f"{self.source}: frame dropped: {cause}{at}", FrameDropWarning, stacklevel=2)

    def note_problem(self, problem: str) -> None:
        """A reader's problem line: a dropped frame ('t=...: frame dropped: why') is counted
        by its cause; anything else ('... skipped: why (log time N)') is warned about once."""
        m = _WHERE.match(problem)
        if m or "frame dropped" in problem:
            self.note(problem[m.end():] if m else problem, m.group(1) if m else "")
            return
        if not any(word in problem for word in ("dropped", "skipped", "stopped", "damaged", "converted", "ignored")):
            return  # a note that loses nothing (repeated stamps kept in file order)
        cause = _LOG_TIME.sub("", problem)
        if cause not in self.other:
            self.other.add(cause)
            warnings.warn(f"{self.source}: {problem}", FrameDropWarning, stacklevel=2)

    @property
    def total(self) -> int:
        return sum(self.counts.values())

    def summary(self) -> None:
        if self.counts:
            causes = "; ".join(f"{cause} ({n})" for cause, n in self.counts.most_common())
            warnings.warn(f"{self.source}: {self.total} frame(s) dropped: {causes}", FrameDropWarning, stacklevel=2)


__all__ = ["DropCounter", "FrameDropWarning"]
