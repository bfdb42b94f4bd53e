"""Worker threads for the independent pieces of one round (estimator.threads).

The compiled kernels release the GIL (numba_support.njit) and scipy's FFTs do too, so the
pieces of a round that do not depend on one another (the correlative search's angles, the
3L draws, scoring and refining a batch of hypotheses) can run on several cores at once.
Each piece writes its own slots of the output, and the pieces are put back together in
their order, so the result is bit for bit the single-threaded one whatever the thread
count and scheduling.

How many threads a round may use is set for the calling thread with `limit` (localize
does, from estimator.threads); code outside such a block runs single-threaded. The
workers come from one pool per process, grown on demand and dropped in a forked child
(whose copy would have no threads behind it). A piece that itself asks for threads
runs them on its own thread: a worker never waits on the pool it belongs to.
"""

from __future__ import annotations

import contextlib
import contextvars
import itertools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Sequence, TypeVar

T = TypeVar("T")
R = TypeVar("R")

# most threads a round is given under `auto`: the pieces are a few milliseconds each, and
# past four the memory-bound FFTs stop gaining
AUTO_MAX = 4

_LIMIT: contextvars.ContextVar[int | None] = contextvars.ContextVar("zfloc_threads", default=None)
_IN_WORKER = threading.local()
_POOL_LOCK = threading.Lock()
_POOL: ThreadPoolExecutor | None = None
_POOL_SIZE = 0


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity, not the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not on Linux
        return max(1, os.cpu_count() or 1)


def resolve(threads: int) -> int:
    """estimator.threads as a count: 0 (auto) is every core this process may use, up to
    AUTO_MAX, whether the round runs in a push or on the worker beside the stream (the
    stream's few milliseconds per frame share the cores); any other value is taken as given."""
    if threads > 0:
        return int(threads)
    return max(1, min(AUTO_MAX, available_cores()))


@contextlib.contextmanager
def limit(threads: int, *, unless_set: bool = False):
    """Let the code in the block (on this thread) run its pieces on up to `threads`
    threads. unless_set: an enclosing block's limit stays (the localizer's round sets
    one that knows where the round runs; localize called directly sets its own)."""
    if unless_set and _LIMIT.get() is not None:
        yield
        return
    token = _LIMIT.set(max(1, int(threads)))
    try:
        yield
    finally:
        _LIMIT.reset(token)


def current() -> int:
    """Threads the calling code may use now: 1 outside a `limit` block and on a pool
    worker (no nesting)."""
    if getattr(_IN_WORKER, "active", False):
        return 1
    return _LIMIT.get() or 1


def _mark_worker() -> None:
    _IN_WORKER.active = True


def _pool(workers: int) -> ThreadPoolExecutor:
    global _POOL, _POOL_SIZE
    with _POOL_LOCK:
        if _POOL is None or _POOL_SIZE < workers:
            old = _POOL
            _POOL, _POOL_SIZE = ThreadPoolExecutor(workers, thread_name_prefix="zfloc-round", initializer=_mark_worker), workers
            if old is not None:
                old.shutdown(wait=False)  # its queued pieces still run; new ones go to the larger pool
        return _POOL


def _forget_pool() -> None:
    global _POOL, _POOL_SIZE
    _POOL, _POOL_SIZE = None, 0


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def run(fn: Callable[[T], R], pieces: Sequence[T]) -> list[R]:
    """[fn(p) for p in pieces], computed by up to current() threads (the caller's
    included), each taking the next piece not yet taken. An exception in a piece is
    raised here once every thread has stopped."""
    threads = min(current(), len(pieces))
    if threads <= 1:
        return [fn(p) for p in pieces]
    results: list = [None] * len(pieces)
    taken = itertools.count()  # next() on it is atomic: each piece is taken once

    def work() -> None:
        while (k := next(taken)) < len(pieces):
            results[k] = fn(pieces[k])

    pool = _pool(threads - 1)
    futures = [pool.submit(work) for _ in range(threads - 1)]
    was_worker = getattr(_IN_WORKER, "active", False)
    _IN_WORKER.active = True  # a piece run here does not ask the pool again
    try:
        work()
    finally:
        _IN_WORKER.active = was_worker
        for f in futures:  # no piece outlives the call, even when one failed
            f.exception()
    for f in futures:
        f.result()
    return results


def ranges(n: int, min_size: int = 1) -> list[tuple[int, int]]:
    """[start, stop) ranges covering range(n), one per thread of current() (fewer when a
    range would hold fewer than min_size items), in order."""
    parts = max(1, min(current(), n // max(1, min_size)))
    bounds = [n * k // parts for k in range(parts + 1)]
    return [(bounds[k], bounds[k + 1]) for k in range(parts)]
