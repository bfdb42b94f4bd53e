"""heap.release_free_heap: free heap pages glibc keeps go back to the OS once resident
memory has grown by the asked amount; rounds call it."""

import ctypes
import os

import pytest

from zfloc_stream.runtime import heap
from zfloc_stream.stream import localizer as localizer_module
from zfloc_stream.stream import scheduler as round_scheduler
from zfloc_stream.settings.loading import load_settings
from zfloc_stream.runtime.heap import _malloc_trim, release_free_heap
from zfloc_stream.sim import build_scene
from zfloc_stream.sim.simulator import SimSettings, simulate


def _rss_mib() -> float:
    return heap.resident_bytes() / 2**20


@pytest.mark.skipif(not os.path.exists("/proc/self/statm") or _malloc_trim() is None, reason="needs Linux with glibc")
def test_free_heap_pages_are_returned():
    libc = ctypes.CDLL(None)
    libc.malloc.restype, libc.malloc.argtypes = ctypes.c_void_p, [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    # 100 KiB blocks (below glibc's mmap threshold: on the heap); freeing every other one
    # leaves free chunks between kept ones, inside the heap, which glibc does not give
    # back by itself
    blocks = []
    for _ in range(640):
        p = libc.malloc(100 * 1024)
        ctypes.memset(p, 1, 100 * 1024)
        blocks.append(p)
    for p in blocks[::2]:
        libc.free(p)
    kept = _rss_mib()
    assert release_free_heap()
    returned = kept - _rss_mib()
    for p in blocks[1::2]:
        libc.free(p)
    assert returned > 20, f"only {returned:.1f} MiB of the 31 MiB freed went back"


@pytest.mark.skipif(heap._malloc_trim() is None, reason="needs glibc")
def test_a_release_waits_until_resident_memory_grew_by_the_asked_amount(monkeypatch):
    resident = [100 * 2**20]
    trims = []
    monkeypatch.setattr(heap, "resident_bytes", lambda: resident[0])
    monkeypatch.setattr(heap, "_malloc_trim", lambda: trims.append)
    monkeypatch.setattr(heap, "_resident_after_trim", None)
    growth = 32 * 2**20
    assert heap.release_free_heap(growth)  # nothing recorded yet: trims, and records 100 MiB
    resident[0] += growth - 1
    assert not heap.release_free_heap(growth)
    assert heap.release_free_heap(0)  # 0: always
    resident[0] += growth  # 32 MiB above the last trim
    assert heap.release_free_heap(growth)
    assert not heap.release_free_heap(growth)
    monkeypatch.setattr(heap, "resident_bytes", lambda: None)  # no /proc: trims every time
    assert heap.release_free_heap(growth)
    assert len(trims) == 4


@pytest.mark.parametrize("release", [True, False])
def test_every_round_releases_the_heap_unless_told_not_to(monkeypatch, release):
    calls = []
    monkeypatch.setattr(round_scheduler, "release_free_heap", lambda growth: calls.append(growth) or True)
    scene = build_scene("rooms", seed=0)
    settings = load_settings(overrides=[f"localizer.release_memory={str(release).lower()}", "localizer.pipeline=inline"])
    loc = localizer_module.Localizer(scene.floorplan, settings)
    rounds = sum("primitives" in loc.push(f).timings for f in simulate(scene, SimSettings(), seed=0, n_frames=12))
    assert rounds >= 2
    assert calls == ([settings.localizer.release_memory_growth * 2**20] * rounds if release else [])


@pytest.mark.skipif(heap._malloc_trim() is None, reason="needs glibc")
def test_malloc_arenas_are_capped_when_rounds_are_scheduled(monkeypatch):
    asked = []
    monkeypatch.setattr(round_scheduler, "limit_arenas", lambda count: asked.append(count) or True)
    scene = build_scene("rooms", seed=0)
    for count in (2, 0):
        settings = load_settings(overrides=[f"localizer.malloc_arenas={count}"])
        localizer_module.Localizer(scene.floorplan, settings).close()
    assert asked == [2, 0]
    assert heap.limit_arenas(2)  # glibc takes the cap
    assert not heap.limit_arenas(0)  # 0: glibc's own choice, nothing set
