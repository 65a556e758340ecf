"""The horizon score of the ECD benchmark (Eurasian Cities: the largest vertical distance between the
estimated and the true horizon across the image, over its height), used by `bench horizon` and by the
solver's sky veto (`solver/horizon_estimate.py`)."""

from __future__ import annotations

import numpy as np


def horizon_error(line_est, line_true, height: int, width: int) -> float:
    """Largest vertical distance between two horizon lines a x + b y + c = 0 over x in [0, width - 1],
    divided by `height` (the ECD score); inf when a line is vertical or at infinity."""
    def y_at(line, x):
        a, b, c = line
        return -(a * x + c) / b if abs(b) > 1e-12 else np.inf
    return max(abs(y_at(line_est, x) - y_at(line_true, x)) for x in (0.0, width - 1.0)) / height
