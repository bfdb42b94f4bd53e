"""zfloc-study: chunking, identical results however it runs, resuming, failure reporting,
outputs and CLI errors. Uses the tiny Gibson(t) fixture (fast chunks)."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from zfloc_stream.settings.loading import Settings
from zfloc_stream.io.datasets.base import Sequence, register
from zfloc_stream.errors import InputError
from zfloc_stream.study import CELLS_FILE, chunk_starts, plan_cells, run_study
from zfloc_stream.tools.study_cli import main

GIBSON = f"gibson:{Path(__file__).resolve().parent / 'fixtures' / 'gibson'}"


def _metrics(rows):
    """Everything but wall time."""
    return [{k: v for k, v in r.items() if k != "seconds"} for r in rows]


def test_chunks_are_consecutive_non_overlapping_and_capped():
    assert chunk_starts(100, 15, 20) == [0, 15, 30, 45, 60, 75]
    assert chunk_starts(14, 15, 20) == []
    capped = chunk_starts(1000, 10, 5)
    assert len(capped) == 5 and capped[0] == 0 and capped[-1] == 990  # spread along the sequence
    assert all(b - a >= 10 for a, b in zip(capped, capped[1:]))
    cells = plan_cells([GIBSON], [15, 20], [0, 1], Settings())
    assert len(cells) == (2 + 2) * 2
    assert {(c.start, c.stop) for c in cells if c.length == 15} == {(0, 15), (15, 30)}


def test_same_results_in_process_with_one_worker_and_with_two_worker_processes(tmp_path):
    kwargs = dict(datasets=[GIBSON], lengths=[20], seeds=[0, 1], progress=False)
    serial = run_study(out_dir=tmp_path / "w0", workers=0, **kwargs)
    one = run_study(out_dir=tmp_path / "w1", workers=1, processes=False, **kwargs)  # a thread worker
    two = run_study(out_dir=tmp_path / "w2", workers=2, **kwargs)  # two worker processes
    assert len(serial.rows) == 4 and not any(r["error"] for r in serial.rows)
    assert _metrics(serial.rows) == _metrics(one.rows) == _metrics(two.rows)
    assert serial.summary == one.summary == two.summary
    # the fixture is easy: most chunks localize
    assert sum(r["success_1m"] for r in serial.rows) >= 2
    # results.csv is identical apart from the timing column
    def table(d):
        with open(d / "results.csv") as f:
            return [{k: v for k, v in r.items() if k != "seconds"} for r in csv.DictReader(f)]
    assert table(tmp_path / "w0") == table(tmp_path / "w2")


def test_resume_skips_finished_cells(tmp_path):
    kwargs = dict(datasets=[GIBSON], lengths=[15], seeds=[0, 1], out_dir=tmp_path, workers=0, progress=False)
    first = run_study(**kwargs)
    assert first.ran == 4 and first.skipped == 0
    second = run_study(**kwargs)
    assert second.ran == 0 and second.skipped == 4
    assert _metrics(second.rows) == _metrics(first.rows)
    # a study cut off mid-way (last line lost, a torn line written) re-runs only that cell
    lines = (tmp_path / CELLS_FILE).read_text().splitlines()
    (tmp_path / CELLS_FILE).write_text("\n".join(lines[:-1]) + '\n{"key": "torn')
    third = run_study(**kwargs)
    assert third.ran == 1 and _metrics(third.rows) == _metrics(first.rows)
    # outputs
    for name in ("results.csv", "results.json", "results.md", "sr_vs_length.png"):
        assert (tmp_path / name).is_file()
    report = json.loads((tmp_path / "results.json").read_text())
    assert report["summary"][0]["length"] == 15 and report["summary"][0]["n_runs"] == 4
    assert "SR@1m #15 (%)" in (tmp_path / "results.md").read_text()
    # other settings in the same folder are refused
    with pytest.raises(InputError, match="different settings"):
        run_study(overrides={"localizer": {"every_k_frames": 3}}, **kwargs)


@register("flaky-test")
def _flaky(args, settings):
    """Two sequences; frames of the second raise in the middle of a chunk."""
    from zfloc_stream.io.datasets import open_dataset

    (good,) = open_dataset(GIBSON, settings)

    def broken(start, stop):
        for i, frame in enumerate(good.frames(start, stop)):
            if i == 3:
                raise RuntimeError("sensor cable unplugged")
            yield frame

    bad = Sequence("bad", broken, good.n_frames, good.ground_truth, good.floorplan, good.settings_overrides)
    return [good, bad]


def test_a_failing_chunk_is_reported_and_the_study_goes_on(tmp_path):
    out = run_study(["flaky-test:x"], [20], [0], tmp_path, workers=0, progress=False)
    errors = [r for r in out.rows if r["error"]]
    assert len(out.rows) == 4 and len(errors) == 2
    assert all("sensor cable unplugged" in r["error"] and r["sequence_name"] == "bad" for r in errors)
    (summary,) = out.summary
    # a cell that raised is a failed run, not one left out of the success rate
    assert summary["n_errors"] == 2 and summary["n_runs"] == 4 and summary["n_no_pose"] == 0
    good = [r for r in out.rows if not r["error"]]
    assert summary["success_rate"]["1"]["mean"] == sum(r["success_1m"] for r in good) / 4  # noqa: E501


def test_cli_exits_non_zero_when_cells_raised(tmp_path, capsys):
    rc = main(["--dataset", "flaky-test:x", "--lengths", "20", "--seeds", "1", "--workers", "0", "--no-progress", "--out", str(tmp_path)])
    assert rc == 1
    assert "2 cell(s) raised" in capsys.readouterr().err


def test_cli_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    cases = [
        ["--dataset", "nope:x", "--out", str(tmp_path)],
        ["--dataset", GIBSON, "--lengths", "15,abc", "--out", str(tmp_path)],
        ["--dataset", GIBSON, "--lengths", "5", "--out", str(tmp_path)],
        ["--dataset", GIBSON, "--seeds", "0", "--out", str(tmp_path)],
        ["--dataset", GIBSON, "--set", "study.eval_framez=3", "--out", str(tmp_path)],
        ["--dataset", "gibson:/no/such/root", "--out", str(tmp_path)],
    ]
    for argv in cases:
        assert main(argv + ["--workers", "0", "--no-progress"]) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("zfloc-study: error:"), (argv, err)


def test_cli_runs_a_tiny_study(tmp_path, capsys):
    assert main(["--dataset", GIBSON, "--lengths", "20", "--seeds", "1", "--workers", "0", "--no-progress", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "| Dataset |" in out and "2 cells" in out
    rows = list(csv.DictReader(open(tmp_path / "results.csv")))
    assert [int(r["start"]) for r in rows] == [0, 20]
    assert all(np.isfinite(float(r["rmse"])) or r["rmse"] == "inf" for r in rows)


def test_an_existing_scheduler_runs_the_cells(tmp_path):
    from dask.distributed import LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False, dashboard_address=":0") as cluster:
        remote = run_study([GIBSON], [20], [0], tmp_path / "remote", scheduler=cluster.scheduler_address, progress=False)
    local = run_study([GIBSON], [20], [0], tmp_path / "local", workers=0, progress=False)
    assert remote.ran == 2 and _metrics(remote.rows) == _metrics(local.rows)


def test_table_columns_read_in_order_and_one_seed_has_no_spread(tmp_path):
    """SR at each length longest first, then the RMSEs of the longest, each named with its
    length; one seed prints the value alone (no "± 0.0"); the plot draws every line."""
    from zfloc_stream.study import markdown_table, plot_sr_vs_length

    def stat(mean, std=float("nan")):
        return {"mean": mean, "std": std}

    summary = [{"dataset": "sim:rooms", "length": L, "success_rate": {"1": stat(sr), "0.5": stat(sr)},
                "rmse_succ": stat(0.2), "rmse_all": stat(0.4), "n_runs": 3, "n_no_pose": 0, "n_errors": 0}
               for L, sr in ((35, 1.0), (20, 0.5), (15, 0.25))]
    table = markdown_table(summary, [15, 20, 35], [1.0, 0.5])
    head = table.splitlines()[0]
    assert head == "| Dataset | SR@1m #35 (%) | SR@1m #20 (%) | SR@1m #15 (%) | RMSE_succ #35 (m) | RMSE_all #35 (m) |"
    assert table.splitlines()[2] == "| sim:rooms | 100.0 | 50.0 | 25.0 | 0.20 | 0.40 |"
    assert "±" not in table
    summary[0]["success_rate"]["1"] = stat(1.0, 0.0)  # two seeds that agree: a real zero spread
    assert "100.0 ± 0.0" in markdown_table(summary, [15, 20, 35], [1.0, 0.5])
    plot_sr_vs_length(summary, [1.0, 0.5], tmp_path / "p.png")
    assert (tmp_path / "p.png").stat().st_size > 0
