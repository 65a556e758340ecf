"""Output files that are never half-written, never written through a link, never the input.

    write_bytes_atomic(out / "summary.json", text.encode())    # temp file + os.replace
    write_image_atomic(out / "masks" / "000001.png", mask)      # cv2.imencode, then as above
    rows = RowFile(out / "trajectory.tum"); rows.write_row("0.0 0 0 0 0 0 0 1\n")  # streamed

- Whole files are written to a hidden temporary file in the same folder and renamed into place
  (`os.replace`) when complete, so a crash, a kill or a full disk never leaves a truncated file
  under the final name (an older file of that name stays as it was).
- Streamed tables (`RowFile`) grow row by row under their final name, so a run that stops leaves
  every row written so far; each row goes out in whole `os.write` calls and, when the disk fills in
  the middle of one, the file is truncated back to the last complete row.
- A symbolic link where the tool would create a file is refused (`InputError`), so a link planted
  in an output folder cannot redirect a write onto another file; `O_NOFOLLOW` makes the check race-free
  for streamed files.
- An existing character device or pipe (`--json /dev/stdout`) is written in place (`write_stream`).
- A failure to write (disk full, quota, I/O error, read-only file system) is an `OutputError` naming
  the file; the CLI reports it on one line and exits 1 (a failing environment, not a user mistake).
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, OutputError

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_CLOEXEC = getattr(os, "O_CLOEXEC", 0)


ENVIRONMENT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EIO, errno.EROFS, errno.EFBIG})
"""OSErrors of a failing environment (`OutputError`, exit 1) rather than of a path the user got wrong
(permission denied, no such folder: `InputError`, exit 2)."""


def cannot_write(path: Path, exc: OSError, detail: str = "") -> InputError | OutputError:
    """The error for an `OSError` met while writing `path`: `OutputError` for a full disk or a failing
    device, `InputError` for a path the user can fix."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    error = OutputError if exc.errno in ENVIRONMENT_ERRNOS else InputError
    return error(f"{path}: could not be written ({reason}){detail}")


def refuse_link(path: Path) -> None:
    """`InputError` when `path` is a symbolic link (the tool writes its own files, never through links)."""
    if os.path.islink(path):
        raise InputError(f"{path}: is a symbolic link (to {os.readlink(path)}); refusing to write through it "
                         "(remove the link or choose another --out)")


def refuse_input_as_output(output: Path, inputs: Iterable[str | Path | None]) -> None:
    """`InputError` when `output` names one of `inputs` (the same file or the same real path)."""
    for source in inputs:
        if source is None:
            continue
        source = Path(str(source)).expanduser()
        same = os.path.realpath(output) == os.path.realpath(source)
        if not same and output.exists() and source.exists():
            try:
                same = os.path.samefile(output, source)
            except OSError:
                same = False
        if same:
            raise InputError(f"--out {output} is the input {source}; writing it would destroy the input "
                             "(choose another output name)")


def temporary_sibling(path: Path) -> Path:
    """A new empty hidden file beside `path` (same folder and suffix) for an atomic write."""
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".partial{path.suffix}", dir=path.parent)
    except OSError as exc:
        raise cannot_write(path, exc) from None
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(name, 0o666 & ~umask)  # as open() would create it (mkstemp makes it private)
    return Path(name)


def publish(tmp: Path, path: Path) -> None:
    """Rename the complete `tmp` to `path` (atomic on one file system); `tmp` is removed on failure."""
    try:
        refuse_link(path)
        os.replace(tmp, path)
    except BaseException as exc:
        discard(tmp)
        if isinstance(exc, OSError):
            raise cannot_write(path, exc) from None
        raise


def discard(tmp: Path) -> None:
    try:
        os.unlink(tmp)
    except OSError:
        pass


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write `data` to `path` all at once: a temporary file beside it, synced, then renamed."""
    path = Path(path)
    refuse_link(path)
    if is_stream(path):
        return write_stream(path, data)
    tmp = temporary_sibling(path)
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
    except BaseException as exc:
        discard(tmp)
        if isinstance(exc, OSError):
            raise cannot_write(path, exc) from None
        raise
    publish(tmp, path)


def is_stream(path: Path) -> bool:
    """True for an existing character device or pipe (`/dev/stdout`, `/dev/full`, a FIFO): written in
    place, never replaced by a renamed file (as root that would replace the device node itself)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode)


def write_stream(path: Path, data: bytes) -> None:
    """Write `data` into a device or pipe; a refused write (`/dev/full`: no space) is an `OutputError`."""
    try:
        with open(path, "wb") as fh:
            fh.write(data)
            fh.flush()
    except OSError as exc:
        raise cannot_write(path, exc) from None


def write_text_atomic(path: Path, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_image_atomic(path: Path, image: np.ndarray) -> None:
    """`cv2.imwrite` (BGR order, format from the suffix), encoded in memory and written atomically."""
    ok, encoded = cv2.imencode(Path(path).suffix or ".png", image)
    if not ok:
        raise OutputError(f"{path}: OpenCV cannot encode this image")
    write_bytes_atomic(path, encoded.tobytes())


def write_npz_atomic(path: Path, compressed: bool = True, **arrays: np.ndarray) -> None:
    """`np.savez(_compressed)` written atomically (an interrupted write never leaves a truncated .npz)."""
    import io

    buffer = io.BytesIO()
    (np.savez_compressed if compressed else np.savez)(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


def save_figure_atomic(path: Path, figure, **savefig_options) -> None:
    """`figure.savefig(path)` (matplotlib; format from the suffix) rendered in memory, written atomically."""
    import io

    buffer = io.BytesIO()
    figure.savefig(buffer, format=Path(path).suffix.lstrip(".") or "png", **savefig_options)
    write_bytes_atomic(path, buffer.getvalue())


class RowFile:
    """A text file streamed row by row under its final name; see the module docstring.

    Opened with `O_NOFOLLOW` (a link in its place is refused), truncated, written with whole rows
    only; `write_row` raises `OutputError` (after truncating back to the last complete row) when
    the disk refuses a row, and every later write is refused the same way.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self.rows = 0
        self._complete = self._last = self._last_rows = 0
        self._fd: int | None = None
        self.failed: InputError | OutputError | None = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            refuse_link(self.path)
            self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | _NOFOLLOW | _CLOEXEC, 0o666)
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                refuse_link(self.path)
            raise cannot_write(self.path, exc) from None
        if not stat.S_ISREG(os.fstat(self._fd).st_mode):
            os.close(self._fd)
            self._fd = None
            raise InputError(f"{self.path}: exists and is not a regular file; refusing to write to it")

    def write_row(self, text: str, counts: bool | int = True) -> None:
        """Append `text` (one or more whole lines); `counts` False for a header, or how many rows
        `text` holds when it holds several (written, and taken back, together)."""
        if self.failed is not None:
            raise self.failed
        encoded = text.encode("utf-8")
        data = memoryview(encoded)
        try:
            while len(data):
                data = data[os.write(self._fd, data):]
        except OSError as exc:
            self._truncate_to_complete()
            self.failed = cannot_write(self.path, exc, f"; kept its {self.rows} complete row(s)")
            raise self.failed from None
        self._last = self._complete
        self._complete += len(encoded)
        self._last_rows = int(counts)
        self.rows += self._last_rows

    def drop_last_row(self) -> None:
        """Remove the row(s) written last (another file of the same results could not be written)."""
        if self._fd is not None and self._complete > self._last and self.rows > 0:
            self._complete = self._last
            self.rows -= self._last_rows
            self._truncate_to_complete()

    def _truncate_to_complete(self) -> None:
        try:
            os.ftruncate(self._fd, self._complete)
        except OSError:
            pass

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


class ReservedFile:
    """A small file written whole at the end of a run, whose disk space is taken at the start.

    The start writes `placeholder` padded with spaces to `reserve_bytes` (JSON and YAML readers skip
    the padding). `write` then replaces it atomically; when the disk is full by then, the text is
    written over the reserved bytes in place instead (shrinking a file never needs space)."""

    def __init__(self, path: Path, placeholder: str, reserve_bytes: int = 8192):
        self.path, self.reserve_bytes = Path(path), int(reserve_bytes)
        data = placeholder.encode("utf-8")
        write_bytes_atomic(self.path, data + b" " * max(self.reserve_bytes - len(data), 0))

    def write(self, text: str) -> None:
        data = text.encode("utf-8")
        try:
            write_bytes_atomic(self.path, data)
        except OutputError:
            if len(data) > self.reserve_bytes:
                raise
            self._overwrite_in_place(data)

    def _overwrite_in_place(self, data: bytes) -> None:
        try:
            fd = os.open(self.path, os.O_WRONLY | _NOFOLLOW | _CLOEXEC)
        except OSError as exc:
            raise cannot_write(self.path, exc) from None
        try:
            os.pwrite(fd, data, 0)
            os.ftruncate(fd, len(data))
            os.fsync(fd)
        except OSError as exc:
            raise cannot_write(self.path, exc) from None
        finally:
            os.close(fd)
