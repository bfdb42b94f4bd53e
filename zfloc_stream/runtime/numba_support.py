"""The compiled kernels' one `njit` (numba is a core dependency).

numba is imported by the kernel modules only (they are imported when a Localizer or an
estimation stage first needs them), so `zfloc-stream --help` and a bad-input error never
pay for it. Kernels are compiled once per machine and cached next to their module
(numba's on-disk cache): a new process pays milliseconds, not the compile, from the
second run on. The first compile of a process says so in one stderr line, so a user never
waits in silence. Every kernel is compiled without fastmath (no reassociation, no fused
multiply-add), so an element-wise kernel gives numpy's bits; kernels that sum in another
order than numpy say so.
"""

from __future__ import annotations

import sys
import threading

import numba
from numba.core import event

COMPILE_NOTICE = (
    "zfloc-stream: compiling the numba kernels (once per machine, cached; this can take a few minutes) ..."
)

_notice_lock = threading.Lock()
_noticed = False


class _FirstCompileNotice(event.Listener):
    """Prints COMPILE_NOTICE at the first compile this process does. numba fires
    "numba:compile" only for a real compile, never for a kernel loaded from its cache, so
    a warm machine prints nothing."""

    def on_start(self, ev):
        global _noticed
        with _notice_lock:
            if _noticed:
                return
            _noticed = True
        print(COMPILE_NOTICE, file=sys.stderr, flush=True)

    def on_end(self, ev):
        pass


event.register("numba:compile", _FirstCompileNotice())


def njit(fn):
    """numba.njit with the package's fixed options: cached on disk, releases the GIL (a
    pipelined round's kernels run beside the stream's fusion), numpy's error model (a
    division by zero gives inf/nan like numpy, no exception), IEEE arithmetic."""
    return numba.njit(cache=True, nogil=True, error_model="numpy", fastmath=False)(fn)
