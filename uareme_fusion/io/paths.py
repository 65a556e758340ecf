"""What a path the user gave is, when it is not a regular file or folder, for messages that say so.

    path_kind(Path("loop"))   # 'a symbolic link loop'
    path_kind(Path("/dev/fd/63"))   # 'a pipe (FIFO or process substitution)'
"""

from __future__ import annotations

import errno
import os
import select
import stat
from pathlib import Path

_KINDS = ((stat.S_ISFIFO, "a pipe (FIFO or process substitution)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def path_kind(path: str | Path) -> str | None:
    """'a pipe (FIFO or process substitution)', 'a symbolic link loop', 'a broken symbolic link (to
    X)', a device or socket, 'not accessible (...)'; None for a regular file, a folder or nothing there."""
    path = os.fspath(path)
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "a symbolic link loop"
        if exc.errno == errno.ENOENT and os.path.islink(path):
            return f"a broken symbolic link (to {os.readlink(path)})"
        if exc.errno in (errno.EACCES, errno.EPERM):
            return f"not accessible ({exc.strerror})"
        return None
    for test, kind in _KINDS:
        if test(mode):
            return kind
    return None


def is_pipe(path: str | Path) -> bool:
    """True for a FIFO or a process substitution (`<(cat f.csv)`): readable once, front to back."""
    try:
        return stat.S_ISFIFO(os.stat(path).st_mode)
    except OSError:
        return False


PIPE_WAIT_S = 10.0
"""How long a pipe may stay silent (no writer, no data) before reading it is given up, s."""


def read_pipe_text(path: str | Path, wait_s: float | None = None) -> str:
    """All the text a pipe delivers until its writer closes it (UTF-8, a byte-order mark dropped).

    `InputError` when nothing arrives within `wait_s` (default `PIPE_WAIT_S`; a FIFO nobody writes
    to would otherwise block forever)."""
    from ..errors import InputError

    wait_s = PIPE_WAIT_S if wait_s is None else wait_s
    fd = os.open(os.fspath(path), os.O_RDONLY | os.O_NONBLOCK)
    try:
        ready, _, _ = select.select([fd], [], [], wait_s)
        if not ready:
            raise InputError(f"{path}: is a pipe (FIFO) and nothing was written to it within {wait_s:g} s")
        os.set_blocking(fd, True)
        chunks = []
        while chunk := os.read(fd, 1 << 20):
            chunks.append(chunk)
    finally:
        os.close(fd)
    return b"".join(chunks).decode("utf-8-sig")
