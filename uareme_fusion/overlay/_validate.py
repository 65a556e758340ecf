"""Input checks shared by the overlay functions; every failure is an `InputError` naming the argument."""

from __future__ import annotations

import numpy as np

from ..errors import InputError


def check_rgb(rgb: np.ndarray, name: str = "rgb") -> np.ndarray:
    """`rgb` as an (H, W, 3) uint8 array, or an InputError saying what was received."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or 0 in rgb.shape:
        raise InputError(f"Expected {name} of shape (H, W, 3), got {rgb.shape}")
    if rgb.dtype != np.uint8:
        raise InputError(f"Expected {name} of dtype uint8, got {rgb.dtype}")
    return rgb


def check_vector3(v: np.ndarray, name: str) -> np.ndarray:
    """A finite, non-zero 3-vector as float64, normalised to unit length."""
    v = np.asarray(v, dtype=float)
    if v.shape != (3,):
        raise InputError(f"Expected {name} of shape (3,), got {v.shape}")
    norm = np.linalg.norm(v)
    if not np.isfinite(norm) or norm == 0.0:
        raise InputError(f"{name} must be finite and non-zero, got {v.tolist()}")
    return v / norm


def check_rotation(R: np.ndarray, name: str) -> np.ndarray:
    """A finite (3, 3) matrix as float64 (orthonormality is the caller's contract, not checked here)."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise InputError(f"Expected {name} of shape (3, 3), got {R.shape}")
    if not np.all(np.isfinite(R)):
        raise InputError(f"{name} has non-finite entries")
    return R
