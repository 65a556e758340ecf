"""16-bit depth PNGs: one channel, uint16, `units_per_m` stored units per metre, 0 = no depth.

    depth_m = read_depth_png(path, ICL_NUIM_DEPTH_UNIT_M)    # float32 metres
    png, n_dropped = depth_png_units(depth_m, TUM_DEPTH_SCALE)  # uint16 to write (0 = no depth)

Units in use: TUM RGB-D, ICL-NUIM and the simulator store 1/5000 m (`TUM_DEPTH_SCALE`); Asus Xtion,
Kinect v2, OAK, the ICSL corridor and this project's recordings store millimetres
(`MILLIMETRE_DEPTH_SCALE`).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..io.images import read_image

TUM_DEPTH_SCALE = 5000.0
"""Depth PNG units per metre in TUM RGB-D, ICL-NUIM and the simulator's output."""
MILLIMETRE_DEPTH_SCALE = 1000.0
"""Depth PNG units per metre of millimetre depth (Xtion, Kinect v2, OAK, ICSL, recordings)."""
ICL_NUIM_DEPTH_UNIT_M = 1.0 / TUM_DEPTH_SCALE
"""ICL-NUIM and TUM RGB-D store depth PNGs in units of 1/5000 m."""
MILLIMETRE_DEPTH_UNIT_M = 1.0 / MILLIMETRE_DEPTH_SCALE
"""Asus Xtion / Kinect v2 / OAK / ICSL corridor depth PNGs are in millimetres."""


def read_depth_png(path, unit_m: float, expected_shape: tuple[int, int] | None = None) -> np.ndarray:
    """A 16-bit single-channel depth PNG as float32 metres (0 where missing).

    `unit_m`: metres per stored unit (`ICL_NUIM_DEPTH_UNIT_M`, `MILLIMETRE_DEPTH_UNIT_M`).
    Raises `InputError` naming the file for a missing or unreadable file, a wrong dtype or channel
    count, or a size other than `expected_shape` (H, W).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: depth image not found")
    if not (np.isfinite(unit_m) and unit_m > 0):
        raise InputError(f"{path}: depth unit must be > 0 metres, got {unit_m}")
    raw = read_image(path, cv2.IMREAD_UNCHANGED, what="a 16-bit depth PNG")
    if raw.ndim != 2:
        raise InputError(f"{path}: expected a single-channel depth image, got shape {raw.shape}")
    if raw.dtype != np.uint16:
        raise InputError(f"{path}: expected 16-bit depth (uint16), got {raw.dtype}")
    if expected_shape is not None and raw.shape != tuple(expected_shape):
        raise InputError(f"{path}: expected depth of size {tuple(expected_shape)} (H, W), got {raw.shape}")
    return raw.astype(np.float32) * np.float32(unit_m)


def depth_png_units(depth_m: np.ndarray, units_per_m: float, far: str = "clip") -> tuple[np.ndarray, int]:
    """Depth (H, W) in metres (0 = none) -> (uint16 stored units, number of pixels stored as 0).

    Non-finite and negative depth is stored as 0 (no depth) and counted; depth beyond 65535 units is
    clipped to 65535 (`far="clip"`) or stored as 0 and counted (`far="drop"`)."""
    units = np.asarray(depth_m) * units_per_m  # in the input's precision (float32 depth rounds as float32)
    bad = ~np.isfinite(units) | (units < 0)
    if far == "drop":
        bad |= units > 65535.49
    elif far != "clip":
        raise ValueError(f"far must be 'clip' or 'drop', got {far!r}")
    png = np.clip(np.rint(np.where(bad, 0.0, units)), 0, 65535).astype(np.uint16)
    return png, int(bad.sum())
