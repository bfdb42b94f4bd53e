"""What a study runs: its cells (dataset, sequence, length, chunk, seed), the chunks a
sequence is cut into, and the settings each cell runs with (the user's --config / --set
over the study base: rounds inline)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..settings.documents import load_yaml, read_document_text
from ..settings.loading import Settings, dotted_to_nested, load_settings, merge_nested
from ..errors import ConfigError


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
    from ..io.datasets import open_dataset

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
        data = load_yaml(read_document_text(config)) or {}
    for item in sets:  # read as load_settings read them (1e-3 a number, 0x10 text)
        key, raw = item.split("=", 1)
        data = merge_nested(data, dotted_to_nested(key.strip(), load_yaml(raw)))
    return data


# Studies run rounds inline unless told otherwise: offline, there is no push latency to
# hide, and inline is the reference every table is compared with (a --set overrides it).
STUDY_BASE = {"localizer": {"pipeline": "inline"}}


def cell_settings(overrides: dict, seed: int, base_overrides: dict | None = None) -> Settings:
    base = merge_nested(STUDY_BASE, base_overrides or {})
    return load_settings(overrides=overrides, base_overrides=base).model_copy(update={"seed": int(seed)})


def parse_lengths(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ConfigError(f"--lengths '{text}' must be comma-separated integers, e.g. 15,20,35,50,100") from None
    if not values or min(values) < 1:
        raise ConfigError(f"--lengths '{text}' must hold positive integers")
    return values
