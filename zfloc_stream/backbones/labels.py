"""Segmenter classes -> the label codes of frames.py, matched by the names in the model's
own id2label (never by index: two models with the same classes in another order map the
same way)."""

from __future__ import annotations

import re

import numpy as np

from ..settings.loading import BackboneSettings
from ..errors import BackboneError
from ..frames import CEILING, FLOOR, OTHER, UNKNOWN, WALL

N_CODES = OTHER + 1


def synonyms(name: str) -> set[str]:
    """'windowpane;window' / 'Door, double door ' -> {'windowpane', 'window'} / {'door', 'double door'}."""
    return {part.strip().lower() for part in re.split(r"[;,]", str(name)) if part.strip()}


def class_codes(id2label: dict, cfg: BackboneSettings, model: str = "model") -> np.ndarray:
    """codes[i] = label code of class i. Classes named in cfg.*_classes map to wall,
    floor, ceiling or unknown (first match in that order); all others are 'other'."""
    if not id2label:
        raise BackboneError(f"{model}: the segmentation model has no id2label class names")
    try:
        ids = {int(k): v for k, v in id2label.items()}
    except (TypeError, ValueError):
        raise BackboneError(f"{model}: id2label keys must be class indices") from None
    groups = (
        (WALL, cfg.wall_classes),
        (FLOOR, cfg.floor_classes),
        (CEILING, cfg.ceiling_classes),
        (UNKNOWN, cfg.unknown_classes),
    )
    wanted = [(code, {n.strip().lower() for n in names}) for code, names in groups]
    codes = np.full(max(ids) + 1, OTHER, dtype=np.uint8)
    for index, name in ids.items():
        names = synonyms(name)
        for code, group in wanted:
            if names & group:
                codes[index] = code
                break
    if not (codes == WALL).any():
        shown = ", ".join(str(ids[i]) for i in sorted(ids)[:12])
        raise BackboneError(
            f"{model}: no class is named like a wall ({', '.join(cfg.wall_classes)}); its classes are {shown}"
            + (", ..." if len(ids) > 12 else "")
            + ": set backbones.wall_classes"
        )
    return codes


def grouping_matrix(codes: np.ndarray) -> np.ndarray:
    """(n_classes, 5) one-hot: class probabilities @ this = probability of each code."""
    g = np.zeros((codes.size, N_CODES), dtype=np.float32)
    g[np.arange(codes.size), codes] = 1.0
    return g
