"""A study's outputs: per dataset and length the mean and spread over seeds, results.csv,
results.json, the markdown table shaped like the paper's, the SR-vs-length plot."""

from __future__ import annotations

import json
from collections import Counter, defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..settings.loading import Settings
from ..metrics import REFERENCE_THRESHOLD, summarize
from .cells import threshold_key


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


def dataset_label(spec: str, depth: int = 1) -> str:
    """'carmen:/data/intel.log.gz' -> 'carmen:intel.log.gz' (tables stay narrow); depth:
    how many trailing path parts to keep."""
    kind, _, rest = spec.partition(":")
    parts = ["/".join(Path(p).parts[-depth:]) or p for p in rest.split(",")]
    return f"{kind}:{','.join(parts)}"


def dataset_labels(specs) -> dict[str, str]:
    """Each spec's label, unique among specs: two sessions both named session.mcap get as
    many parent folders as tell them apart ('mcap:fhw/session.mcap', 'mcap:aces/session.mcap')."""
    specs = list(dict.fromkeys(specs))
    labels = {spec: dataset_label(spec) for spec in specs}
    for depth in range(2, 64):
        taken = Counter(labels.values())
        clashing = [spec for spec in specs if taken[labels[spec]] > 1]
        if not clashing:
            break
        for spec in clashing:  # the whole spec once its parts are used up (one file spelt two ways)
            labels[spec] = dataset_label(spec, depth) if depth < 63 else spec
    return labels


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
    labels = dataset_labels(key[0] for key in groups)
    for (dataset, length), by_seed in sorted(groups.items(), key=lambda kv: (kv[0][0], -kv[0][1])):
        per_seed = []
        for seed, seed_rows in sorted(by_seed.items()):
            failed = [r.get("error") is not None for r in seed_rows]
            successes = [{t: not bad and bool(r[threshold_key(t)]) for t in thresholds} for r, bad in zip(seed_rows, failed)]
            rmses = [float("nan") if bad else r["rmse"] for r, bad in zip(seed_rows, failed)]
            per_seed.append(summarize(successes, rmses, thresholds, reference))
        summary.append(
            {
                "dataset": dataset,
                "label": labels[dataset],
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
    labels = dataset_labels(datasets)
    head = [f"SR@{ref}m #{L} (%)" for L in lengths] + [f"RMSE_succ #{longest} (m)", f"RMSE_all #{longest} (m)"]
    lines = ["| Dataset | " + " | ".join(head) + " |", "|---" * (len(head) + 1) + "|"]
    for d in datasets:
        cells = [_pct(by[(d, L)]["success_rate"][ref]) if (d, L) in by else "--" for L in lengths]
        s = by.get((d, longest))
        cells += ["--"] * 2 if s is None else [_metres(s["rmse_succ"]), _metres(s["rmse_all"])]
        lines.append(f"| {labels[d]} | " + " | ".join(cells) + " |")
    lines += ["", "| Dataset | length | runs | " + " | ".join(f"SR@{t:g}m (%)" for t in thresholds) + " | no pose | errors |"]
    lines.append("|---" * (len(thresholds) + 5) + "|")
    for d in datasets:
        for L in lengths:
            s = by.get((d, L))
            if s is None:
                continue
            srs = " | ".join(_pct(s["success_rate"][f"{t:g}"]) for t in thresholds)
            lines.append(f"| {labels[d]} | {L} | {s['n_runs']} | {srs} | {s['n_no_pose']} | {s['n_errors']} |")
    return "\n".join(lines) + "\n"


def plot_sr_vs_length(summary: list[dict], thresholds: Sequence[float], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    datasets = list(dict.fromkeys(s["dataset"] for s in summary))
    labels = dataset_labels(datasets)
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
                        label=f"{labels[d]} @{t:g} m")
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
    columns += [threshold_key(t) for t in thresholds]
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
