"""Damaged session files never end in a traceback: every fault is a SessionLogError that
names the file (or the damage changed only values and the file still reads)."""

import numpy as np
import pytest
from benchmarks.inputs.session_frames import camera_frames, laser_frames
from session_helpers import write_fake_session

from zfloc_stream.settings.loading import load_settings
from zfloc_stream.errors import SessionLogError
from zfloc_stream.plans.floorplan import Floorplan
from zfloc_stream.io.session import read_session

N_CASES = 520


def _read_everything(path, salvage: bool, with_floorplan: bool) -> int:
    session = read_session(path, salvage=salvage)
    n = 0
    for rec in session.records():
        _ = rec.outputs.estimate, rec.outputs.bev_grid
        n += 1
    if with_floorplan:
        _ = session.floorplan
    return n


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    occ = np.zeros((12, 16), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    plan = Floorplan.from_occupancy(occ, 0.1, (0.0, 0.0), name="tiny")
    settings = load_settings(overrides=["logging.chunk_max_frames=2", "logging.compression=zstd"])
    path = tmp_path_factory.mktemp("fuzz") / "small.mcap"
    write_fake_session(path, camera_frames(4, seed=9, shape=(6, 8)), settings, floorplan=plan)
    return path.read_bytes()


def _mutate(data: bytes, rng: np.random.Generator) -> bytes:
    buf = bytearray(data)
    kind = rng.integers(3)
    if kind in (0, 2):  # byte flips
        for pos in rng.integers(0, len(buf), size=rng.integers(1, 4)):
            buf[pos] ^= int(rng.integers(1, 256))
    if kind in (1, 2):  # truncation
        buf = buf[: int(rng.integers(0, len(buf)))]
    return bytes(buf)


def test_random_flips_and_truncations_fail_cleanly(original, tmp_path):
    rng = np.random.default_rng(20240601)
    path = tmp_path / "damaged.mcap"
    outcomes = {"read": 0, "error": 0}
    for case in range(N_CASES):
        path.write_bytes(_mutate(original, rng))
        salvage = case % 2 == 1
        try:
            _read_everything(path, salvage, with_floorplan=case % 10 == 0)
            outcomes["read"] += 1
        except SessionLogError as err:
            msg = str(err)
            assert str(path) in msg, f"case {case}: error does not name the file: {msg}"
            assert "\n" not in msg.strip() and len(msg) > len(str(path)) + 5, f"case {case}: {msg!r}"
            outcomes["error"] += 1
    # both outcomes must occur, or the test is not exercising the damage paths
    assert outcomes["read"] > 20 and outcomes["error"] > 100, outcomes


def test_every_truncation_point_salvages_a_prefix(original, tmp_path):
    """Cutting the file anywhere: a strict read refuses (file named), a salvage read
    returns a prefix of the frames, growing with the cut."""
    path = tmp_path / "cut.mcap"
    full = _read_everything_bytes(original, tmp_path / "full.mcap")
    counts = []
    for cut in range(0, len(original) - 1, max(1, len(original) // 60)):
        path.write_bytes(original[:cut])
        with pytest.raises(SessionLogError, match="cut.mcap"):
            _read_everything(path, salvage=False, with_floorplan=False)
        try:
            counts.append(_read_everything(path, salvage=True, with_floorplan=False))
        except SessionLogError as err:
            assert "cut.mcap" in str(err)
            counts.append(0)
    assert counts == sorted(counts) and counts[-1] >= full - 2 and counts[0] == 0


def _read_everything_bytes(data: bytes, path) -> int:
    path.write_bytes(data)
    return _read_everything(path, salvage=False, with_floorplan=True)


def test_laser_session_flips(tmp_path):
    path = tmp_path / "laser.mcap"
    write_fake_session(path, laser_frames(3, beams=20), load_settings(overrides=["logging.compression=none"]))
    data = path.read_bytes()
    rng = np.random.default_rng(5)
    for _ in range(60):  # uncompressed chunks: flips land in message fields, not only zstd frames
        path.write_bytes(_mutate(data, rng))
        try:
            _read_everything(path, salvage=False, with_floorplan=False)
        except SessionLogError as err:
            assert str(path) in str(err)


# --- issue 44 families: valid-but-odd and hostile sessions (benchmarks/inputs/hostile_sessions.py) --
def _read_hostile(path, salvage: bool) -> int:
    session = read_session(path, salvage=salvage)
    n = sum(1 for _ in session.records())
    if not salvage:
        index = session.frame_index()
        assert index is None or len(index) == n, (len(index), n)
    return n


def _hostile_cases(n_cases: int, seed: int, tmp_path) -> dict:
    import warnings

    from benchmarks.inputs.hostile_sessions import hostile_session

    rng = np.random.default_rng(seed)
    path = tmp_path / "hostile.mcap"
    outcomes = {"read": 0, "error": 0, "frames": 0}
    for case in range(n_cases):
        what = hostile_session(rng, path)
        for salvage in (False, True):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("error", RuntimeWarning)  # no numpy overflow on the way either
                    outcomes["frames"] += _read_hostile(path, salvage)
                outcomes["read"] += 1
            except SessionLogError as err:
                msg = str(err)
                assert str(path) in msg and "\n" not in msg.strip(), f"case {case} ({what}): {msg!r}"
                outcomes["error"] += 1
            except Exception as err:  # noqa: BLE001 - the point of the test
                raise AssertionError(f"case {case} ({what}), salvage={salvage}: {type(err).__name__}: {err}") from err
    return outcomes


def test_hostile_session_families_read_or_fail_in_one_line(tmp_path):
    """Fast subset (CI): 60 seeded sessions of the issue-44 families, read strictly and salvaged."""
    outcomes = _hostile_cases(60, 4401, tmp_path)
    assert outcomes["read"] > 30 and outcomes["error"] > 5 and outcomes["frames"] > 100, outcomes


@pytest.mark.slow
def test_hostile_session_families_1000(tmp_path):
    """>= 1,000 inputs, 0 tracebacks; peak RSS printed (pytest -s)."""
    import resource

    outcomes = _hostile_cases(1000, 4402, tmp_path)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"hostile sessions: {outcomes}, peak RSS {peak_mib:.0f} MiB")
    assert outcomes["read"] > 500 and outcomes["error"] > 50, outcomes
