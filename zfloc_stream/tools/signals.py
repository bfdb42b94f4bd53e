"""SIGTERM ends a command as Ctrl-C (SIGINT) does: service managers and containers stop
a process with SIGTERM, and a run must then close its session file (footer, summary) and
say how it ended, instead of dying mid-chunk.

    with terminate_as_interrupt():
        ...                                    # SIGTERM raises Terminated here
    except KeyboardInterrupt as err:
        return interrupted("zfloc-stream", err)
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading

EXIT_INTERRUPTED = 130  # 128 + SIGINT
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived: unwinds like Ctrl-C, so every `with` block closes its files."""


def _raise_terminated(signum, frame):
    raise Terminated()


@contextlib.contextmanager
def terminate_as_interrupt():
    """Within the block SIGTERM raises Terminated (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def interrupted(prog: str, err: BaseException) -> int:
    """One line on stderr saying how the command ended; the exit code for it."""
    if isinstance(err, Terminated):
        print(f"{prog}: terminated (SIGTERM): outputs written so far were closed; exit {EXIT_TERMINATED}", file=sys.stderr)
        return EXIT_TERMINATED
    print(f"{prog}: interrupted: outputs written so far were closed; exit {EXIT_INTERRUPTED}", file=sys.stderr)
    return EXIT_INTERRUPTED
