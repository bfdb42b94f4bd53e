"""The benchmarks' harness (benchmarks/harness.py): every stage benchmark runs at its smallest
size (--quick) and writes valid JSON rows after the machine header; no file under
benchmarks/ reaches into tests/ (the inputs both use live once, in benchmarks/inputs/)."""

import ast
import importlib
import json
from pathlib import Path

import numpy as np
import pytest

from benchmarks import harness
from benchmarks.shared_data import SHARED_DATA

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"
# the stage benchmarks: bench_*.py, and profile_round (a round's stages on real data)
STAGE = sorted(p.stem for p in BENCHMARKS.glob("bench_*.py")) + ["profile_round"]
CARMEN = SHARED_DATA / "carmen"
NEEDS = {  # benchmark: (what it needs, whether it is there)
    "bench_scan_match": ("the shared Carmen logs", (CARMEN / "intel-corrected.log.gz").is_file()),
    "bench_scoring": ("the shared Carmen logs", (CARMEN / "aces-corrected.log.gz").is_file()),
    "profile_round": ("the shared Carmen logs", (CARMEN / "fhw-corrected.log.gz").is_file()),
}


def read_rows(path: Path) -> tuple[dict, list[dict]]:
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert lines and all(isinstance(x, dict) for x in lines)
    return lines[0], lines[1:]


def test_every_stage_benchmark_is_listed():
    assert len(STAGE) >= 15 and "bench_round" in STAGE and "bench_localize" in STAGE


@pytest.mark.parametrize("name", STAGE)
def test_stage_benchmark_quick_run_writes_json_rows(name, tmp_path, capsys, monkeypatch):
    needs, present = NEEDS.get(name, ("", True))
    if not present:
        pytest.skip(f"{name} needs {needs}")
    if name == "bench_backbones":
        pytest.importorskip("transformers")
    monkeypatch.chdir(ROOT)  # the benchmarks' child processes run `python -m benchmarks.…` from the root
    out = tmp_path / "rows.jsonl"
    module = importlib.import_module(f"benchmarks.{name}")
    assert module.main(["--quick", "--json", str(out)]) == 0
    header, rows = read_rows(out)
    assert header["benchmark"] == name.removeprefix("bench_")
    assert {"python", "numpy", "cpus", "commit", "date"} <= header["header"].keys()
    assert rows, f"{name} --quick wrote no rows"
    assert all(r["benchmark"] == header["benchmark"] and "table" in r for r in rows)
    printed = capsys.readouterr().out
    assert printed.count(f"numpy {header['header']['numpy']}") == 1  # the header, once
    assert "|---|" in printed  # a markdown table


def test_harness_table_and_json(tmp_path, capsys):
    import numpy as np

    bench = harness.Benchmark("demo", "a demo", seed=3, repeat=2, frames=[5, 6], workers=1, settings=True)
    args = bench.parse(["--json", str(tmp_path / "rows.jsonl"), "--repeats", "4", "--frames", "7", "8", "--set", "seed=1"])
    assert (args.seed, args.repeat, args.frames, args.workers, args.set, args.quick) == (3, 4, [7, 8], 1, ["seed=1"], False)
    table = bench.table(["case", ("ms", "time ms")], title="stage")
    table.add(case="x", ms=np.float64(12.345), extra=np.int64(2))
    table.add(case="y", ms=None)
    assert bench.done() == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[-6:] == ["### stage", "", "| case | time ms |", "|---|---|", "| x | 12.35 |", "| y |  |"]
    header, rows = read_rows(tmp_path / "rows.jsonl")
    assert header["argv"][-1] == "seed=1"
    assert rows == [{"benchmark": "demo", "table": "stage", "case": "x", "ms": 12.345, "extra": 2},
                    {"benchmark": "demo", "table": "stage", "case": "y", "ms": None}]


def test_cells_keep_three_significant_digits():
    assert [harness.cell(v) for v in (1234.5, 123.45, 12.345, 1.2345, 0.012345, 0.0, True, None, 7)] == [
        "1234", "123.5", "12.35", "1.234", "0.0123", "0", "yes", "", "7"]


def reaches_into_tests(folder: Path) -> list[str]:
    """Imports of a module of tests/ and sys.path edits in the Python files under folder."""
    test_modules = {p.stem for p in (ROOT / "tests").glob("*.py")} | {"tests", "conftest"}
    offenders = []
    for path in sorted(folder.rglob("*.py")):
        where = path.relative_to(folder)
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            offenders += [f"{where}:{node.lineno}: import {n}" for n in names if n.split(".")[0] in test_modules]
            if isinstance(node, ast.Attribute) and node.attr == "path" and getattr(node.value, "id", None) == "sys":
                offenders.append(f"{where}:{node.lineno}: sys.path")
    return offenders


def test_nothing_under_benchmarks_imports_tests():
    """No sys.path edit and no import of a module of tests/ anywhere under benchmarks/."""
    assert reaches_into_tests(BENCHMARKS) == []


def test_the_check_catches_an_import_from_tests(tmp_path):
    (tmp_path / "bench_bad.py").write_text("import sys\nsys.path.insert(0, 'tests')\nfrom session_helpers import fake_estimate\n")
    assert sorted(reaches_into_tests(tmp_path)) == ["bench_bad.py:2: sys.path", "bench_bad.py:3: import session_helpers"]


@pytest.mark.parametrize("argv, message", [
    (["--frames", "-5"], "argument --frames: must be at least 1, got -5"),
    (["--frames", "x"], "argument --frames: 'x' is not a whole number"),
    (["--json", "/nonexistent/dir/rows.json"], "--json /nonexistent/dir/rows.json: No such file or directory"),
    (["--set", "nosuch.key=1"], "unknown setting 'nosuch'"),
    (["--set", "bev.free_margin=0.2"], "'bev.free_margin' is no longer a setting"),
])
def test_bad_common_options_are_one_error_line_and_exit_2(argv, message, capsys):
    """The harness's options are checked before anything runs: no traceback, nothing written."""
    bench = harness.Benchmark("probe", "probe", frames=10, settings=True)
    with pytest.raises(SystemExit) as stop:
        bench.parse(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1] and "error:" in err[-1] and not any("Traceback" in line for line in err)


def _still_sensor(fp, truth, centre, radius, frames=31):
    """Wall hits and plane poses of a sensor standing at `centre` (floorplan frame) for
    `frames` frames, its odometry plane mapped onto the floorplan by `truth`."""
    from plan_helpers import observe

    hits = observe(fp, truth, np.asarray(centre, dtype=float), radius).wall_points
    x, y = truth.inverse().apply(np.asarray(centre, dtype=float))
    true_pose = np.array([*centre, 0.0])
    return [hits] * frames, [(x, y, -truth.theta)] * frames, np.tile(true_pose, (frames, 1))


def test_evidence_frames_asks_the_exact_search_whether_the_hits_tell_the_place():
    """eval_scenes --evidence: hits that fit one place of an asymmetric building tell it at
    once (5 frames); the same corridor stretch seen in a corridor twice its length, no end in
    sight, fits every shift along it: never within 30 frames."""
    from plan_helpers import building
    from zfloc_stream.geometry.sim2 import Sim2
    from zfloc_stream.plans.floorplan import Floorplan
    from benchmarks.evaluation.eval_scenes import evidence_frames

    fp, truth = building(), Sim2(1.0, 0.4, (3.0, -1.0))
    hits, plane, poses = _still_sensor(fp, truth, (10.5, 3.0), 4.0)
    assert evidence_frames(fp, hits, plane, poses, 0, 1.0) == 5

    res = 0.05
    occ = np.zeros((int(3 / res), int(60 / res)), dtype=bool)
    occ[:4], occ[-4:] = True, True  # two walls 60 m long, 2.6 m apart, no ends seen
    corridor = Floorplan.from_occupancy(occ, res, (0.0, 0.0))
    wall_points = np.array([(x, y) for x in np.arange(25.0, 35.0, 0.05) for y in (0.2, 2.8)])
    hits = [truth.inverse().apply(wall_points)] * 31
    x, y = truth.inverse().apply(np.array([30.0, 1.5]))
    plane, poses = [(x, y, -truth.theta)] * 31, np.tile([30.0, 1.5, 0.0], (31, 1))
    assert evidence_frames(corridor, hits, plane, poses, 0, 1.0) is None
