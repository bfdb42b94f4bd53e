"""Give freed heap memory back to the operating system after each round.

A round allocates and frees tens of MB of numpy temporaries (scoring chunks, FFT planes).
glibc raises its mmap threshold each time such a block is freed, so later blocks of that
size come from the heap, and a heap that freed them keeps its pages: resident memory
then drifts up and down by tens of MB over a long session without anything leaking
(measured, benchmarks/bench_localizer.py). malloc_trim(0) returns the free pages; it costs
about 2 ms on the shared 2-core machine. Elsewhere (no glibc) this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _malloc_trim():
    name = ctypes.util.find_library("c")
    try:
        trim = ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):  # not glibc (musl, macOS, Windows)
        return None
    if trim is not None:
        trim.argtypes, trim.restype = [ctypes.c_size_t], ctypes.c_int
    return trim


def release_free_heap() -> bool:
    """Return the allocator's free pages to the OS; True where that was possible."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
