"""What held in earlier rounds of hostile inputs stays held (issue 44): a run stopped by
SIGINT, SIGTERM or SIGKILL loses no finished frame; resident memory stays flat over a long
stream; no YAML tag executes code (settings overrides, config files, map YAMLs, a
session's settings). Fast versions here; the long ones (30 trials per signal, 5,455
frames) are marked slow. benchmarks/bench_signals.py and bench_localizer.py measure the
same at length."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from zfloc_stream.io.session import read_session

DEMO = [sys.executable, "-m", "zfloc_stream.tools.cli", "demo", "--scene", "rooms", "--frames", "3000", "--no-progress"]  # never done before the signal


def _ctrl_c_as_in_a_terminal() -> None:
    """In the child before exec: SIGINT at its default, so that Python turns it into
    KeyboardInterrupt. A child inherits an ignored SIGINT, and a shell ignores it in its
    background jobs: the suite run as one (`... &` or under nohup) saw Ctrl-C have no effect
    on the demo, which ran to its end and exited 0."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _stopped_demo(out: Path, sig: int, after_rows: int) -> tuple[int, str, int, int]:
    """`zfloc-stream demo` stopped by `sig` once trajectory.csv has after_rows rows:
    (exit code, stderr, rows finished, frames in session.mcap). A SIGKILLed file is read
    with salvage, the others strictly (their footer must be there)."""
    child = subprocess.Popen(DEMO + ["--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=_ctrl_c_as_in_a_terminal)
    csv = out / "trajectory.csv"
    try:
        for _ in range(6000):
            if csv.is_file() and len(csv.read_text().splitlines()) > after_rows:
                break
            assert child.poll() is None, child.stderr.read()
            time.sleep(0.02)
        child.send_signal(sig)
        _, err = child.communicate(timeout=120)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    rows = len(csv.read_text().splitlines()) - 1
    records = list(read_session(out / "session.mcap", salvage=sig == signal.SIGKILL).records())
    return child.returncode, err, rows, len(records)


def test_sigint_closes_the_session_and_loses_no_frame(tmp_path):
    """Ctrl-C: the session file gets its footer, every finished frame is in it, one line
    says how the run ended, exit 130."""
    code, err, rows, frames = _stopped_demo(tmp_path / "run", signal.SIGINT, 6)
    assert code == 130 and err.strip().splitlines() == [
        "zfloc-stream: interrupted: outputs written so far were closed; exit 130"], err
    assert rows >= 6 and frames >= rows


def _raised_from(cause: BaseException) -> SystemError:
    """A SystemError chained to `cause`, as compiled code reports an exception raised in a
    Python callback (numba loading a kernel from its cache when Ctrl-C lands)."""
    try:
        try:
            raise cause
        except BaseException as inner:
            raise SystemError("returned a result with an exception set") from inner
    except SystemError as outer:
        return outer


def test_an_interrupt_inside_compiled_code_ends_as_ctrl_c_does(monkeypatch, capsys):
    """interruption_in finds the interrupt behind the SystemError (SIGTERM's too) and the
    CLI ends with its one line and exit 130 / 143; any other SystemError stays an error."""
    from zfloc_stream.tools import cli
    from zfloc_stream.tools.signals import Terminated, interruption_in

    assert isinstance(interruption_in(_raised_from(KeyboardInterrupt())), KeyboardInterrupt)
    assert isinstance(interruption_in(_raised_from(Terminated())), Terminated)
    assert interruption_in(_raised_from(ValueError())) is None and interruption_in(None) is None
    for cause, code, line in ((KeyboardInterrupt(), 130, "interrupted"), (Terminated(), 143, "terminated (SIGTERM)")):
        def stopped(args, cause=cause):
            raise _raised_from(cause)
        monkeypatch.setattr(cli, "cmd_demo", stopped)
        assert cli.main(["demo"]) == code
        assert capsys.readouterr().err.strip().splitlines() == [
            f"zfloc-stream: {line}: outputs written so far were closed; exit {code}"]
    monkeypatch.setattr(cli, "cmd_demo", lambda args: (_ for _ in ()).throw(_raised_from(ValueError())))
    with pytest.raises(SystemError):
        cli.main(["demo"])


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGKILL], ids=["SIGINT", "SIGTERM", "SIGKILL"])
def test_thirty_stops_lose_no_finished_frame(tmp_path, sig):
    """30 runs per signal, each stopped after a seeded random number of finished frames:
    every frame trajectory.csv shows finished is in session.mcap."""
    trials = int(os.environ.get("ZFLOC_SIGNAL_TRIALS", "30"))
    rng = np.random.default_rng(44)
    for trial in range(trials):
        code, err, rows, frames = _stopped_demo(tmp_path / f"run{trial}", sig, int(rng.integers(1, 40)))
        assert code == {signal.SIGINT: 130, signal.SIGTERM: 143, signal.SIGKILL: -signal.SIGKILL}[sig], err
        assert frames >= rows, (trial, rows, frames)


def _rss_growth(n_frames: int, warm_up: int) -> float:
    """MiB the process's resident memory grew from frame warm_up to frame n_frames of one
    laser stream (a walk back and forth through the office, pushed frame by frame)."""
    from dataclasses import replace

    from zfloc_stream.runtime import heap
    from zfloc_stream.settings.loading import Settings
    from zfloc_stream.stream.localizer import Localizer
    from zfloc_stream.sim import LaserSimSettings, build_scene, simulate_laser

    scene = build_scene("office", seed=1)
    walk = list(simulate_laser(scene, LaserSimSettings(), seed=1, n_frames=200).frames)
    there_and_back = walk + walk[::-1]
    resident = {}
    with Localizer(scene.floorplan, Settings()) as loc:
        for k in range(n_frames):
            f = there_and_back[k % len(there_and_back)]
            loc.push(replace(f, timestamp=0.1 * k))
            if k + 1 in (warm_up, n_frames):
                resident[k + 1] = heap.resident_bytes() / 2**20
    return resident[n_frames] - resident[warm_up]


def test_resident_memory_stays_flat_over_a_stream():
    """600 frames after 200 of warm-up: a leak of a few kB per frame shows. Frames that
    walk back and forth rebuild the same map, so nothing should accumulate."""
    assert _rss_growth(800, 200) < 32.0


@pytest.mark.slow
def test_resident_memory_stays_flat_over_5455_frames():
    """Issue 44's length (measured +17 MB): under 64 MiB after 500 frames of warm-up."""
    assert _rss_growth(5455, 500) < 64.0


TAGS = ["!!python/object/apply:os.system ['touch {marker}']", "!!python/name:os.system",
        "!!python/object/new:os.system ['touch {marker}']", "!!python/module:os"]


@pytest.mark.parametrize("tag", TAGS)
def test_no_yaml_tag_executes_code(tmp_path, tag):
    """A python tag in an override (--set), a config file (--config), a map YAML or a
    session's settings is refused with one error, and its code never runs."""
    import yaml

    from zfloc_stream.settings.loading import load_settings
    from zfloc_stream.settings.documents import load_yaml
    from zfloc_stream.errors import ConfigError, FloorplanError, ZflocError
    from zfloc_stream.plans.floorplan import Floorplan
    from zfloc_stream.io.session.reader import _YAML_LOADER

    marker = tmp_path / "ran"
    value = tag.format(marker=marker)
    with pytest.raises(ConfigError):
        load_settings(overrides=[f"seed={value}"])
    config = tmp_path / "config.yaml"
    config.write_text(f"seed: {value}\n")
    with pytest.raises(ConfigError):
        load_settings(config)
    map_yaml = tmp_path / "map.yaml"
    map_yaml.write_text(f"image: {value}\nresolution: 0.05\norigin: [0, 0, 0]\n")
    with pytest.raises(FloorplanError):
        Floorplan.load(map_yaml)
    for load in (load_yaml, lambda text: yaml.load(text, Loader=_YAML_LOADER)):
        with pytest.raises((yaml.YAMLError, ZflocError)):
            load(f"seed: {value}\n")
    assert not marker.exists()
