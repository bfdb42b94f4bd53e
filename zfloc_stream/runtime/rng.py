"""Seeded randomness. Every random draw in the package comes from a Generator made here,
from the config seed plus stable integer keys (frame index, trial, stage), so the same
inputs + config give the same bits whatever ran before."""

from __future__ import annotations

import zlib

import numpy as np


def _key(part) -> int:
    if isinstance(part, str):
        return zlib.crc32(part.encode())  # stable across processes, unlike hash()
    return int(part)


def make_rng(seed: int, *keys) -> np.random.Generator:
    """A Generator determined by seed and keys, e.g. make_rng(cfg.seed, "ransac", frame)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), *(_key(k) for k in keys)]))
