"""What the three command-line tools share: an argument parser whose every error is one
line on stderr with exit code 2 and a "did you mean" where a near name exists, warnings
printed as one `warning: ...` line, and a progress display that draws a bar only on a
terminal (a log file gets a plain line now and then instead of `\\r` redraws).

Kept free of heavy imports: `--help` and a usage error must stay fast.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys
import time
import warnings
from pathlib import Path

from ..errors import InputError


def did_you_mean(word: str, candidates, cutoff: float = 0.6) -> str:
    """' (did you mean X?)' for the nearest candidate, or ''."""
    match = difflib.get_close_matches(word, list(candidates), n=1, cutoff=cutoff)
    return f" (did you mean {match[0]}?)" if match else ""


def _option_strings(parser: argparse.ArgumentParser) -> list[str]:
    return [s for action in parser._actions for s in action.option_strings if s.startswith("--")]


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


class CliParser(argparse.ArgumentParser):
    """argparse with one-line errors (exit 2) and suggestions for misspelt options and
    commands. Subparsers made from it are CliParsers too."""

    def error(self, message: str):  # argparse would print the whole usage first
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = re.findall(r"'([^']*)'", m.group(2))
            message += did_you_mean(m.group(1), choices)
        self.exit(2, f"{self.prog}: error: {message}\n")

    def parse_args(self, args=None, namespace=None):
        parsed, extras = self.parse_known_args(args, namespace)
        if extras:
            # The subcommand that got them knows which options would have fitted.
            command = getattr(parsed, "command", None)
            owner = _subparsers(self).get(command, self) if command else self
            options = _option_strings(owner)
            hints = [(t.split("=", 1)[0], did_you_mean(t.split("=", 1)[0], options)) for t in extras if t.startswith("--")]
            hints = [(name, hint) for name, hint in hints if hint]
            text = f"unrecognized arguments: {' '.join(extras)}"
            if len(hints) == 1:
                text += hints[0][1]
            elif hints:
                text += " (" + "; ".join(f"{name}: {hint.strip(' ()')}" for name, hint in hints) + ")"
            owner.error(text)
        return parsed


def one_line(err: BaseException) -> str:
    """An error's message on one line (a multi-line one joined), or its type's name."""
    text = str(err)
    return (" ".join(text.split()) if "\n" in text else text) or type(err).__name__


_active_bar = None  # the tqdm bar on screen, so a warning is printed above it, not into it


def print_warning(text: str) -> None:
    """One `warning: ...` line on stderr (above a progress bar that is being drawn)."""
    line = "warning: " + " ".join(str(text).split())
    if _active_bar is not None:
        _active_bar.write(line, file=sys.stderr)
    else:
        print(line, file=sys.stderr, flush=True)


def install_warning_format() -> None:
    """Python warnings (from loaders, the session writer...) as one `warning: ...` line,
    without the file, line number and source line Python adds. Only the formatting is
    replaced: filters, and pytest.warns / catch_warnings(record=True), work as before."""

    def format_one_line(message, category, filename, lineno, line=None):
        if _active_bar is not None:  # above the bar, not into it
            print_warning(message)
            return ""
        return "warning: " + " ".join(str(message).split()) + "\n"

    warnings.formatwarning = format_one_line


class Progress:
    """Counts items. On a terminal: a tqdm bar on stderr. Otherwise one plain line every
    `every` seconds (and one at the end), so a log shows the run advancing without the
    bar's carriage returns."""

    def __init__(self, total: int | None, description: str, unit: str = "frame", enabled: bool = True,
                 stream=None, every: float = 10.0):
        global _active_bar
        self.total, self.description, self.unit = total, description, unit
        self.stream = sys.stderr if stream is None else stream
        self.enabled = enabled
        self.count = 0
        self.every = every
        self._t0 = self._last = time.monotonic()
        self._bar = None
        if enabled and self.stream.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=description, unit=unit, file=self.stream)
            _active_bar = self._bar

    def update(self, n: int = 1) -> None:
        self.count += n
        if self._bar is not None:
            self._bar.update(n)
        elif self.enabled and time.monotonic() - self._last >= self.every:
            self._line()

    def write(self, text: str) -> None:
        """A message line that does not break the bar."""
        if self._bar is not None:
            self._bar.write(text, file=self.stream)
        else:
            print(text, file=self.stream, flush=True)

    def _line(self) -> None:
        self._last = time.monotonic()
        of = f"/{self.total}" if self.total else ""
        print(f"{self.description}: {self.count}{of} {self.unit}s, {self._last - self._t0:.0f} s", file=self.stream, flush=True)

    def close(self) -> None:
        global _active_bar
        if self._bar is not None:
            self._bar.close()
            if _active_bar is self._bar:
                _active_bar = None
            self._bar = None
        elif self.enabled and self.count and time.monotonic() - self._t0 >= self.every:
            self._line()  # a long run ends with its final count; a short one stays quiet

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def prepare_out_dir(out_dir, create: bool = True) -> Path:
    """The output folder, created; a clear error when the path is a file or cannot be made.
    create=False only checks (the CLI does so before any heavy work, so the mistake costs no
    waiting and a later error leaves no empty folder behind)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"--out {out_dir} is a file, not a folder: name a folder (it is created if missing)")
    if not create:
        return out_dir
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"--out {out_dir}: cannot create the folder: {err.strerror or err}") from None
    return out_dir
