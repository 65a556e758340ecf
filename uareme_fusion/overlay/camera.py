"""Pinhole intrinsics for drawing: the given K, or one assumed from a horizontal field of view.

Pixel convention (OpenCV): pixel centres sit at integer coordinates, so the image centre of a
W x H image is ((W - 1) / 2, (H - 1) / 2). K maps camera rays (x right, y down, z forward) to
homogeneous pixels: p ~ K @ r.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..pinhole import DEFAULT_FOV_DEG, assumed_K  # noqa: F401  (drawing code takes them from here)


def check_K(K: np.ndarray, name: str = "K") -> np.ndarray:
    """`K` as a float (3, 3) upper-triangular pinhole matrix with positive focal lengths, or an InputError."""
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3):
        raise InputError(f"Expected {name} of shape (3, 3), got {K.shape}")
    if not np.all(np.isfinite(K)):
        raise InputError(f"{name} has non-finite entries: {K.tolist()}")
    if not (K[0, 0] > 0 and K[1, 1] > 0) or np.any(K[[1, 2, 2], [0, 0, 1]] != 0) or K[2, 2] != 1:
        raise InputError(f"{name} is not a pinhole matrix [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0: {K.tolist()}")
    return K


def intrinsics_or_assumed(
    K: np.ndarray | None, height: int, width: int, fov_deg: float = DEFAULT_FOV_DEG
) -> tuple[np.ndarray, bool]:
    """`(K, assumed)`: the given intrinsics (checked) and False, or `assumed_K(height, width, fov_deg)`
    and True when `K` is None. `K` must belong to the `width` x `height` image being drawn on."""
    if K is None:
        return assumed_K(height, width, fov_deg), True
    return check_K(K), False


def assumed_fov_note(fov_deg: float = DEFAULT_FOV_DEG) -> str:
    """The annotation written on overlays whose focal length is assumed, e.g. "assumed FOV 60 deg"."""
    return f"assumed FOV {fov_deg:g} deg"
