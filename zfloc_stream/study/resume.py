"""A study's out folder as a resume point: cells.jsonl (one row per finished cell,
appended as cells finish) and study.json (the settings fingerprint a resumed study must
match)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from ..settings.loading import dump_settings, load_settings
from ..errors import InputError


CELLS_FILE = "cells.jsonl"
MANIFEST_FILE = "study.json"


def _settings_fingerprint(overrides: dict) -> str:
    return hashlib.sha256(dump_settings(load_settings(overrides=overrides)).encode()).hexdigest()[:16]


def check_manifest(out: Path, overrides: dict) -> None:
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
