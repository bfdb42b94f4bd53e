"""One harness for the stage benchmarks (benchmarks/bench_*.py): the common options, the
machine header printed once, rows as JSON lines, one markdown table format.

A benchmark declares the common options it takes (with its own defaults), adds its own,
and reports rows through tables:

    bench = Benchmark("fusion", __doc__, frames=300, repeat=3)   # --json, --quick always; these too
    bench.parser.add_argument("--scene", default="apartment")
    args = bench.parse(argv)                              # prints the header
    table = bench.table(["case", ("median_ms", "median ms")], title="push")
    table.add(case="apartment", median_ms=1.23, p95_ms=2.0)   # printed as a line; every field to --json
    return bench.done()

--json PATH writes one JSON object a line: first the header (machine, commit, command
line), then every row with the benchmark's name and its table's title. --quick asks for the
smallest size (what tests/test_benchmarks.py runs); each benchmark says what it shrinks.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def positive_int(text: str) -> int:
    """argparse type: a whole number >= 1 (a count of frames, repetitions or workers)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def machine() -> dict:
    """Python, numpy, CPUs (and their load), the checkout's commit, the date."""
    try:
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                                capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "", False
    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "cpus": os.cpu_count(),
        "load": round(os.getloadavg()[0], 1),
        "commit": (commit or "unknown") + (" (with local changes)" if dirty else ""),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
    }


def header_line(info: dict) -> str:
    return (f"python {info['python']}, numpy {info['numpy']}, {info['cpus']} CPUs (load {info['load']:g}), "
            f"commit {info['commit']}, {info['date']}")


def cell(value, spec: str | None = None) -> str:
    """One table cell: a float with 3 significant digits at most one decimal past them
    (1234, 123.4, 12.34, 1.234, 0.0123), unless the column gives a format."""
    if value is None:
        return ""
    if spec is not None:
        return format(value, spec)
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (float, np.floating)):
        v = float(value)
        if not np.isfinite(v):
            return str(v)
        a = abs(v)
        if a >= 1000 or v == 0:
            return f"{v:.0f}"
        if a >= 100:
            return f"{v:.1f}"
        if a >= 10:
            return f"{v:.2f}"
        if a >= 1:
            return f"{v:.3f}"
        return f"{v:.3g}"
    return str(value)


def jsonable(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON: {type(value).__name__}")


class Table:
    """A markdown table printed line by line as its rows come (long runs show progress)."""

    def __init__(self, bench: Benchmark, columns, title: str | None, formats: dict | None):
        self.bench, self.title = bench, title
        self.keys = [c if isinstance(c, str) else c[0] for c in columns]
        labels = [c if isinstance(c, str) else c[1] for c in columns]
        self.formats = formats or {}
        self.rows: list[dict] = []
        if title:
            print(f"\n### {title}\n")
        print("| " + " | ".join(labels) + " |")
        print("|" + "---|" * len(labels), flush=True)

    def add(self, **fields) -> dict:
        """One row: its table columns printed, every field written to --json."""
        self.rows.append(fields)
        self.bench.write({"table": self.title, **fields})
        print("| " + " | ".join(cell(fields.get(k), self.formats.get(k)) for k in self.keys) + " |", flush=True)
        return fields


class Benchmark:
    """The parser with the common options, the header and the JSON rows of one run."""

    def __init__(self, name: str, doc: str, *, seed: int | None = None, repeat: int | None = None, frames=None,
                 workers: int | None = None, settings: bool = False):
        self.name = name  # the script's, in every JSON row
        self.parser = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
        common = self.parser.add_argument_group("common benchmark options (benchmarks/harness.py)")
        common.add_argument("--json", type=Path, metavar="PATH", help="write the header and every row here, one JSON object a line")
        common.add_argument("--quick", action="store_true", help="the smallest size (a smoke run)")
        if seed is not None:
            common.add_argument("--seed", type=int, default=seed, help=f"random seed (default {seed})")
        if repeat is not None:
            common.add_argument("--repeat", "--repeats", dest="repeat", type=positive_int, default=repeat,
                                help=f"timed repetitions of each case (default {repeat})")
        if frames is not None:
            many = isinstance(frames, (list, tuple))
            common.add_argument("--frames", type=positive_int, nargs="+" if many else None, default=frames,
                                help=f"frames per case (default {' '.join(map(str, frames)) if many else frames})")
        if workers is not None:
            common.add_argument("--workers", type=positive_int, default=workers, help=f"worker processes (default {workers})")
        if settings:
            common.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a settings override (repeatable)")
        self._out = None
        self.args = None

    def parse(self, argv=None) -> argparse.Namespace:
        """Parse the command line, print the header, open --json. A bad option (an unknown
        or invalid --set, a --json that cannot be written) is one usage error line, exit 2,
        before anything runs."""
        self.args = self.parser.parse_args(argv)
        if getattr(self.args, "set", None):
            from zfloc_stream.errors import ZflocError
            from zfloc_stream.settings.loading import load_settings

            try:
                load_settings(overrides=self.args.set)
            except ZflocError as err:
                self.parser.error(str(err))
        if self.args.json:
            try:
                self._out = open(self.args.json, "w")
            except OSError as err:
                self.parser.error(f"--json {self.args.json}: {err.strerror}")
        info = machine()
        print(header_line(info), flush=True)
        if self._out is not None:
            self.write({"header": info, "argv": list(sys.argv[1:] if argv is None else argv)})
        return self.args

    def write(self, record: dict) -> None:
        if self._out is not None:
            self._out.write(json.dumps({"benchmark": self.name, **record}, default=jsonable) + "\n")
            self._out.flush()

    def table(self, columns, title: str | None = None, formats: dict | None = None) -> Table:
        """A new table: columns are row keys or (key, label) pairs; formats maps a key to a
        format spec (default: cell())."""
        return Table(self, columns, title, formats)

    def note(self, text: str) -> None:
        """A line that is not a row (what was skipped, what the case is)."""
        print(text, flush=True)

    def done(self) -> int:
        if self._out is not None:
            self._out.close()
            self._out = None
        return 0
