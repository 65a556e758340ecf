"""docs/results.md written by the benchmarks: `bench WHAT --results docs/results.md` replaces the
section named after WHAT with what the benchmark printed, the command and the date.

    printed = capture_stdout(Path("docs/results.md"))   # checks the path; the figures still reach the terminal
    ...                                                 # the benchmark prints its tables against the goals
    write_section(Path("docs/results.md"), "solver", printed.stop(), "uareme-fusion bench solver")

A section lies between `<!-- results:NAME -->` and `<!-- /results:NAME -->`; everything outside the
sections (the document's own prose) is kept as it is, and a section not yet there is appended.
"""

from __future__ import annotations

import datetime
import io
import os
import re
import sys
from pathlib import Path

from ..errors import InputError
from ..io.safe_files import write_text_atomic

ANSI_ESCAPE = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
"""Terminal colour and cursor codes, which rich may print: not for a markdown file."""


class StdoutTee(io.TextIOBase):
    """Everything written to stdout while installed, also kept; `stop()` restores stdout and returns it."""

    def __init__(self, columns: int = 120):
        self._out, self._kept = sys.stdout, io.StringIO()
        self._columns = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = self._columns or str(columns)  # rich's width when stdout is no terminal
        sys.stdout = self

    def write(self, text: str) -> int:
        self._kept.write(text)
        return self._out.write(text)

    def flush(self) -> None:
        self._out.flush()

    def isatty(self) -> bool:
        return False  # rich then prints no cursor tricks (progress bars) into the kept text

    def stop(self) -> str:
        if sys.stdout is self:
            sys.stdout = self._out
            if self._columns is None:
                os.environ.pop("COLUMNS", None)
        return self._kept.getvalue()


def capture_stdout(results_path: Path) -> StdoutTee:
    """A tee of stdout, once `results_path` is known to be writable (before a long benchmark runs)."""
    _check_writable(Path(results_path))
    return StdoutTee()


def _check_writable(path: Path) -> None:
    if path.is_dir() or not path.parent.is_dir():
        raise InputError(f"--results {path}: cannot write a file there (a folder, or its folder does not exist)")


def invoked_command(ctx, leave_out: tuple[str, ...] = ("--results", "--json")) -> str:
    """The command of click/typer context `ctx` as a user would type it: its name, arguments and the
    options that differ from their defaults (those in `leave_out` left out)."""
    words = ["uareme-fusion", ctx.info_name or ""]  # as installed, however it was started (python -m ...)
    for param in ctx.command.params:
        value = ctx.params.get(param.name)
        if param.param_type_name == "argument":
            words.append(str(value))
        elif value != param.default and value is not None and not set(param.opts) & set(leave_out):
            name = max(param.opts, key=len)
            words.append(name if value is True else f"{name} {value}")
    return " ".join(words)


def section_markers(name: str) -> tuple[str, str]:
    return f"<!-- results:{name} -->", f"<!-- /results:{name} -->"


def write_section(path: Path, name: str, printed: str, command: str, today: datetime.date | None = None) -> None:
    """Replace (or append) section `name` of the markdown file `path` with the figures `printed` by
    `command`, dated `today` (default: today, UTC). The file's other text is kept byte for byte."""
    path = Path(path)
    _check_writable(path)
    text = path.read_text(encoding="utf-8") if path.is_file() else "# Results\n"
    start, end = section_markers(name)
    today = today or datetime.datetime.now(datetime.timezone.utc).date()
    figures = ANSI_ESCAPE.sub("", printed).rstrip().replace("```", "'''")
    body = (f"{start}\n`{command}`, {today.isoformat()}:\n\n```text\n{figures}\n```\n{end}")
    first, last = text.find(start), text.find(end)
    if first >= 0 and last > first:
        text = text[:first] + body + text[last + len(end):]
    elif first >= 0 or last >= 0:
        raise InputError(f"--results {path}: the section markers of '{name}' are unpaired or out of order")
    else:
        text = text.rstrip("\n") + f"\n\n## bench {name}\n{body}\n"
    write_text_atomic(path, text)
