"""Keep the process's heap from growing over a long session: few malloc arenas, and freed
memory given back to the operating system once it has piled up.

glibc gives threads their own malloc arenas (up to 8 per core) and each keeps what its
thread used at its peak. With the rounds on a worker thread beside the stream, resident
memory grew by 16-24 MiB per 1,000 frames over 4,000 frames of the built-in apartment walk
(three runs; +26 MiB from frame 1,000 to 10,000 in a longer one), with no Python object,
numpy array or compiled-kernel allocation alive to explain it (tracemalloc and numba's
allocation counts flat); with one or two arenas (MALLOC_ARENA_MAX) it stayed at the first
1,000 frames' level, like the inline path, which has no worker. limit_arenas caps them
(mallopt(M_ARENA_MAX)): a process-wide allocator setting, taken when a Localizer's round
scheduler is built (localizer.malloc_arenas; 0 leaves glibc's choice).

A round allocates and frees tens of MB of numpy temporaries (scoring chunks, FFT planes).
glibc raises its mmap threshold each time such a block is freed, so later blocks of that
size come from the heap, and a heap that freed them keeps its pages: resident memory
then drifts up and down by tens of MB over a long session without anything leaking
(measured, benchmarks/bench_localizer.py). malloc_trim(0) returns the free pages (about
2 ms on the shared 2-core machine).

Trimming after every round has a price in the stream's time: it also returns the free
pages the stream's own fusion reuses every frame, and the push after it faults them back
in (a camera push at a round's join frame took 8.2 instead of 5.9 ms, median, on the shared
sessions; docs/performance.md). So a round trims only once the process's resident memory
has grown by `growth` bytes since the last trim: the drift stays bounded by that much
and most pushes find their pages warm. Elsewhere (no glibc, no /proc) this does nothing
or trims every time it is asked.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import threading

_lock = threading.Lock()
_resident_after_trim: int | None = None  # bytes resident right after this process's last trim


_M_ARENA_MAX = -8  # mallopt's parameter number in glibc's malloc.h


@functools.cache
def _glibc():
    """The C library's malloc_trim and mallopt, typed; None where they are missing (musl,
    macOS, Windows)."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name) if name else None
        trim, mallopt = (libc.malloc_trim, libc.mallopt) if libc is not None else (None, None)
    except (OSError, AttributeError):
        return None
    if trim is None:
        return None
    trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return trim, mallopt


def _malloc_trim():
    return None if _glibc() is None else _glibc()[0]


@functools.cache
def limit_arenas(count: int) -> bool:
    """At most `count` malloc arenas in this process from now on (glibc; once per count).
    True where the allocator took it."""
    if count <= 0 or _glibc() is None:  # 0: glibc's own choice; not glibc: nothing to set
        return False
    return _glibc()[1](_M_ARENA_MAX, int(count)) == 1


def resident_bytes() -> int | None:
    """The process's resident memory (Linux /proc/self/statm), None where it cannot be read."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return None


def release_free_heap(growth: int = 0) -> bool:
    """Return the allocator's free pages to the OS if resident memory grew by at least
    `growth` bytes since the last such release in this process (0: always). True when it
    trimmed."""
    global _resident_after_trim
    trim = _malloc_trim()
    if trim is None:
        return False
    with _lock:  # several localizers in one process share the heap and this record
        if growth > 0 and _resident_after_trim is not None:
            now = resident_bytes()
            if now is not None and now - _resident_after_trim < growth:
                return False
        trim(0)
        _resident_after_trim = resident_bytes()
    return True
