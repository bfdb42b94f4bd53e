"""Using the Localizer out of order (issue 44): a push after close(), two threads pushing
at once, the caller reusing a frame's buffers after push. Each is a clear exception
(errors.UsageError) or a documented safe behaviour (the localizer copies what it keeps)."""

import threading
from dataclasses import replace

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.errors import UsageError, ZflocError
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.sim import SimSettings, build_scene, simulate


@pytest.fixture(scope="module")
def walk():
    scene = build_scene("apartment", seed=2)
    return scene, list(simulate(scene, SimSettings(), seed=2, n_frames=20))


def test_push_after_close_is_a_usage_error_and_starts_no_worker(walk):
    """Issue 44: a push after close() answered `tracking` and started a round worker that
    was never stopped."""
    scene, frames = walk
    loc = Localizer(scene.floorplan, Settings())
    for f in frames[:12]:
        loc.push(f)
    assert loc.rounds._pool is not None  # the round worker ran (online pipeline)
    loc.close()
    loc.close()  # twice is harmless
    alive = set(threading.enumerate())  # the process-wide helper threads (threads.py) stay: shared
    with pytest.raises(UsageError, match="after close"):
        loc.push(frames[12])
    assert issubclass(UsageError, ZflocError)
    with pytest.raises(UsageError, match="closed"):
        with loc:
            pass
    assert loc.rounds._pool is None and set(threading.enumerate()) == alive  # no worker started again


def test_two_threads_pushing_at_once_is_a_usage_error(walk, monkeypatch):
    """Issue 44: two threads pushing into one localizer gave a raw numpy IndexError. A push
    that starts while another is running raises UsageError at once; the running push is
    untouched and the stream goes on."""
    scene, frames = walk
    loc = Localizer(scene.floorplan, Settings())
    for f in frames[:5]:
        loc.push(f)
    inside, release = threading.Event(), threading.Event()
    add = loc.bev.add

    def slow_add(frame):  # holds the first push inside the localizer
        inside.set()
        assert release.wait(30)
        add(frame)

    monkeypatch.setattr(loc.bev, "add", slow_add)
    first = {}
    worker = threading.Thread(target=lambda: first.setdefault("est", loc.push(frames[5])))
    worker.start()
    assert inside.wait(30)
    with pytest.raises(UsageError, match="another thread"):
        loc.push(frames[6])
    release.set()
    worker.join(30)
    monkeypatch.setattr(loc.bev, "add", add)
    assert first["est"].frame == 5 and loc.frames_pushed == 6  # the refused push counted no frame
    assert loc.push(frames[6]).frame == 6
    loc.close()


def test_reusing_the_callers_buffers_after_push_changes_nothing(walk):
    """Issue 44: the localizer kept the caller's depth array (frames wait for gravity), so
    a caller refilling one buffer for every frame moved the poses by up to 6 cm. What the
    localizer keeps it copies: the same estimates as with a fresh array per frame."""
    scene, frames = walk
    fresh = Localizer(scene.floorplan, Settings())
    expected = [fresh.push(f) for f in frames]
    fresh.close()
    depth = np.empty_like(frames[0].depth)
    labels = np.empty_like(frames[0].labels)
    pose = np.empty((4, 4))
    reused = Localizer(scene.floorplan, Settings())
    got = []
    for f in frames:
        depth[...], labels[...], pose[...] = f.depth, f.labels, f.T_odom_cam
        got.append(reused.push(replace(f, depth=depth, labels=labels, T_odom_cam=pose)))
        depth[...] = 7.0  # the caller reuses its buffers at once
        labels[...] = 0
        pose[:3, 3] += 0.5
    reused.close()
    assert [e.status for e in got] == [e.status for e in expected]
    for a, b in zip(got, expected):
        assert (a.pose is None) == (b.pose is None)
        if a.pose is not None:
            assert np.array_equal(a.pose, b.pose)
