"""Summary statistics of per-frame errors, computed here for every report (eval, compare, demo, bench).

`error_stats(values, ("mean", "p95", "max"))` -> `{"mean": ..., "p95": ..., "max": ...}` as plain
floats; the names are those of `STATISTICS`. NaNs are the caller's to drop (pass the scored frames).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np


def rmse(values: np.ndarray) -> float:
    """Root mean square of `values` (any shape), in their unit."""
    return float(np.sqrt(np.mean(np.square(values))))


STATISTICS = {
    "mean": lambda v: float(np.mean(v)),
    "median": lambda v: float(np.median(v)),
    "rmse": rmse,
    "p95": lambda v: float(np.percentile(v, 95)),
    "max": lambda v: float(np.max(v)),
    "min": lambda v: float(np.min(v)),
}
"""Statistic name -> function of a 1-D array, returning a float in the array's unit."""


def error_stats(values: np.ndarray, names: Iterable[str] = ("mean", "median", "rmse", "p95", "max")) -> dict:
    """The statistics `names` (keys of `STATISTICS`) of `values` (N,), as plain floats for JSON."""
    values = np.asarray(values, float).ravel()
    return {name: STATISTICS[name](values) for name in names}
