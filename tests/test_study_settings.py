"""Boundary tests of the study.* settings no other test names: study.eval_frames,
study.max_chunks_per_sequence, study.connect_timeout_s (the tiny Gibson(t) fixture)."""

import socket
import time
from pathlib import Path

import pytest

from zfloc_stream.errors import InputError
from zfloc_stream.settings.loading import load_settings
from zfloc_stream.study import plan_cells, run_study

GIBSON = f"gibson:{Path(__file__).resolve().parent / 'fixtures' / 'gibson'}"


def test_max_chunks_per_sequence_keeps_consecutive_chunks_up_to_it_then_spreads_them():
    """study.max_chunks_per_sequence: a 100-frame sequence holds five 20-frame chunks; a cap
    of 5 keeps them all, 4 spreads four along it (the first and the last kept)."""
    def starts(cap: int) -> list[int]:
        s = load_settings(overrides=["datasets.sim.n_frames=100", f"study.max_chunks_per_sequence={cap}"])
        return [c.start for c in plan_cells(["sim:rooms"], [20], [0], s)]

    assert starts(5) == [0, 20, 40, 60, 80]
    assert starts(4) == [0, 20, 60, 80]
    assert starts(1) == [0]


@pytest.mark.slow  # ~7 s: the fixture's floorplan is built once per process (4 s), two studies
def test_eval_frames_is_the_tail_a_run_is_judged_on(tmp_path):
    """study.eval_frames: the fixture's first 20-frame chunk has a pose from its 5th frame on
    (16 frames). Judged on the last 16 it succeeds; on the last 17 a frame without a pose
    makes it fail (rmse inf)."""
    rows = {}
    for n in (16, 17):
        out = run_study([GIBSON], [20], [0], tmp_path / str(n), workers=0, progress=False,
                        overrides={"study": {"eval_frames": n, "max_chunks_per_sequence": 1}})
        (rows[n],) = out.rows
    assert rows[16]["frames_with_pose"] == 16 and rows[16]["success_1m"] and rows[16]["rmse"] < 0.1
    assert rows[17]["frames_with_pose"] == 16 and not rows[17]["success_1m"] and rows[17]["rmse"] == float("inf")


def test_eval_frames_is_the_shortest_length_a_study_accepts(tmp_path):
    """study.eval_frames=10: chunks of 9 frames are refused before anything runs; of 10 they
    are planned (here none fits the 5-frame sequences, which is the next error)."""
    overrides = {"study": {"eval_frames": 10}, "datasets": {"sim": {"n_frames": 5}}}
    with pytest.raises(InputError, match="at least study.eval_frames = 10"):
        run_study(["sim:rooms"], [9], [0], tmp_path / "a", workers=0, progress=False, overrides=overrides)
    with pytest.raises(InputError, match="no chunk of 10 frames fits"):
        run_study(["sim:rooms"], [10], [0], tmp_path / "b", workers=0, progress=False, overrides=overrides)


def test_connect_timeout_s_is_how_long_a_missing_scheduler_is_waited_for(tmp_path):
    """study.connect_timeout_s: a scheduler address nobody listens on fails with one
    InputError after the timeout (not before it; 0.5 s and 1.5 s)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{s.getsockname()[1]}"  # free once closed
    for timeout in (0.5, 1.5):
        t0 = time.monotonic()
        with pytest.raises(InputError, match=f"cannot connect to dask scheduler {address}.*after {timeout:g} s"):
            run_study([GIBSON], [20], [0], tmp_path / str(timeout), scheduler=address, progress=False,
                      overrides={"study": {"connect_timeout_s": timeout}})
        assert time.monotonic() - t0 >= timeout
