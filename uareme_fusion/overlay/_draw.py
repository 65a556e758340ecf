"""Small OpenCV drawing helpers: sub-pixel anti-aliased lines and outlined text on RGB images."""

from __future__ import annotations

import cv2
import numpy as np

SHIFT_BITS = 4
"""Fractional bits for OpenCV's sub-pixel drawing (coordinates are multiplied by 2**SHIFT_BITS)."""
OUTLINE_RGB = (0, 0, 0)


def fixed_point(xy) -> tuple[int, int]:
    """Pixel coordinates (x, y) as OpenCV fixed-point integers for `shift=SHIFT_BITS`."""
    scale = 1 << SHIFT_BITS
    return int(round(float(xy[0]) * scale)), int(round(float(xy[1]) * scale))


def stroke_px(height: int, width: int) -> int:
    """Line thickness in pixels that reads well at this image size (1 px at 240 px, 2 at 480, ...)."""
    return max(1, int(round(min(height, width) / 240)))


def outlined_line(image: np.ndarray, p0, p1, colour_rgb, thickness: int) -> None:
    """An anti-aliased line with a dark outline, drawn in place."""
    a, b = fixed_point(p0), fixed_point(p1)
    cv2.line(image, a, b, OUTLINE_RGB, thickness + 2, cv2.LINE_AA, SHIFT_BITS)
    cv2.line(image, a, b, tuple(int(c) for c in colour_rgb), thickness, cv2.LINE_AA, SHIFT_BITS)


def outlined_text(image: np.ndarray, text: str, origin_xy: tuple[int, int], colour_rgb=(255, 255, 255)) -> None:
    """Anti-aliased text with a dark outline, its baseline starting at `origin_xy`, drawn in place."""
    height, width = image.shape[:2]
    scale = max(0.4, min(height, width) / 600)
    thickness = max(1, int(round(scale * 1.5)))
    x, y = origin_xy
    # The outline is the same text shifted by one pixel: a thicker stroke would also widen the advance.
    for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1), (-1, 0), (1, 0), (0, -1), (0, 1)):
        cv2.putText(image, text, (x + dx, y + dy), cv2.FONT_HERSHEY_SIMPLEX, scale, OUTLINE_RGB, thickness, cv2.LINE_AA)
    cv2.putText(image, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, tuple(int(c) for c in colour_rgb), thickness, cv2.LINE_AA)


def text_height_px(image: np.ndarray) -> int:
    """Height of one line of `outlined_text` on this image, for stacking lines."""
    height, width = image.shape[:2]
    return int(round(30 * max(0.4, min(height, width) / 600)))
