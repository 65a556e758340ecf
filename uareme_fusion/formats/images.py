"""Colour images as (H, W, 3) uint8 RGB arrays: OpenCV's gray, BGR and BGRA, 8- or 16-bit, converted
the same way for every source (image files, folders, videos, EuRoC, the single-image analyser).

    rgb = read_rgb("photo.jpg", max_pixels=4_000_000)
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..io.images import read_image

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm", ".jp2")
"""File endings read as images wherever a folder or a file is given (lower case)."""
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v", ".mpg", ".mpeg")


def natural_key(path: Path) -> list:
    """Sort key ordering numbers inside names by value: `img2` before `img10`."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def images_in_folder(folder: Path) -> list[Path]:
    """The image files (`IMAGE_SUFFIXES`) directly in `folder`, in natural order; [] when none."""
    return sorted((p for p in Path(folder).iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
                  key=natural_key)


def to_rgb8(image: np.ndarray) -> np.ndarray:
    """An OpenCV image (gray, BGR or BGRA; uint8 or uint16) as (H, W, 3) uint8 RGB."""
    if image.dtype == np.uint16:
        image = (image.astype(np.uint32) * 255 + 32767) // 65535  # full 16-bit range -> 0..255, rounded
        image = image.astype(np.uint8)
    elif image.dtype != np.uint8:
        raise InputError(f"expected an 8- or 16-bit image, got dtype {image.dtype}")
    if image.ndim == 2 or image.shape[2] == 1:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def read_rgb(path: str | Path, max_pixels: int | None = None) -> np.ndarray:
    """An image file as RGB uint8 (grayscale, RGBA and 16-bit converted as the image sources do);
    decoded at reduced size when larger than `max_pixels` (`io.images.read_image`)."""
    try:
        return to_rgb8(read_image(path, cv2.IMREAD_UNCHANGED, max_pixels=max_pixels))
    except InputError as exc:
        if str(path) in str(exc):
            raise
        raise InputError(f"{path}: {exc}") from None
