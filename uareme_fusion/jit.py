"""The project's one compiler switch: numba's `njit`, or nothing (pure-numpy reference paths).

`compiled(fn)` compiles `fn` with `numba.njit` (`nogil=True` unless told otherwise) when numba
imports (lazily, at its first call), and returns None otherwise, after one warning line. Callers keep
a pure Python/numpy reference beside each compiled kernel and use it whenever the kernel is None or
fails to compile (`disable`).
`UAREME_NO_JIT=1` in the environment forces the reference paths (tests compare the two).
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path

try:
    if os.environ.get("UAREME_NO_JIT"):
        raise ImportError("UAREME_NO_JIT is set")
    import numba
except Exception as exc:  # noqa: BLE001 -- a broken numba install must not stop the package
    numba = None
    _REASON = f"{type(exc).__name__}: {exc}"
else:
    _REASON = ""

_warned = False


def _warn_once(reason: str) -> None:
    global _warned
    if not _warned and not os.environ.get("UAREME_NO_JIT"):
        _warned = True
        warnings.warn(f"uareme_fusion: compiled kernels unavailable ({reason}); using the numpy reference paths",
                      RuntimeWarning, stacklevel=3)


def available() -> bool:
    """Whether numba imported (kernels may still fail to compile: see `disable`)."""
    return numba is not None


def compiled(fn=None, cache: bool = False, nogil: bool = True, **options):
    """`numba.njit(cache=cache, nogil=nogil, **options)(fn)`, or None without numba (one warning).
    `cache=True` keeps the machine code on disk (numba's `__pycache__` beside the source, or
    `NUMBA_CACHE_DIR`, or a cache folder in the user's home for a read-only install) for kernels
    whose compilation takes a second or more; where none of those is writable, the kernel compiles
    in each process instead. `nogil=False` for a kernel of a few microseconds called often: releasing
    and taking back the GIL costs about half a microsecond a call."""
    def wrap(f):
        if numba is None:
            _warn_once(_REASON)
            return None
        try:
            return numba.njit(cache=cache, nogil=nogil, **options)(f)
        except RuntimeError:  # "cannot cache function ...: no locator available" (nowhere writable)
            if not cache:
                raise
            return numba.njit(cache=False, nogil=nogil, **options)(f)
    return wrap(fn) if fn is not None else wrap


def drop_stale_caches(sources) -> None:
    """numba checks a cached kernel against its own source file only, so kernels that inline
    functions or freeze constants from other modules would load stale machine code after one of
    those changed (a state-buffer layout, say). Deletes the numba cache files (`*.nbi`, `*.nbc`) in the
    `__pycache__` folders beside `sources` (paths of the modules the kernels draw on, their own
    included) that are older than the newest of those sources, so that the kernels compile again.
    Caches elsewhere (`NUMBA_CACHE_DIR`) and unwritable folders are left alone."""
    paths = [Path(s) for s in sources]
    try:
        newest = max(p.stat().st_mtime for p in paths)
    except OSError:
        return
    for folder in {p.parent / "__pycache__" for p in paths}:
        for cached in [*folder.glob("*.nbi"), *folder.glob("*.nbc")]:
            try:
                if cached.stat().st_mtime < newest:
                    cached.unlink()
            except OSError:
                pass


def disable(exc: BaseException) -> None:
    """Report a kernel that failed to compile or run (one warning); the caller falls back."""
    _warn_once(f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")
