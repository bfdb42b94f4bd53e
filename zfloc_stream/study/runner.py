"""Running a study's cells on dask (an in-process local cluster by default, or a
scheduler's), resuming where a previous run stopped."""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from ..settings.loading import Settings, load_settings
from ..errors import InputError
from .cells import run_cell
from .plan import plan_cells
from .report import StudyOutcome, summarize_rows, write_outputs
from .resume import CELLS_FILE, check_manifest, load_finished


def _make_client(scheduler: str | None, workers: int | None, processes: bool, settings: Settings):
    from dask.distributed import Client, LocalCluster

    if scheduler:
        try:
            return Client(scheduler, timeout=settings.study.connect_timeout_s), None
        except (OSError, TimeoutError, ValueError) as err:
            raise InputError(f"cannot connect to dask scheduler {scheduler}: {err}") from None
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(
        n_workers=n, threads_per_worker=1, processes=processes, dashboard_address=":0", silence_logs=logging.ERROR
    )
    return Client(cluster), cluster


class _Quiet:
    """No progress display; a failed chunk still gets its line on stderr."""

    def update(self, n: int = 1) -> None:
        pass

    def write(self, text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    def close(self) -> None:
        pass


def run_study(
    datasets: Sequence[str],
    lengths: Sequence[int],
    seeds: Sequence[int],
    out_dir: str | Path,
    overrides: dict | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    processes: bool = True,
    progress: Callable[[int, str, str], Any] | None = None,
) -> StudyOutcome:
    """Plan, run the unfinished cells (workers=0: in this process, no dask), write the
    outputs. Returns the sorted rows and the summary. progress(total, description, unit):
    a counter with update(n), write(text) and close() (the CLI passes its progress bar;
    this layer draws none itself); None or False: no display, a failed chunk's line on stderr."""
    overrides = overrides or {}
    settings = load_settings(overrides=overrides)
    lengths = sorted({int(x) for x in lengths}, reverse=True)
    if not lengths or min(lengths) < settings.study.eval_frames:
        raise InputError(f"sequence lengths must be at least study.eval_frames = {settings.study.eval_frames} frames")
    if not seeds:
        raise InputError("need at least one seed")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    check_manifest(out, overrides)
    cells = plan_cells(datasets, lengths, seeds, settings)
    if not cells:
        raise InputError(f"no chunk of {min(lengths)} frames fits in {', '.join(datasets)}")
    finished = load_finished(out)
    todo = [c for c in cells if finished.get(c.key, {}).get("error", "x") is not None]
    bar = progress(len(cells), "study", "chunk") if progress else _Quiet()
    bar.update(len(cells) - len(todo))
    t0 = time.perf_counter()
    with open(out / CELLS_FILE, "a") as sink:

        def record(row: dict) -> None:
            finished[row["key"]] = row
            sink.write(json.dumps(row) + "\n")
            sink.flush()
            bar.update(1)
            if row["error"] is not None:
                bar.write(f"chunk failed: {row['key']}: {row['error']}")

        if todo and workers == 0:
            for cell in todo:
                record(run_cell(cell, overrides))
        elif todo:
            from dask.distributed import as_completed

            client, cluster = _make_client(scheduler, workers, processes, settings)
            try:
                futures = client.map(run_cell, todo, overrides=overrides, key=[f"cell-{i}-{c.key}" for i, c in enumerate(todo)])
                for future in as_completed(futures):
                    record(future.result())
            finally:
                client.close()
                if cluster is not None:
                    cluster.close()
    bar.close()
    seconds = time.perf_counter() - t0
    rows = [finished[c.key] for c in cells]
    summary = summarize_rows(rows, settings)
    outcome = StudyOutcome(rows, summary, ran=len(todo), skipped=len(cells) - len(todo), seconds=seconds, out_dir=out)
    write_outputs(outcome, datasets, lengths, seeds, settings)
    return outcome
