"""One call for the overlay the paper shows: horizon, Manhattan axes and the assumed-FOV note."""

from __future__ import annotations

import numpy as np

from ._validate import check_rgb
from .camera import DEFAULT_FOV_DEG, assumed_fov_note, intrinsics_or_assumed
from .horizon import draw_horizon, draw_manhattan_axes


def draw_overlay(
    rgb: np.ndarray,
    up_c: np.ndarray,
    R_cm: np.ndarray | None = None,
    K: np.ndarray | None = None,
    fov_deg: float = DEFAULT_FOV_DEG,
    std_px: float | None = None,
    known: bool = True,
) -> np.ndarray:
    """A copy of `rgb` (H, W, 3) uint8 with the horizon of `up_c` (world up in the OpenCV camera
    frame) and, when `R_cm` (Manhattan to camera) is given, the Manhattan axes. `K` (pixels, for
    this image size) or, when None, a pinhole with horizontal FOV `fov_deg`, noted on the image;
    `std_px` and `known` as `draw_horizon` (a +-1 std band; no line when the horizon is not known)."""
    height, width = check_rgb(rgb).shape[:2]
    K, assumed = intrinsics_or_assumed(K, height, width, fov_deg)
    image = draw_horizon(rgb, up_c, K, fov_note=assumed_fov_note(fov_deg) if assumed else None, std_px=std_px,
                         known=known)
    return image if R_cm is None else draw_manhattan_axes(image, R_cm, K)
