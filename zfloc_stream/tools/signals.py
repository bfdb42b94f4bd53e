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


def interruption_in(err: BaseException | None) -> KeyboardInterrupt | None:
    """The KeyboardInterrupt (Ctrl-C, or Terminated) that err is or was raised from, else
    None. A signal that lands while compiled code calls back into Python comes out as a
    SystemError chained to the interrupt: Ctrl-C while numba loaded a kernel from its cache
    (a fresh install's first run) ended `zfloc-stream demo` with a traceback and exit 1."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return err
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


def interrupted(prog: str, err: BaseException) -> int:
    """One line on stderr saying how the command ended; the exit code for it."""
    if isinstance(err, Terminated):
        print(f"{prog}: terminated (SIGTERM): outputs written so far were closed; exit {EXIT_TERMINATED}", file=sys.stderr)
        return EXIT_TERMINATED
    print(f"{prog}: interrupted: outputs written so far were closed; exit {EXIT_INTERRUPTED}", file=sys.stderr)
    return EXIT_INTERRUPTED
