"""Text tables (TUM lists and trajectories, EuRoC CSV) read with `np.loadtxt`, with errors that name
the file, the line number in the file (1-based, comments and blank lines counted) and the column.
A pipe (FIFO, `<(cat f.csv)`) is read to its end (`io.paths.read_pipe_text`).

    table = read_table(path, ("timestamp [ns]", "w_x", ...), delimiter=",")
    t_ns = table.ints(0); values = table.floats(slice(1, 7))
    table.require_finite(values, "gyro and accel")

Lines starting with `#` and blank lines are skipped; a UTF-8 byte-order mark is accepted; columns
beyond the named ones are ignored.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .paths import is_pipe, read_pipe_text

_MAX_LISTED = 3
"""How many offending lines an error message lists before it counts the rest."""


@dataclass(frozen=True)
class TextTable:
    """The cells of a text table as strings, with the file line number of each row."""

    path: Path
    columns: tuple[str, ...]
    cells: np.ndarray
    """(N, len(columns)) str."""
    line: np.ndarray
    """(N,) int: 1-based line number in the file of each row."""

    def __len__(self) -> int:
        return self.cells.shape[0]

    def floats(self, col: int | slice) -> np.ndarray:
        """Column(s) as float64; `InputError` naming line and column of the first cell that is no number."""
        return self._convert(col, np.float64, "a number")

    def ints(self, col: int) -> np.ndarray:
        """One column as int64; `InputError` naming line and column of the first cell that is no integer."""
        return self._convert(col, np.int64, "an integer")

    def strings(self, col: int) -> list[str]:
        return [str(c) for c in self.cells[:, col]]

    def lines_where(self, bad_rows: np.ndarray) -> str:
        """'lines 4, 9, 12 and 5 more' for a boolean row mask."""
        lines = self.line[np.asarray(bad_rows, bool)]
        text = ", ".join(str(n) for n in lines[:_MAX_LISTED])
        more = len(lines) - _MAX_LISTED
        return f"line{'s' if len(lines) > 1 else ''} {text}" + (f" and {more} more" if more > 0 else "")

    def require_finite(self, values: np.ndarray, what: str) -> None:
        """`InputError` naming the lines whose `values` (N,) or (N, k) hold NaN or infinity."""
        finite = np.isfinite(values)
        bad = ~finite.all(axis=tuple(range(1, finite.ndim))) if finite.ndim > 1 else ~finite
        if bad.any():
            raise InputError(
                f"{self.path}: {int(bad.sum())} row(s) hold a NaN or infinite {what} ({self.lines_where(bad)})"
            )

    def require_increasing(self, t: np.ndarray, what: str = "timestamp") -> None:
        """`InputError` naming the first line whose `t` is not after the previous row's."""
        bad = np.flatnonzero(np.diff(t) <= 0)
        if len(bad):
            i = bad[0] + 1
            raise InputError(
                f"{self.path}: line {self.line[i]}: {what} {self.cells[i, 0]} is not after the previous "
                f"row's {self.cells[i - 1, 0]} (line {self.line[i - 1]}); {len(bad)} such row(s): the file "
                "must be in strictly increasing time order"
            )

    def _convert(self, col, dtype, kind: str) -> np.ndarray:
        cells = self.cells[:, col]
        try:
            return cells.astype(dtype)
        except (ValueError, OverflowError):
            pass
        # Error path only: find the first offending cell to name it.
        cols = range(self.cells.shape[1])[col]
        for j in [cols] if isinstance(cols, int) else cols:
            for i, cell in enumerate(self.cells[:, j]):
                try:
                    np.array([cell]).astype(dtype)
                except (ValueError, OverflowError):
                    raise InputError(
                        f"{self.path}: line {self.line[i]}, column {j + 1} ({self.columns[j]}): "
                        f"cannot read {str(cell)!r} as {kind}"
                    ) from None
        raise AssertionError("unreachable: a conversion failed but no cell fails alone")


def read_table(path: str | Path, columns: tuple[str, ...], delimiter: str | None = None,
               kind: str = "a table") -> TextTable:
    """Read a `delimiter`-separated text table (None: whitespace) with at least `len(columns)`
    columns per row; `InputError` naming the file (and line) if it is missing, not text, or ragged.
    `kind` names the format in messages about columns ("... is not {kind}: ...")."""
    path = Path(path)
    try:
        text = read_pipe_text(path) if is_pipe(path) else path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, expected a text file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except UnicodeDecodeError as exc:
        raise InputError(f"{path}: not a text file (byte {exc.object[exc.start]:#04x} at offset {exc.start} "
                         "is not UTF-8)") from None
    all_lines = text.splitlines()
    keep = [i for i, s in enumerate(all_lines) if s.strip() and not s.lstrip().startswith("#")]
    data = [all_lines[i] for i in keep]
    line = np.array(keep, dtype=int) + 1
    n_cols = len(columns)
    what = f"{n_cols} {'comma' if delimiter == ',' else 'whitespace'}-separated columns ({', '.join(columns)})"
    what = f"{what}, as {kind} has"
    if not data:
        return TextTable(path, columns, np.zeros((0, n_cols), dtype=str), line)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            cells = np.loadtxt(data, dtype=str, delimiter=delimiter, comments="#", ndmin=2)
    except ValueError:
        counts = np.array([len(s.split(delimiter)) for s in data])  # error path: name the ragged line
        i = int(np.flatnonzero(counts != counts[0])[0]) if np.any(counts != counts[0]) else 0
        raise InputError(
            f"{path} is not {kind}: line {line[i]} has {counts[i]} column(s) but line {line[0]} has "
            f"{counts[0]}; expected {what}"
        ) from None
    if cells.shape[1] < n_cols:
        raise InputError(f"{path} is not {kind}: line {line[0]} has {cells.shape[1]} column(s); expected {what}")
    return TextTable(path, columns, cells[:, :n_cols], line)


TEXT_SNIFF_BYTES = 8192
"""How much of a file `is_text_file` and `sniff_delimiter` look at."""


def _head(path: str | Path) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(TEXT_SNIFF_BYTES)


def is_text_file(path: str | Path) -> bool:
    """True when the file's first bytes are UTF-8 text without NUL bytes (a table, not a video)."""
    head = _head(path)
    if not head or b"\x00" in head:
        return False
    for cut in range(4):  # the sniffed block may end inside a multi-byte character
        try:
            head[: len(head) - cut].decode("utf-8")
            return True
        except UnicodeDecodeError:
            continue
    return False


def sniff_delimiter(path: str | Path) -> str | None:
    """',' when the first data line (not a comment, not blank) holds a comma, else None (whitespace)."""
    for line in _head(path).decode("utf-8", errors="replace").splitlines():
        if line.strip() and not line.lstrip().lstrip("\ufeff").startswith("#"):
            return "," if "," in line else None
    return ","
