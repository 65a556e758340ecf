"""Timing helpers shared by the benchmarks."""

from __future__ import annotations

import os
import time
from typing import Callable

import numpy as np


def pin_to_one_core() -> str:
    """Restrict this process (and its BLAS threads) to one CPU core; returns a note for the report."""
    if hasattr(os, "sched_setaffinity"):
        core = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {core})
        return f"pinned to CPU core {core}"
    return "not pinned (no sched_setaffinity on this platform)"


def time_ms(fn: Callable[[], object], repeats: int, warmup: int = 3) -> np.ndarray:
    """Wall-clock milliseconds of `repeats` calls after `warmup` calls."""
    for _ in range(warmup):
        fn()
    out = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        fn()
        out[i] = (time.perf_counter() - t0) * 1e3
    return out


def time_ms_interleaved(fns: dict[str, Callable[[], object]], repeats: int, warmup: int = 3) -> dict[str, np.ndarray]:
    """As `time_ms` for several functions, called in turn within each repeat: a ratio between them
    is not skewed by a change of load on a shared machine during the run."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    out = {name: np.empty(repeats) for name in fns}
    for i in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            out[name][i] = (time.perf_counter() - t0) * 1e3
    return out


def summary(values: np.ndarray) -> str:
    return f"median {np.median(values):7.3f}  p90 {np.percentile(values, 90):7.3f}  min {values.min():7.3f}"
