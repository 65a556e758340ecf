"""Photos turned by 90, 180 or 270 deg (issue 26 bad input): the turned image, its labelled horizon turned
alike, and one verdict per answer: right (horizon within the ECD tolerance, up on the sky side), declined
(`horizon_known` false), or confidently wrong.

A turn is `pipeline.turned_photo.turned_photo` (clockwise), a line goes with its pixel map (`quarter_turn`).
"""

from __future__ import annotations

import numpy as np

from ..pipeline.turned_photo import mapped_line, quarter_turn
from ..scoring.horizon import horizon_error
from .horizon_uav import PASS_ERROR_FRACTION, PASS_ROLL_DEG, roll_error_deg

QUARTERS = (1, 2, 3)
"""The turns scored: 90, 180 and 270 deg clockwise."""


def turned_line(line, height: int, width: int, quarters: int) -> np.ndarray:
    """The image line `line` ([a, b, c], pixels of a `height` x `width` image) in the photo turned clockwise
    by `quarters` x 90 deg, [a, b] unit, its positive side kept."""
    return mapped_line(line, quarter_turn(height, width, quarters)[0])


def sky_side_up(line) -> np.ndarray:
    """An upright photo's labelled horizon signed so that it is positive on the sky side (image up, -y)."""
    line = np.asarray(line, float)
    return -line if line[1] > 0 else line


def verdict(known: bool, line_est, truth, height: int, width: int, quarters: int = 0) -> dict:
    """"declined", "right" (ECD error < `PASS_ERROR_FRACTION`, roll < `PASS_ROLL_DEG`, the sky on the
    positive side) or "wrong", with the errors: `line_est` in the photo turned by `quarters`, `truth` in the
    upright `height` x `width` photo, scored there (the ECD score, a vertical distance, means nothing for the
    near-vertical horizon of a photo on its side)."""
    if not known:
        return {"verdict": "declined", "error": None, "roll_deg": None, "sky_side": None}
    line = mapped_line(line_est, np.linalg.inv(quarter_turn(height, width, quarters)[0]))
    error = horizon_error(line, truth, height, width)
    roll = roll_error_deg(line, truth)
    sky_side = bool(np.dot(line[:2], np.asarray(truth, float)[:2]) > 0)
    right = error < PASS_ERROR_FRACTION and roll < PASS_ROLL_DEG and sky_side
    return {"verdict": "right" if right else "wrong", "error": error, "roll_deg": roll, "sky_side": sky_side}
