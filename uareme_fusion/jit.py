"""The project's one compiler switch: numba's `njit`, or nothing (plain Python / numpy paths).

`compiled(fn)` compiles `fn` with `numba.njit` (`nogil=True` unless told otherwise) when numba
imports (lazily, at its first call), and returns None otherwise, after one warning line. Callers then
run the same function as plain Python (the EKF's kernels, `backends/mekf/kernels.py`) or a numpy
reference beside it (the solver's moments), also when a kernel fails to compile (`disable`).
`Kernel(fn, ...)` holds such a compiled function with its fallback state: calling it runs the kernel, or
answers `FALLBACK` when there is none or it has failed once (then never again; one warning), and the
caller takes its reference path. `UAREME_NO_JIT=1` in the environment forces the plain paths (tests
compare the two).
"""

from __future__ import annotations

import hashlib
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
        warnings.warn(f"uareme_fusion: compiled kernels unavailable ({reason}); running them as plain Python",
                      RuntimeWarning, stacklevel=3)


def available() -> bool:
    """Whether numba imported (kernels may still fail to compile: see `disable`)."""
    return numba is not None


def compiled(fn=None, cache: bool = False, nogil: bool = True, sources=None, **options):
    """`numba.njit(cache=cache, nogil=nogil, **options)(fn)`, or None without numba (one warning).
    `cache=True` keeps the machine code on disk (numba's `__pycache__` beside the source, or
    `NUMBA_CACHE_DIR`, or a cache folder in the user's home for a read-only install) for kernels
    whose compilation takes a second or more; where none of those is writable, the kernel compiles
    in each process instead. numba checks a cached kernel against its own source file only; with
    `sources` (paths of every module the kernel inlines functions or freezes constants from, its own
    included) the cache is keyed by their contents instead (`key_cache_by_sources`). `nogil=False`
    for a kernel of a few microseconds called often: releasing and taking back the GIL costs about
    half a microsecond a call."""
    def wrap(f):
        if numba is None:
            _warn_once(_REASON)
            return None
        try:
            kernel = numba.njit(cache=cache, nogil=nogil, **options)(f)
        except RuntimeError:  # "cannot cache function ...: no locator available" (nowhere writable)
            if not cache:
                raise
            return numba.njit(cache=False, nogil=nogil, **options)(f)
        if cache and sources:
            key_cache_by_sources(kernel, sources)
        return kernel
    return wrap(fn) if fn is not None else wrap


_STAMPS: dict[tuple, str] = {}


def sources_stamp(sources) -> str:
    """A digest of the contents of the files `sources` (once per process and set of files)."""
    key = tuple(sorted(str(s) for s in sources))
    stamp = _STAMPS.get(key)
    if stamp is None:
        digest = hashlib.sha256()
        for path in key:
            digest.update(path.encode())
            try:
                digest.update(Path(path).read_bytes())
            except OSError:
                pass
        stamp = _STAMPS[key] = digest.hexdigest()
    return stamp


def key_cache_by_sources(kernel, sources) -> None:
    """Key the disk cache of a numba dispatcher `kernel` by the contents of `sources` instead of its own
    file's time stamp: numba keeps that stamp in the cache's index and ignores (then overwrites) an
    index whose stamp differs, so an edit to any of `sources` (a state-buffer layout, a model the
    kernel inlines) makes the kernel compile again; no file is deleted. Left as numba keys it where
    this numba keeps its cache otherwise (the attribute is not there)."""
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    if cache_file is not None and hasattr(cache_file, "_source_stamp"):
        cache_file._source_stamp = sources_stamp(sources)


def disable(exc: BaseException) -> None:
    """Report a kernel that failed to compile or run (one warning); the caller falls back."""
    _warn_once(f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}")


FALLBACK = object()
"""What a `Kernel` call answers when the caller must take its own reference path."""


class Kernel:
    """`compiled(fn, **options)` and its fallback state: `kernel(*args)` is the kernel's result, or
    `FALLBACK` without numba or once the kernel has failed to compile or run (`disable`: one warning, and
    it is not tried again). `bool(kernel)`: whether it may run (before building its output arrays)."""

    def __init__(self, fn, **options):
        self.dispatcher = compiled(fn, **options)

    def __bool__(self) -> bool:
        return self.dispatcher is not None

    def __call__(self, *args):
        if self.dispatcher is None:
            return FALLBACK
        try:
            return self.dispatcher(*args)
        except Exception as exc:  # noqa: BLE001 -- a compiler or loader failure falls back to the reference
            disable(exc)
            self.dispatcher = None
            return FALLBACK
