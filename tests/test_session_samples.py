"""Every sample session in replay/ replays with the same decisions and its numbers within
the tolerance (zfloc-replay --check): the samples were recorded on another machine, whose
CPU and BLAS may change the last bits. (Bit-for-bit replays are tested on sessions this
machine records: test_session_replay.py.)

A failure means the engine's decisions or numbers changed: if intended, regenerate the
samples with `.venv/bin/python replay/record_samples.py` (see replay/README.md)."""

from pathlib import Path

import pytest

from zfloc_stream.io.session import read_session
from zfloc_stream.tools.replay_cli import main

SAMPLES = sorted((Path(__file__).resolve().parents[1] / "replay").glob("*.mcap"))


def test_samples_are_there_and_small():
    assert {p.name for p in SAMPLES} >= {"apartment-camera.mcap", "symmetric-camera-small.mcap", "office-laser.mcap"}
    assert sum(p.stat().st_size for p in SAMPLES) < 5e6


@pytest.mark.parametrize("path", SAMPLES, ids=[p.stem for p in SAMPLES])
def test_sample_replays_identically(path, capsys):
    session = read_session(path)
    assert session.info.get("recorded_by") == "replay/record_samples.py" and session.floorplan is not None
    code = main([str(path), "--check", "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0, f"{path.name} diverged (regenerate with replay/record_samples.py if intended): {out}"
    assert f"{session.info['frames']} frames checked" in out and "largest deviation per topic:" in out
