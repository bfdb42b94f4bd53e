"""SR-vs-length studies (F3Loc protocol), scaled out with dask.

Each sequence is cut into consecutive non-overlapping chunks of L frames; when a sequence
holds more than study.max_chunks_per_sequence chunks of a length, that many are kept,
spread evenly along it. A cell = (dataset spec, sequence, length, chunk, seed): a fresh
Localizer (settings.seed = seed) runs on the chunk's frames and the last study.eval_frames
frames are scored (metrics.py). `run_cell` is a pure function of the cell and the
settings overrides, so results do not depend on where or in which order cells run
(rows are sorted by cell before anything is written).

Out folder: cells.jsonl (one row per finished cell, appended as cells finish: the study
resumes where it stopped; failed cells are retried), study.json (the settings the cells
were run with: a resumed study must use the same), results.csv (one row per cell of this
study, sorted), results.json (summary: per dataset and length, mean and spread over
seeds), results.md (a table shaped like the paper's), sr_vs_length.png.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import time
import traceback
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from .config import Settings, dotted_to_nested, dump_settings, load_settings, merge_nested
from .errors import ConfigError, InputError, ZflocError
from .metrics import REFERENCE_THRESHOLD, evaluate_run, position_errors, summarize

CELLS_FILE = "cells.jsonl"
MANIFEST_FILE = "study.json"


# ---------------------------------------------------------------------------------------
# cells
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, order=True)
class Cell:
    dataset: str  # spec, e.g. "sim:apartment"
    sequence: int  # index in open_dataset(dataset)
    sequence_name: str
    length: int
    chunk: int
    start: int
    stop: int
    seed: int

    @property
    def key(self) -> str:
        return f"{self.dataset}|{self.sequence_name}|L{self.length}|c{self.chunk}|s{self.seed}"


def chunk_starts(n_frames: int, length: int, max_chunks: int) -> list[int]:
    """Start frames of the kept chunks: consecutive, non-overlapping; at most max_chunks,
    spread evenly along the sequence when there are more."""
    available = n_frames // length
    if available <= max_chunks:
        picked = np.arange(available)
    else:
        picked = np.unique(np.round(np.linspace(0, available - 1, max_chunks)).astype(int))
    return [int(i) * length for i in picked]


def plan_cells(datasets: Sequence[str], lengths: Sequence[int], seeds: Sequence[int], settings: Settings) -> list[Cell]:
    from .datasets import open_dataset

    cells = []
    for spec in datasets:
        for index, seq in enumerate(open_dataset(spec, settings)):
            for length in lengths:
                for chunk, start in enumerate(chunk_starts(seq.n_frames, length, settings.study.max_chunks_per_sequence)):
                    cells.extend(Cell(spec, index, seq.name, length, chunk, start, start + length, seed) for seed in seeds)
    return sorted(cells)


def user_overrides(config: str | Path | None = None, sets: Iterable[str] = ()) -> dict:
    """--config FILE + --set k=v as one nested dict (validated), to ship to workers."""
    load_settings(config, list(sets))  # raises ConfigError with a clear message
    data: dict = {}
    if config is not None:
        data = yaml.safe_load(Path(config).read_text()) or {}
    for item in sets:
        key, raw = item.split("=", 1)
        data = merge_nested(data, dotted_to_nested(key.strip(), yaml.safe_load(raw)))
    return data


# Studies run rounds inline unless told otherwise: offline, there is no push latency to
# hide, and inline is the reference every table is compared with (a --set overrides it).
STUDY_BASE = {"localizer": {"pipeline": "inline"}}


def cell_settings(overrides: dict, seed: int, base_overrides: dict | None = None) -> Settings:
    base = merge_nested(STUDY_BASE, base_overrides or {})
    return load_settings(overrides=overrides, base_overrides=base).model_copy(update={"seed": int(seed)})


@lru_cache(maxsize=8)
def _open_cached(spec: str, settings_json: str):
    from .datasets import open_dataset

    return open_dataset(spec, Settings.model_validate_json(settings_json))


def _threshold_key(t: float) -> str:
    return f"success_{t:g}m"


def run_cell(cell: Cell, overrides: dict | None = None) -> dict:
    """Localize one chunk with one seed; a row of results. Never raises: a failure is
    reported in the row's `error` field."""
    from .localizer import Localizer

    overrides = overrides or {}
    row = asdict(cell)
    row["key"] = cell.key
    t0 = time.perf_counter()
    try:
        data_settings = cell_settings(overrides, cell.seed)
        seq = _open_cached(cell.dataset, data_settings.model_dump_json())[cell.sequence]
        if seq.name != cell.sequence_name:
            raise InputError(f"dataset {cell.dataset}: sequence {cell.sequence} is {seq.name!r}, expected {cell.sequence_name!r}")
        settings = cell_settings(overrides, cell.seed, seq.settings_overrides)
        study = settings.study
        poses, truth, status = [], [], None
        with Localizer(seq.floorplan_for(cell.start, cell.stop), settings) as localizer:
            for frame in seq.frames(cell.start, cell.stop):
                est = localizer.push(frame)
                poses.append(est.pose)
                truth.append(np.full(3, np.nan) if frame.ground_truth is None else frame.ground_truth)
                status = est.status
        truth = np.asarray(truth, dtype=float)
        if not np.isfinite(truth[-study.eval_frames :, :2]).all():
            raise InputError(f"{cell.key}: ground truth missing in the last {study.eval_frames} frames")
        errors = position_errors(poses, truth)
        run = evaluate_run(errors, study.thresholds, study.eval_frames)
        tail = errors[-study.eval_frames :]
        row.update({_threshold_key(t): ok for t, ok in run.success.items()})
        row.update(
            rmse=run.rmse,
            max_error=run.max_error,
            final_error=run.final_error,
            frames_with_pose=int(np.isfinite(tail).sum()),
            final_status=status,
            error=None,
        )
    except Exception as err:  # noqa: BLE001 (a failing chunk is reported, the study goes on)
        detail = str(err) if isinstance(err, ZflocError) else f"{type(err).__name__}: {err} [{_where(err)}]"
        row.update(error=detail)
    row["seconds"] = time.perf_counter() - t0
    return row


def _where(err: Exception) -> str:
    frames = traceback.extract_tb(err.__traceback__)
    return f"{Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else "?"


# ---------------------------------------------------------------------------------------
# running
# ---------------------------------------------------------------------------------------
def _settings_fingerprint(overrides: dict) -> str:
    return hashlib.sha256(dump_settings(load_settings(overrides=overrides)).encode()).hexdigest()[:16]


def _check_manifest(out: Path, overrides: dict) -> None:
    manifest = out / MANIFEST_FILE
    fingerprint = _settings_fingerprint(overrides)
    if manifest.is_file():
        try:
            old = json.loads(manifest.read_text())
        except (OSError, json.JSONDecodeError):
            raise InputError(f"{manifest} is unreadable: remove it or use another --out") from None
        if old.get("settings_fingerprint") != fingerprint:
            raise InputError(f"{out} holds a study run with different settings; use another --out (or delete {CELLS_FILE})")
        return
    manifest.write_text(json.dumps({"settings_fingerprint": fingerprint, "overrides": overrides}, indent=2))


def load_finished(out: Path) -> dict[str, dict]:
    """Rows of cells finished without error, by key (a torn last line is ignored)."""
    rows: dict[str, dict] = {}
    path = out / CELLS_FILE
    if not path.is_file():
        return rows
    for line in path.read_text().splitlines():
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            continue  # interrupted while writing
        if isinstance(row, dict) and "key" in row:
            if row.get("error") is None:
                rows[row["key"]] = row
            else:
                rows.setdefault(row["key"], row)
    return rows


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


@dataclass
class StudyOutcome:
    rows: list[dict]  # one per planned cell, sorted
    summary: list[dict]
    ran: int  # cells run this time
    skipped: int  # cells already finished
    seconds: float  # wall time of the cells run this time
    out_dir: Path

    @property
    def chunks_per_second(self) -> float:
        return self.ran / self.seconds if self.seconds > 0 else float("nan")


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
    _check_manifest(out, overrides)
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


# ---------------------------------------------------------------------------------------
# summaries and outputs
# ---------------------------------------------------------------------------------------
def dataset_label(spec: str) -> str:
    """'carmen:/data/intel.log.gz' -> 'carmen:intel.log.gz' (tables stay narrow)."""
    kind, _, rest = spec.partition(":")
    parts = [Path(p).name or p for p in rest.split(",")]
    return f"{kind}:{','.join(parts)}"


def _spread(values) -> dict:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if v.size == 0:
        return {"mean": float("nan"), "std": float("nan")}
    # one seed has no spread: NaN, so the table prints the value alone, not "± 0.0"
    return {"mean": float(v.mean()), "std": float(v.std(ddof=1)) if v.size > 1 else float("nan")}


def summarize_rows(rows: list[dict], settings: Settings) -> list[dict]:
    """Per (dataset, length): SR per threshold and RMSEs computed per seed over all chunks
    of all sequences, then mean and sample std over seeds. A cell that raised counts as a
    failed run (no pose): leaving it out would make a crashing estimator look better than
    one that answers wrongly. It is also counted in n_errors."""
    thresholds = [float(t) for t in settings.study.thresholds]
    reference = REFERENCE_THRESHOLD if REFERENCE_THRESHOLD in thresholds else thresholds[0]
    groups: dict[tuple, dict[int, list[dict]]] = defaultdict(lambda: defaultdict(list))
    errors: dict[tuple, int] = defaultdict(int)
    for row in rows:
        key = (row["dataset"], row["length"])
        if row.get("error") is not None:
            errors[key] += 1
        groups[key][row["seed"]].append(row)
    summary = []
    for (dataset, length), by_seed in sorted(groups.items(), key=lambda kv: (kv[0][0], -kv[0][1])):
        per_seed = []
        for seed, seed_rows in sorted(by_seed.items()):
            failed = [r.get("error") is not None for r in seed_rows]
            successes = [{t: not bad and bool(r[_threshold_key(t)]) for t in thresholds} for r, bad in zip(seed_rows, failed)]
            rmses = [float("nan") if bad else r["rmse"] for r, bad in zip(seed_rows, failed)]
            per_seed.append(summarize(successes, rmses, thresholds, reference))
        summary.append(
            {
                "dataset": dataset,
                "label": dataset_label(dataset),
                "length": length,
                "n_seeds": len(per_seed),
                "n_runs": sum(s.n_runs for s in per_seed),
                "n_errors": errors[(dataset, length)],
                "n_no_pose": sum(s.n_no_pose for s in per_seed) - errors[(dataset, length)],  # errors apart
                "success_rate": {f"{t:g}": _spread([s.success_rate[t] for s in per_seed]) for t in thresholds},
                "rmse_succ": _spread([s.rmse_succ for s in per_seed]),
                "rmse_all": _spread([s.rmse_all for s in per_seed]),
            }
        )
    return summary


def _pct(stat: dict) -> str:
    if not np.isfinite(stat["mean"]):
        return "--"
    spread = f" ± {100 * stat['std']:.1f}" if np.isfinite(stat["std"]) else ""
    return f"{100 * stat['mean']:.1f}{spread}"


def _metres(stat: dict) -> str:
    if not np.isfinite(stat["mean"]):
        return "--"
    spread = f" ± {stat['std']:.2f}" if np.isfinite(stat["std"]) else ""
    return f"{stat['mean']:.2f}{spread}"


def markdown_table(summary: list[dict], lengths: Sequence[int], thresholds: Sequence[float]) -> str:
    """Per dataset: SR@1m at every length, longest first, then RMSE_succ and RMSE_all at
    the longest (the paper's numbers, with each column's length in its name, so the columns
    read in order); a second table gives SR at every threshold and length. Mean ± sample
    std over seeds; with one seed the value alone."""
    lengths = sorted(lengths, reverse=True)
    longest = lengths[0]
    ref = f"{REFERENCE_THRESHOLD:g}" if REFERENCE_THRESHOLD in thresholds else f"{thresholds[0]:g}"
    by = {(s["dataset"], s["length"]): s for s in summary}
    datasets = list(dict.fromkeys(s["dataset"] for s in summary))
    head = [f"SR@{ref}m #{L} (%)" for L in lengths] + [f"RMSE_succ #{longest} (m)", f"RMSE_all #{longest} (m)"]
    lines = ["| Dataset | " + " | ".join(head) + " |", "|---" * (len(head) + 1) + "|"]
    for d in datasets:
        cells = [_pct(by[(d, L)]["success_rate"][ref]) if (d, L) in by else "--" for L in lengths]
        s = by.get((d, longest))
        cells += ["--"] * 2 if s is None else [_metres(s["rmse_succ"]), _metres(s["rmse_all"])]
        lines.append(f"| {dataset_label(d)} | " + " | ".join(cells) + " |")
    lines += ["", "| Dataset | length | runs | " + " | ".join(f"SR@{t:g}m (%)" for t in thresholds) + " | no pose | errors |"]
    lines.append("|---" * (len(thresholds) + 5) + "|")
    for d in datasets:
        for L in lengths:
            s = by.get((d, L))
            if s is None:
                continue
            srs = " | ".join(_pct(s["success_rate"][f"{t:g}"]) for t in thresholds)
            lines.append(f"| {dataset_label(d)} | {L} | {s['n_runs']} | {srs} | {s['n_no_pose']} | {s['n_errors']} |")
    return "\n".join(lines) + "\n"


def plot_sr_vs_length(summary: list[dict], thresholds: Sequence[float], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    datasets = list(dict.fromkeys(s["dataset"] for s in summary))
    all_lengths = sorted({s["length"] for s in summary})
    # Thresholds often give the same SR (every success within 0.5 m): each (dataset,
    # threshold) line gets its own colour, marker and line style, and a small sideways
    # offset, so coinciding lines stay visible side by side.
    width = (all_lengths[-1] - all_lengths[0]) if len(all_lengths) > 1 else 10.0
    n_lines = max(1, len(datasets) * len(thresholds))
    styles = ("-o", "--s", ":^", "-.v", "-D", "--P")
    for i, d in enumerate(datasets):
        rows = sorted((s for s in summary if s["dataset"] == d), key=lambda s: s["length"])
        for j, t in enumerate(thresholds):
            k = i * len(thresholds) + j
            dodge = (k - (n_lines - 1) / 2) * 0.012 * width
            x = [s["length"] + dodge for s in rows]
            mean = [100 * s["success_rate"][f"{t:g}"]["mean"] for s in rows]
            std = [100 * s["success_rate"][f"{t:g}"]["std"] for s in rows]
            std = [v if np.isfinite(v) else 0.0 for v in std]
            ax.errorbar(x, mean, yerr=std, fmt=styles[j % len(styles)], color=f"C{k % 10}", capsize=3, mfc="none" if j else None,
                        label=f"{dataset_label(d)} @{t:g} m")
    ax.set_xlabel("sequence length (frames)")
    ax.set_ylabel("success rate (%)")
    ax.set_ylim(-2, 102)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("SR vs sequence length (mean ± std over seeds; lines offset sideways)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_outputs(outcome: StudyOutcome, datasets, lengths, seeds, settings: Settings) -> None:
    import csv

    out = outcome.out_dir
    thresholds = [float(t) for t in settings.study.thresholds]
    columns = ["dataset", "sequence", "sequence_name", "length", "chunk", "start", "stop", "seed"]
    columns += [_threshold_key(t) for t in thresholds]
    columns += ["rmse", "max_error", "final_error", "frames_with_pose", "final_status", "error", "seconds"]
    with open(out / "results.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(outcome.rows)
    report = {
        "datasets": list(datasets),
        "lengths": list(lengths),
        "seeds": list(seeds),
        "thresholds": thresholds,
        "eval_frames": settings.study.eval_frames,
        "max_chunks_per_sequence": settings.study.max_chunks_per_sequence,
        "summary": outcome.summary,
        "run": {"cells_run": outcome.ran, "cells_skipped": outcome.skipped, "seconds": outcome.seconds,
                "chunks_per_second": outcome.chunks_per_second},
    }
    (out / "results.json").write_text(json.dumps(_finite_or_null(report), indent=2, allow_nan=False))
    (out / "results.md").write_text(markdown_table(outcome.summary, lengths, thresholds))
    plot_sr_vs_length(outcome.summary, thresholds, out / "sr_vs_length.png")


def _finite_or_null(value):
    """NaN / inf -> None, so results.json is strict JSON."""
    if isinstance(value, dict):
        return {k: _finite_or_null(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_finite_or_null(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def parse_lengths(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ConfigError(f"--lengths '{text}' must be comma-separated integers, e.g. 15,20,35,50,100") from None
    if not values or min(values) < 1:
        raise ConfigError(f"--lengths '{text}' must hold positive integers")
    return values
