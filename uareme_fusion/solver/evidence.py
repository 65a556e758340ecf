"""Whether an image holds any evidence for image-based cues, and the wide covariance of a frame without.

A network's normals on a black, blank or badly blurred image are a guess of what rooms look like, not a
measurement, however confident its kappa (a black 640x480 frame gave a tilt std of 1.4 deg). So a frame
whose image has almost no gradient, `textured_fraction` below `NO_EVIDENCE_TEXTURED_FRACTION` at 160 px
wide or at its own pixels (`SHARP_WIDTH_PX`: blur), keeps
its rotation but reports the solver's capped variance on every axis and says why (`VisualRotation.reason`).
Depth normals need no texture and are not judged here.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from ..types import VisualRotation

EVIDENCE_WIDTH_PX = 160
"""The image is judged at this width (area-averaged: sensor noise averages out, edges stay)."""
MIN_GRADIENT_DN = 8.0
"""A pixel is textured where the grey gradient exceeds this (8-bit digital numbers per pixel at
`EVIDENCE_WIDTH_PX`): above sensor noise (Gaussian noise of 8 DN on a blank image reaches none)."""
NO_EVIDENCE_TEXTURED_FRACTION = 0.02
"""Below this fraction of textured pixels a frame has no image evidence. Real frames (every 10th of TUM
fr1 rpy train, ICSL, EuRoC cam0, ICL kt3, every ECD photo, every 5th Horizon-UAV photo): 0.06 at least,
median 0.16-0.40; a black or uniform image 0.000, one blurred by a 25 px Gaussian 0.000 (8 px: 0.09)."""
SHARP_WIDTH_PX = 640
"""... and again at the image's own pixels (area-averaged to this width when wider), where blur shows: real
frames (every 5th of TUM fr1 rpy train, ICSL corridor, EuRoC cam0, ICL kt3) 0.058 at least (kt3), 0.080 on TUM
(its motion blur included); the same frames blurred by a 31 px box 0.008 at most (0.163 at 160 px wide)."""


def textured_fraction(image: np.ndarray, width_px: int = EVIDENCE_WIDTH_PX) -> float:
    """Fraction of pixels whose grey gradient exceeds `MIN_GRADIENT_DN` at `width_px` wide;
    `image` uint8 RGB (H, W, 3) or grey (H, W)."""
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if grey.shape[1] == width_px:
        small = grey.astype(np.float32)
    else:
        height = max(int(round(grey.shape[0] * width_px / max(grey.shape[1], 1))), 3)
        small = cv2.resize(grey, (width_px, height), interpolation=cv2.INTER_AREA).astype(np.float32)
    gx = cv2.Sobel(small, cv2.CV_32F, 1, 0, ksize=3)  # Sobel's weights sum to 8 per unit slope
    gy = cv2.Sobel(small, cv2.CV_32F, 0, 1, ksize=3)
    return float(np.count_nonzero(gx * gx + gy * gy > (8.0 * MIN_GRADIENT_DN) ** 2) / gx.size)


def no_evidence_reason(image: np.ndarray | None, fraction: float | None = None) -> str:
    """Why `image` holds no evidence for image-based cues ("" when it does, or when there is no image);
    `fraction`: its `textured_fraction` when already measured (`NormalMap.textured_fraction`)."""
    if image is None:
        return ""
    fraction = textured_fraction(image) if fraction is None else fraction
    if fraction < NO_EVIDENCE_TEXTURED_FRACTION:
        return (f"no image evidence: {100 * fraction:.1f} % of the image is textured, under "
                f"{100 * NO_EVIDENCE_TEXTURED_FRACTION:.0f} % (black, blank or blurred)")
    width = min(image.shape[1], SHARP_WIDTH_PX)
    sharp = textured_fraction(image, width)
    if sharp < NO_EVIDENCE_TEXTURED_FRACTION:
        return (f"no image evidence: {100 * sharp:.1f} % of the image is textured at {width} px wide, under "
                f"{100 * NO_EVIDENCE_TEXTURED_FRACTION:.0f} % (blurred)")
    return ""


def without_evidence(visual: VisualRotation, reason: str, max_variance_rad2: float) -> VisualRotation:
    """`visual` with `max_variance_rad2` on every axis and `reason` (rad^2, right perturbation of R_cm)."""
    return dataclasses.replace(visual, cov=max_variance_rad2 * np.eye(3), reason=reason, quality=0.0)
