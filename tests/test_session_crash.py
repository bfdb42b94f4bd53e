"""A recording process killed with SIGKILL leaves a file whose finished chunks read back."""

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from benchmarks.inputs.session_frames import camera_frames

from zfloc_stream.errors import SessionLogError
from zfloc_stream.io.session import read_session

CHUNK_FRAMES = 3
PENDING_BATCHES = 2  # background writer queue: one frame's inputs + outputs
KILL_AFTER = 11
# Frames handed to the writer but lost: the chunk in progress + what waits in the queue.
MAX_LOST = CHUNK_FRAMES + PENDING_BATCHES // 2

CHILD = textwrap.dedent(
    """
    import sys, time
    sys.path[:0] = [{tests!r}, {root!r}]  # session_helpers; benchmarks.inputs
    from benchmarks.inputs.session_frames import camera_frames
    from session_helpers import fake_estimate
    from zfloc_stream.settings.loading import load_settings
    from zfloc_stream.io.session import SessionWriter

    settings = load_settings(overrides=["logging.chunk_max_frames={chunk}", "logging.chunk_size=100000000",
                                        "logging.max_pending_batches={pending}"])
    log = SessionWriter({path!r}, settings, metadata={{"source": "crash-test"}})
    i = 0
    while True:  # runs until killed; never closes the file
        frame = camera_frames(1, seed=i, shape=(48, 64), t0=0.5 + 0.1 * i)[0]
        f = log.write_frame(i, frame)
        log.write_estimate(fake_estimate(i, f.timestamp))
        print(i, flush=True)
        i += 1
        time.sleep(0.01)
    """
)


@pytest.fixture(scope="module")
def killed_session(tmp_path_factory):
    path = tmp_path_factory.mktemp("crash") / "killed.mcap"
    code = CHILD.format(tests=str(Path(__file__).parent), root=str(Path(__file__).parents[1]), chunk=CHUNK_FRAMES, pending=PENDING_BATCHES, path=str(path))
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    written = -1
    try:
        for line in child.stdout:
            written = int(line)
            if written + 1 >= KILL_AFTER:
                break
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    assert written + 1 >= KILL_AFTER, child.stderr.read()
    return path, written + 1


def test_killed_file_is_refused_without_salvage(killed_session):
    path, _ = killed_session
    with pytest.raises(SessionLogError, match=r"killed\.mcap: file is truncated.*salvage"):
        read_session(path)


def test_salvage_reads_every_finished_chunk(killed_session):
    path, written = killed_session
    session = read_session(path, salvage=True)
    assert session.info["source"] == "crash-test" and session.settings.logging.chunk_max_frames == CHUNK_FRAMES
    records = list(session.records())
    assert len(records) >= written - MAX_LOST, (len(records), written, session.problems)
    for rec in records:  # the salvaged frames are the ones that were written, bit for bit
        want = camera_frames(1, seed=rec.index, shape=(48, 64), t0=0.5 + 0.1 * rec.index)[0]
        assert np.array_equal(rec.frame.depth, want.depth, equal_nan=True)
        assert np.array_equal(rec.frame.labels, want.labels)
        assert rec.outputs.estimate is not None and rec.outputs.estimate.frame == rec.index


ENGINE_CHILD = textwrap.dedent(
    """
    import sys
    from zfloc_stream.settings.loading import load_settings
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.sim.raycast2d import RangeSensor2D
    from zfloc_stream.runtime.rng import make_rng
    from zfloc_stream.io.session import SessionWriter
    from zfloc_stream.sim import build_scene
    from zfloc_stream.sim.trajectory import random_walk

    settings = load_settings(overrides=["logging.chunk_max_frames={chunk}", "logging.max_pending_batches={pending}"])
    scene = build_scene("rooms", 0)
    plan = scene.floorplan
    walk = random_walk(scene, make_rng(0, "walk"), 400)
    sensor = RangeSensor2D(n_beams=180, range_noise=0.01)
    localizer = Localizer(plan, settings)
    log = SessionWriter({path!r}, settings, plan)
    for i, p in enumerate(walk):
        frame = log.write_frame(i, sensor.frame(plan, p, p, 0.1 * i, make_rng(0, "scan", i)))
        log.write_estimate(localizer.push(frame), localizer)
        print(i, flush=True)
    """
)


def test_salvaged_engine_session_replays_identically(tmp_path, capsys):
    from zfloc_stream.tools.replay_cli import main

    path = tmp_path / "engine-killed.mcap"
    child = subprocess.Popen([sys.executable, "-c", ENGINE_CHILD.format(chunk=CHUNK_FRAMES, pending=PENDING_BATCHES, path=str(path))],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    written = 0
    try:
        for line in child.stdout:
            written = int(line) + 1
            if written >= 16:
                break
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    assert written >= 16, child.stderr.read()
    assert main([str(path), "--check"]) == 2
    assert "truncated" in capsys.readouterr().err
    assert main([str(path), "--salvage", "--check"]) == 0
    captured = capsys.readouterr()
    checked = int(captured.out.split("identical: ")[1].split()[0])
    assert checked >= written - MAX_LOST, captured
    assert "note: reading stopped: file is truncated" in captured.err


@pytest.mark.parametrize("background", ["true", "false"])
def test_default_chunking_loses_no_finished_frame(tmp_path, background):
    """With the default chunk_max_frames (1) a frame's chunk closes right after its
    estimate: a kill loses no finished frame, only one still queued for the background
    writer (at most max_pending_batches / 2 frames; none when writing inline)."""
    path = tmp_path / f"default-{background}.mcap"
    code = CHILD.format(tests=str(Path(__file__).parent), root=str(Path(__file__).parents[1]), chunk=1, pending=PENDING_BATCHES, path=str(path))
    code = code.replace('"logging.chunk_size=100000000",', f'"logging.chunk_size=100000000", "logging.background={background}",')
    child = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    written = -1
    try:
        for line in child.stdout:
            written = int(line)
            if written + 1 >= 7:
                break
    finally:
        os.kill(child.pid, signal.SIGKILL)
        child.wait()
    session = read_session(path, salvage=True)
    recovered = len(list(session.records()))
    queued = PENDING_BATCHES // 2 if background == "true" else 0
    assert recovered >= written + 1 - queued, (recovered, written + 1)


def test_sigterm_closes_the_session_like_ctrl_c(tmp_path):
    """SIGTERM (service managers, containers): the session file gets its footer, every
    frame in it reads without --salvage, one line says how the run ended, exit 143."""
    out = tmp_path / "run"
    child = subprocess.Popen([sys.executable, "-m", "zfloc_stream.tools.cli", "demo", "--scene", "rooms", "--frames", "400",
                              "--out", str(out), "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    csv = out / "trajectory.csv"
    try:
        for _ in range(6000):
            if csv.is_file() and len(csv.read_text().splitlines()) > 6:
                break
            assert child.poll() is None, child.stderr.read()
            time.sleep(0.05)
        child.send_signal(signal.SIGTERM)
        _, err = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
    assert child.returncode == 143 and err.strip().splitlines() == [
        "zfloc-stream: terminated (SIGTERM): outputs written so far were closed; exit 143"], err
    rows = len(csv.read_text().splitlines()) - 1
    records = list(read_session(out / "session.mcap").records())  # strict: the footer is there
    assert rows >= 6 and len(records) >= rows and records[-1].index == len(records) - 1
