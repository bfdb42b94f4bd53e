"""CLI contract: bad input ends with one clear line on stderr and exit code 2."""

import subprocess
import sys

import pytest

from benchmarks.shared_data import SHARED_DATA

from zfloc_stream.tools.cli import main

SHARED = SHARED_DATA.parent


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "zfloc_stream.tools.cli", *args], capture_output=True, text=True, timeout=120)


def _assert_clean_failure(proc, fragment):
    assert proc.returncode == 2, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert "Traceback" not in proc.stderr
    assert fragment in proc.stderr
    assert len(lines) <= 3  # argparse prints usage + one error line; ours prints one line


def test_missing_floorplan(tmp_path):
    proc = run_cli("run", "--floorplan", str(tmp_path / "nope.yaml"), "--input", str(tmp_path / "in.mcap"), "--out", str(tmp_path))
    _assert_clean_failure(proc, "nope.yaml")


def test_unreadable_input(tmp_path):
    plan = tmp_path / "plan"
    from zfloc_stream.sim import build_scene

    yaml_path = build_scene("rooms", seed=0).floorplan.write_ros(plan, "map")
    garbage = tmp_path / "garbage.bin"
    garbage.write_bytes(b"\x00\x01not a session")
    proc = run_cli("run", "--floorplan", str(yaml_path), "--input", str(garbage), "--out", str(tmp_path / "o"))
    _assert_clean_failure(proc, "garbage.bin")


def test_unknown_scene(tmp_path):
    proc = run_cli("demo", "--scene", "castle", "--out", str(tmp_path), "--no-progress")
    _assert_clean_failure(proc, "castle")


def test_bad_config_key(tmp_path):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("estimator:\n  ransac:\n    iterationz: 3\n")
    proc = run_cli("demo", "--config", str(cfg), "--out", str(tmp_path), "--no-progress")
    _assert_clean_failure(proc, "iterationz")
    proc = run_cli("demo", "--set", "bev.nonsense=1", "--out", str(tmp_path), "--no-progress")
    _assert_clean_failure(proc, "bev.nonsense")


def test_help_everywhere():
    for args in (["--help"], ["demo", "--help"], ["run", "--help"], ["map-from-log", "--help"], ["config", "--help"]):
        with pytest.raises(SystemExit) as exit_info:
            main(args)
        assert exit_info.value.code == 0


def test_short_demo_writes_its_files(tmp_path):
    out = tmp_path / "demo"
    proc = run_cli("demo", "--scene", "rooms", "--frames", "12", "--out", str(out), "--no-progress")
    assert proc.returncode == 0, proc.stderr
    for name in ("trajectory.csv", "overlay.png", "session.mcap"):
        assert (out / name).stat().st_size > 0
    rows = (out / "trajectory.csv").read_text().splitlines()
    assert rows[0] == "frame,timestamp,x,y,theta,scale,score,n_hypotheses,status,confidence"
    assert len(rows) == 13
    assert "final status" in proc.stdout
