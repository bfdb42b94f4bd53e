"""A recording process killed with SIGKILL leaves a file whose finished chunks read back."""

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from session_helpers import camera_frames

from zfloc_stream.errors import SessionLogError
from zfloc_stream.session import read_session

CHUNK_FRAMES = 3
KILL_AFTER = 11

CHILD = textwrap.dedent(
    """
    import sys, time
    sys.path.insert(0, {tests!r})
    from session_helpers import camera_frames, fake_estimate
    from zfloc_stream.config import load_settings
    from zfloc_stream.session import SessionWriter

    settings = load_settings(overrides=["logging.chunk_max_frames={chunk}", "logging.chunk_size=100000000"])
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
    code = CHILD.format(tests=str(Path(__file__).parent), chunk=CHUNK_FRAMES, path=str(path))
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
    assert len(records) >= written - CHUNK_FRAMES, (len(records), written, session.problems)
    for rec in records:  # the salvaged frames are the ones that were written, bit for bit
        want = camera_frames(1, seed=rec.index, shape=(48, 64), t0=0.5 + 0.1 * rec.index)[0]
        assert np.array_equal(rec.frame.depth, want.depth, equal_nan=True)
        assert np.array_equal(rec.frame.labels, want.labels)
        assert rec.outputs.estimate is not None and rec.outputs.estimate.frame == rec.index
