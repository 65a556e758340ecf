"""Shared test fixtures, and the compiled kernels built once, by one xdist worker at a time."""

import contextlib
import gc
import hashlib
import importlib.util
import os
import sys
import tempfile
from pathlib import Path


def _one_thread_per_worker() -> None:
    """xdist runs one worker per core (pyproject addopts), so a worker's numpy, torch, numba or OpenCV
    thread pool only oversubscribes the cores: 2 workers x 2 threads measured 61.5 s wall / 112 s CPU,
    one thread each 56.6 s / 102 s. Set before numpy is imported; workers and the CLI processes
    inherit it; a value the user set wins."""
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
                 "OPENCV_FOR_THREADS_NUM"):
        os.environ.setdefault(name, "1")


_one_thread_per_worker()

import numpy as np  # noqa: E402  (after the thread counts are set)
import pytest  # noqa: E402


def _bytecode_cached() -> None:
    """Let this process and its children (xdist's workers, the CLI processes) write `.pyc` files even
    where PYTHONDONTWRITEBYTECODE is set (it is on this machine): otherwise each worker compiles the
    package and re-rewrites all 60 test modules' asserts on every run (collection 7.7 s -> 5.3 s of one
    core per worker measured with them cached). The files go to the `__pycache__` folders git ignores."""
    sys.dont_write_bytecode = False
    os.environ.pop("PYTHONDONTWRITEBYTECODE", None)


_bytecode_cached()


def _temporary_files_in_memory() -> None:
    """The tests write many small files through the package's atomic writes, each ending in fsync:
    about 1,200 fsyncs a run, 5-6 ms each on this machine's disk (3-4 s of the suite's wall time) and
    none on a tmpfs. Where TMPDIR is unset and /dev/shm is a writable tmpfs, pytest's `tmp_path`
    folders (xdist's workers and the CLI processes inherit TMPDIR) live there; a few MB a run."""
    shm = Path("/dev/shm")
    if "TMPDIR" not in os.environ and shm.is_dir() and os.access(shm, os.W_OK | os.X_OK):
        os.environ["TMPDIR"] = str(shm)
        tempfile.tempdir = None  # gettempdir() reads TMPDIR again


_temporary_files_in_memory()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """`../shared/data` beside the repository; skips the test when it is absent."""
    from helpers import shared_data_or_skip

    return shared_data_or_skip()


def pytest_collection_modifyitems(items):
    """The test files holding a test marked `slow` (seconds of one core each: subprocesses, long
    statistical checks) run before all others. xdist (pyproject: `--dist loadfile
    --no-loadscope-reorder`) hands each worker whole files in collection order, so the long files start
    first and the short ones even out the workers' ends (its default order, files with most tests
    first, left the 5 s demo file to the end of one worker)."""
    slow_files = {item.path for item in items if item.get_closest_marker("slow")}
    items.sort(key=lambda item: item.path not in slow_files)  # stable: files stay whole and in order


def pytest_collection_finish(session):
    """Move everything alive after collection (the package, numpy, scipy, torch, ...: about 365,000
    objects) out of the garbage collector's reach: each full collection then skips them, those Python
    starts on its own during the run and the five pytest runs at the end (0.17 s each before,
    0.00 s after, measured)."""
    gc.freeze()


def pytest_configure(config):
    """In each of xdist's workers (pyproject's addopts: `-n auto`), load the numba kernels from their
    on-disk cache, or compile them into it, holding a lock: on a fresh checkout one worker compiles the
    EKF kernels (20-40 s of one core: 42 s measured on a busy 2-core machine) while the other waits,
    then loads them in a fraction of a second. The process that starts the workers imports nothing of
    the package (that would only delay the workers' start); a run in one process compiles on first use."""
    if hasattr(config, "workerinput"):
        with _kernel_cache_lock():
            warm_compiled_kernels()


@contextlib.contextmanager
def _kernel_cache_lock():
    """An exclusive lock for this checkout's kernel cache (a file in the temporary folder named after
    the package's path); no lock where the platform has no `fcntl`."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    package = importlib.util.find_spec("uareme_fusion").submodule_search_locations[0]
    name = f"uareme-fusion-kernels-{hashlib.sha1(package.encode()).hexdigest()[:12]}.lock"
    with open(Path(tempfile.gettempdir()) / name, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def warm_compiled_kernels() -> None:
    """Call each compiled kernel once with the argument types the package uses (numba's cache keys):
    the EKF's (`load_kernels`: IMU-only in bulk and with frames) and the float32/float64 normal moments."""
    from uareme_fusion.backends.mekf.filter import load_kernels
    from uareme_fusion.solver.moments import fused_moments

    for dtype in (np.float32, np.float64):
        fused_moments(np.ones((4, 3), dtype), np.ones(4, dtype))
    for with_frames in (False, True):
        load_kernels(with_frames)
