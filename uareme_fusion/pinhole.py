"""Pinhole intrinsics K (3, 3) in pixels, OpenCV convention: `[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`.

    K = pinhole(fx, fy, cx, cy)
    K = intrinsics_from_fov(width=640, height=480, hfov_deg=60.0)
    K = assumed_K(height, width)            # a source without intrinsics: DEFAULT_FOV_DEG
"""

from __future__ import annotations

import math

import numpy as np

from .errors import InputError


def pinhole(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """The (3, 3) pinhole matrix of focal lengths and principal point, pixels."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def intrinsics_from_fov(width: int, height: int, hfov_deg: float,
                        fov_range_deg: tuple[float, float] = (0.0, 180.0)) -> np.ndarray:
    """K (3, 3) of a `width` x `height` pixel camera with horizontal field of view `hfov_deg` over the
    full image width, square pixels and the principal point at the image centre ((W-1)/2, (H-1)/2).

    `InputError` for a size that is not two positive integers, or a field of view outside
    `fov_range_deg` (and always outside the open interval (0, 180))."""
    if not (isinstance(height, (int, np.integer)) and isinstance(width, (int, np.integer)) and height > 0 and width > 0):
        raise InputError(f"Image size must be positive integers, got height={height!r}, width={width!r}")
    lo, hi = fov_range_deg
    if not (lo <= float(hfov_deg) <= hi and 0.0 < float(hfov_deg) < 180.0):
        raise InputError(f"field of view fov_deg must be within {lo:g} to {hi:g} degrees (exclusive of 0 and 180), "
                         f"got {hfov_deg}")
    return centred_K(focal_from_hfov(width, hfov_deg), height, width)


def focal_from_hfov(width: float, hfov_deg: float) -> float:
    """The focal length (in the units of `width`) that spans `hfov_deg` over the full width."""
    return (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)


def centred_K(f_px: float, height: int, width: int) -> np.ndarray:
    """Square pixels, focal `f_px`, principal point at the image centre ((W-1)/2, (H-1)/2)."""
    return pinhole(f_px, f_px, (width - 1) / 2.0, (height - 1) / 2.0)


DEFAULT_FOV_DEG = 60.0
"""Horizontal field of view assumed when a source has no intrinsics (the paper's training FOV)."""


def assumed_K(height: int, width: int, fov_deg: float = DEFAULT_FOV_DEG) -> np.ndarray:
    """K assumed for a `width` x `height` image without intrinsics: `intrinsics_from_fov` with
    horizontal field of view `fov_deg` (arguments in the (height, width) order of image shapes)."""
    return intrinsics_from_fov(width, height, fov_deg)
