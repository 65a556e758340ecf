"""Ground segmentation from a normal map and the up vector (the paper's Section 4.2 application).

A floor's normal in the camera frame points along world up, i.e. along `up_c` (OpenCV camera frame:
x right, y down, z forward; `up_c` is `Estimate.up_c`). Confidence weighting:
- hard mask: a pixel is ground when its normal is within `threshold_deg` of `up_c` AND its kappa is
  at least `min_kappa` (kappa 0, "ignore this pixel", never counts; nor do zero or non-finite normals);
- soft score in [0, 1]: `max(cos angle, 0) * kappa / (kappa + kappa_half)`, how ground-like and how
  trusted a pixel is (kappa_half is the kappa at which trust is one half), for display or downstream
  weighting. The mask is not derived from the score, so a threshold in degrees keeps its meaning.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from ..errors import InputError
from ..types import NormalMap
from ._validate import check_rgb, check_vector3

GROUND_RGB = (0, 255, 0)
"""The paper highlights ground pixels in green."""
DEFAULT_MIN_KAPPA = 0.5
"""Below this kappa a normal's angular spread is over a radian (kappa ~ 1 / angular variance): not
usable. The simulator's inliers carry kappa 1 and its outliers 0.1."""
DEFAULT_KAPPA_HALF = 1.0


def ground_mask(
    normal_map: NormalMap,
    up_c: np.ndarray,
    threshold_deg: float = 15.0,
    min_kappa: float = DEFAULT_MIN_KAPPA,
    kappa_half: float = DEFAULT_KAPPA_HALF,
) -> tuple[np.ndarray, np.ndarray]:
    """`(mask, score)` for a normal map (H, W): `mask` bool, True on ground pixels; `score` float32
    soft ground score in [0, 1]; both as defined in the module docstring."""
    normals = np.asarray(normal_map.normals)
    kappa = np.asarray(normal_map.kappa)
    if normals.ndim != 3 or normals.shape[2] != 3:
        raise InputError(f"Expected normals of shape (H, W, 3), got {normals.shape}")
    if kappa.shape != normals.shape[:2]:
        raise InputError(f"Expected kappa of shape {normals.shape[:2]} to match the normals, got {kappa.shape}")
    if not 0.0 < threshold_deg < 90.0:
        raise InputError(f"threshold_deg must be in (0, 90) degrees, got {threshold_deg}")
    if not (min_kappa >= 0.0 and kappa_half > 0.0):
        raise InputError(f"min_kappa must be >= 0 and kappa_half > 0, got {min_kappa} and {kappa_half}")
    up_c = check_vector3(up_c, "up_c").astype(np.float32)

    length = np.linalg.norm(normals, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_angle = (normals @ up_c) / length
        trust = kappa / (kappa + np.float32(kappa_half))
    usable = np.isfinite(cos_angle) & (length > 0) & np.isfinite(kappa) & (kappa > 0)
    mask = usable & (cos_angle >= math.cos(math.radians(threshold_deg))) & (kappa >= min_kappa)
    score = np.where(usable, np.clip(cos_angle, 0.0, 1.0) * trust, 0.0).astype(np.float32)
    return mask, score


def draw_ground(
    rgb: np.ndarray,
    mask: np.ndarray,
    colour_rgb: tuple[int, int, int] = GROUND_RGB,
    alpha: float = 0.5,
) -> np.ndarray:
    """A copy of `rgb` (H, W, 3) uint8 with `colour_rgb` blended in at opacity `alpha` where `mask`
    is True. `mask` may also be float weights in [0, 1] (e.g. the soft score), blended at
    `alpha * weight`. A mask of another size (normals at a lower resolution) is resized to the image."""
    image = check_rgb(rgb)
    mask = np.asarray(mask)
    if mask.ndim != 2 or 0 in mask.shape:
        raise InputError(f"Expected a mask of shape (H, W), got {mask.shape}")
    if not 0.0 <= alpha <= 1.0:
        raise InputError(f"alpha must be in [0, 1], got {alpha}")
    height, width = image.shape[:2]
    weight = mask.astype(np.float32)
    if not np.all(np.isfinite(weight)) or weight.min() < 0.0 or weight.max() > 1.0:
        raise InputError("Expected mask weights in [0, 1]")
    if weight.shape != (height, width):
        interpolation = cv2.INTER_NEAREST if mask.dtype == bool else cv2.INTER_LINEAR
        weight = cv2.resize(weight, (width, height), interpolation=interpolation)
    weight *= np.float32(alpha)
    colour_image = np.empty_like(image)
    colour_image[:] = colour_rgb
    return cv2.blendLinear(np.ascontiguousarray(image), colour_image, 1.0 - weight, weight)
