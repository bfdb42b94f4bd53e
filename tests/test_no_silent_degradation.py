"""What used to degrade without a word (issue 29) is now refused, warned about or named:
a missing optional scoring backend, frames dropped by validation, integer depth of
unknown unit, a zeroed region of a session file, an undecodable message on a topic the
run does not need."""

from __future__ import annotations

import dataclasses
import sys

import numpy as np
import pytest
from benchmarks.inputs.session_frames import camera_frames, laser_frames
from session_helpers import record_laser_session, write_fake_session

from zfloc_stream.io import session as S_pkg
from zfloc_stream.settings.loading import load_settings
from zfloc_stream.errors import BackboneError, FrameError, SessionLogError
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.frames import CameraFrame
from zfloc_stream.stream.localizer import Localizer
from zfloc_stream.io.session import SessionWriter, read_session
from zfloc_stream.io.session import schemas as S

K = np.array([[20.0, 0, 4], [0, 20.0, 3], [0, 0, 1]])


def _plan():
    occ = np.zeros((40, 50), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    return Floorplan.from_occupancy(occ, 0.1, (0.0, 0.0), name="box")


# --- optional backends --------------------------------------------------------------------------
def test_torch_scoring_without_torch_is_refused_up_front(monkeypatch):
    """As estimator.kernels=numba without numba: one line at start, not a run without poses."""
    monkeypatch.setitem(sys.modules, "torch", None)  # import torch -> ImportError
    settings = load_settings(overrides=["estimator.scoring.backend=torch"])
    with pytest.raises(BackboneError, match=r"estimator.scoring.backend: torch needs the optional \[torch\] extra"):
        Localizer(_plan(), settings)


# --- depth units ----------------------------------------------------------------------------------
def test_integer_depth_must_be_declared_millimetres():
    mm = np.full((6, 8), 1500, np.uint16)
    with pytest.raises(FrameError, match="uint16: integer depth is millimetres.*depth_unit='mm'"):
        CameraFrame(mm, None, K, np.eye(4), 0.0)
    frame = CameraFrame(mm, None, K, np.eye(4), 0.0, depth_unit="mm")
    assert frame.depth.dtype == np.float32 and np.allclose(frame.depth, 1.5) and frame.depth_unit == "m"
    assert np.allclose(CameraFrame(mm.astype(np.int16), None, K, np.eye(4), 0.0, depth_unit="mm").depth, 1.5)


@pytest.mark.parametrize("depth", [np.ones((6, 8), bool), np.ones((6, 8), complex)])
def test_bool_and_complex_depth_are_refused(depth):
    with pytest.raises(FrameError, match="depth must be real numbers"):
        CameraFrame(depth, None, K, np.eye(4), 0.0)


def test_unknown_depth_unit_is_refused():
    with pytest.raises(FrameError, match="depth_unit must be one of m, mm"):
        CameraFrame(np.ones((6, 8)), None, K, np.eye(4), 0.0, depth_unit="cm")


# --- dropped frames are counted and warned about once per cause -----------------------------------
class _DamagingWriter(SessionWriter):
    """Writes the depth of some frames as all zeros (no valid reading: dropped on read) and
    the ground truth of others as bytes protobuf cannot decode."""

    zero_depth = {2, 3, 5}
    bad_truth = {6}

    def _write(self, topic, msg, ns, sequence, metadata=None):
        if topic == S.TOPIC_DEPTH and sequence in self.zero_depth:
            msg.data = bytes(len(msg.data))
        super()._write(topic, msg, ns, sequence, metadata)
        if topic == S.TOPIC_GROUND_TRUTH and sequence in self.bad_truth:
            self._batch[-1] = dataclasses.replace(self._batch[-1], data=b"\xff\xff\xff")


def _damaged_session(path):
    with _DamagingWriter(path, load_settings(), _plan(), metadata={"source": "test"}) as log:
        for i, frame in enumerate(camera_frames(10, seed=3, shape=(6, 8))):
            log.write_frame(i, frame)
    return path


def test_run_warns_once_per_cause_and_counts_dropped_frames(tmp_path, capsys):
    from zfloc_stream.tools.cli import main

    path = _damaged_session(tmp_path / "damaged.mcap")
    with pytest.warns(UserWarning) as caught:
        code = main(["run", "--input", str(path), "--out", str(tmp_path / "out"), "--no-progress"])
    assert code == 0
    messages = [str(w.message) for w in caught]
    dropped = [m for m in messages if "frame dropped: depth has no valid reading" in m]
    assert len(dropped) == 1 and "first at t=" in dropped[0], messages
    assert any("3 frame(s) dropped: depth has no valid reading (all zero or NaN) (3)" in m for m in messages), messages
    # the bad ground-truth message: skipped with a warning (localizing does not need it), not a refusal
    assert any("/groundtruth/pose message skipped: cannot be decoded" in m for m in messages), messages
    rows = (tmp_path / "out" / "trajectory.csv").read_text().splitlines()
    assert len(rows) - 1 == 7  # 10 frames, 3 dropped


def test_bad_message_on_a_needed_topic_still_refuses(tmp_path):
    class BadOdometry(SessionWriter):
        def _write(self, topic, msg, ns, sequence, metadata=None):
            super()._write(topic, msg, ns, sequence, metadata)
            if topic == S.TOPIC_ODOMETRY and sequence == 2:
                self._batch[-1] = dataclasses.replace(self._batch[-1], data=b"\xff\xff\xff")

    path = tmp_path / "badodom.mcap"
    with BadOdometry(path, load_settings(), _plan()) as log:
        for i, frame in enumerate(camera_frames(4, seed=3, shape=(6, 8))):
            log.write_frame(i, frame)
    with pytest.raises(SessionLogError, match="/odometry message at log time .* cannot be decoded"):
        list(read_session(path).frames())


# --- a zeroed region is damage, not empty records -------------------------------------------------
def _zero_chunks(data: bytes, start: int, stop: int) -> bytes:
    """Bytes start..stop overwritten with zeros (whole records, as a disk or a copy that
    lost a block leaves them); the remainder past the last whole 9 bytes becomes a
    private (0x80) record, so the reader stays in step after the region."""
    length = stop - start
    rest = length % 9
    zeros = length - (9 + rest if rest else 0)
    tail = (bytes([0x80]) + rest.to_bytes(8, "little") + bytes(rest)) if rest else b""
    return data[:start] + bytes(zeros) + tail + data[stop:]


@pytest.fixture(scope="module")
def zeroed_session(tmp_path_factory):
    from mcap.reader import make_reader

    d = tmp_path_factory.mktemp("zeroed")
    path = d / "zeroed.mcap"
    record_laser_session(path, n_frames=30)
    data = path.read_bytes()
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    chunks = sorted((c.chunk_start_offset, c.chunk_start_offset + c.chunk_length) for c in summary.chunk_indexes)
    path.write_bytes(_zero_chunks(data, chunks[18][0], chunks[20][1]))  # three chunks' worth (frames 18-20)
    return path


def test_zeroed_region_is_named_as_damage(zeroed_session):
    with pytest.raises(SessionLogError, match=r"damaged file: zeroed bytes at byte \d+.*--salvage"):
        list(read_session(zeroed_session).records())
    session = read_session(zeroed_session, salvage=True)
    frames = list(session.records())
    assert len(frames) < 30 and any(p.startswith("damaged file: zeroed bytes at bytes") for p in session.problems), session.problems


def test_replay_check_says_damaged_file_not_diverged(zeroed_session, capsys):
    from zfloc_stream.tools.replay_cli import main

    assert main([str(zeroed_session), "--check", "--no-progress"]) == 2
    assert "damaged file: zeroed bytes" in capsys.readouterr().err
    code = main([str(zeroed_session), "--check", "--salvage", "--no-progress"])
    out = capsys.readouterr()
    assert "DIVERGED" not in out.out, out.out
    assert code == 2 and "damaged file: damaged file: zeroed bytes" not in out.out and "damaged file:" in out.out, (code, out.out)


# --- crashed logs: run and export read them with --salvage ----------------------------------------
def test_run_and_export_read_a_cut_off_session_with_salvage(tmp_path, capsys):
    from zfloc_stream.tools.cli import main

    full = tmp_path / "full.mcap"
    write_fake_session(full, laser_frames(12, beams=90), load_settings(), floorplan=_plan())
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(full.read_bytes()[: int(full.stat().st_size * 0.5)])
    assert main(["export", str(cut), "--tum", str(tmp_path / "t.txt")]) == 2
    assert "salvage" in capsys.readouterr().err
    assert main(["export", str(cut), "--tum", str(tmp_path / "t.txt"), "--salvage"]) == 0
    poses = [line for line in (tmp_path / "t.txt").read_text().splitlines() if not line.startswith("#")]
    assert 0 < len(poses) < 11  # frame 0 has no pose; the cut loses the last frames
    assert main(["run", "--input", str(cut), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    capsys.readouterr()
    assert main(["run", "--input", str(cut), "--out", str(tmp_path / "o"), "--no-progress", "--salvage"]) == 0
    assert 1 < len((tmp_path / "o" / "trajectory.csv").read_text().splitlines()) <= 12


def test_drop_counter_warns_once_per_cause_and_sums_up():
    from zfloc_stream.io.drops import DropCounter

    drops = DropCounter("bag.mcap")
    with pytest.warns(UserWarning) as caught:
        for t in range(5):
            drops.note("depth contains inf", f"t={t}")
        drops.note_problem("t=7.000000000: frame dropped: no /odometry pose (gap)")
        drops.note_problem("repeated timestamps (first at t=1.0): frames kept in file order")  # loses nothing: no warning
        drops.summary()
    messages = [str(w.message) for w in caught]
    assert messages == [
        "bag.mcap: frame dropped: depth contains inf (first at t=0; further ones are counted)",
        "bag.mcap: frame dropped: no /odometry pose (gap) (first at t=7.000000000; further ones are counted)",
        "bag.mcap: 6 frame(s) dropped: depth contains inf (5); no /odometry pose (gap) (1)",
    ]
