"""A single image, a folder of images or a glob, as a stream of frames.

    ImageSource("frames/")            # every image file in the folder, natural order (2.png before 10.png)
    ImageSource("shots/*.jpg", fps=10)

Timestamps (s): with `fps` given, `index / fps`. Otherwise from the file names when every stem is a
number: names with a decimal point are seconds (`1305031102.175304.png`, TUM style), integers of 16
or more digits are nanoseconds (EuRoC), smaller integers are frame numbers at 30 fps (`17.png` ->
17 / 30 s). Any other names: `index / 30`. Images are converted to RGB uint8 (grayscale, RGBA and
16-bit included). A listed file that is no image OpenCV reads is refused at open (`InputError` naming
it); one that fails to decode mid-stream raises `SourceError` naming it.
"""

from __future__ import annotations

import glob as globlib
import re
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.io.images import read_image
from uareme_fusion.types import Frame

from .base import Source, SourceInfo
from .video import to_rgb8

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm", ".jp2")
DEFAULT_FPS = 30.0
NANOSECOND_DIGITS = 16
"""Integer file names with at least this many digits are nanosecond timestamps."""
_NUMBER = re.compile(r"^\d+(\.\d+)?$")


def natural_key(path: Path) -> list:
    """Sort key ordering numbers inside names by value: `img2` before `img10`."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def list_images(spec: str | Path) -> list[Path]:
    """The image files a folder, a single file or a glob pattern names, in natural order."""
    text = str(spec)
    path = Path(text)
    if path.is_dir():
        files = [p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES]
        if not files:
            raise InputError(f"image folder {path}: holds no image files ({', '.join(IMAGE_SUFFIXES)})")
    elif path.is_file():
        files = [path]
    elif globlib.has_magic(text):
        files = [Path(p) for p in globlib.glob(text) if Path(p).is_file()]
        if not files:
            raise InputError(f"image pattern {text!r}: matches no files")
    else:
        raise InputError(f"{text}: no such file or folder")
    unreadable = [p for p in files if not cv2.haveImageReader(str(p))]
    if unreadable:
        more = f" and {len(unreadable) - 3} more" if len(unreadable) > 3 else ""
        raise InputError(f"{', '.join(str(p) for p in unreadable[:3])}{more}: not an image format OpenCV reads")
    return sorted(files, key=natural_key)


def timestamps_from_names(paths: list[Path], fps: float | None) -> np.ndarray:
    """Frame times in seconds; see the module docstring for the rules."""
    n = len(paths)
    if fps is not None:
        return np.arange(n) / fps
    stems = [p.stem for p in paths]
    if n and all(_NUMBER.match(s) for s in stems):
        if any("." in s for s in stems):
            t = np.array([float(s) for s in stems])
        elif min(len(s) for s in stems) >= NANOSECOND_DIGITS:
            t = np.array([int(s) for s in stems], dtype=np.int64) * 1e-9
        else:
            t = np.array([int(s) for s in stems], float) / DEFAULT_FPS
        if np.all(np.diff(t) > 0):
            return t
    return np.arange(n) / DEFAULT_FPS


class ImageSource(Source):
    """Frames from image files; see the module docstring."""

    def __init__(self, spec: str | Path, fps: float | None = None, K: np.ndarray | None = None):
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise InputError(f"--fps must be > 0, got {fps}")
        self.paths = list_images(spec)
        self.t_s = timestamps_from_names(self.paths, fps)
        span = self.t_s[-1] - self.t_s[0]
        rate = fps or ((len(self.t_s) - 1) / span if span > 0 else DEFAULT_FPS)
        self.notes: list[str] = []
        """What was left out or not used, for the run summary."""
        self.info = SourceInfo(name=str(spec), n_frames=len(self.paths), fps=float(rate),
                               K=None if K is None else np.asarray(K, float))

    def read_frame(self, i: int) -> Frame:
        """Frame i, RGB uint8; `SourceError` naming the file when it cannot be decoded."""
        try:
            image = read_image(self.paths[i], cv2.IMREAD_UNCHANGED, what=f"image {i} of {self.info.name}")
        except InputError as exc:
            raise SourceError(str(exc)) from None
        try:
            rgb = to_rgb8(image)
        except InputError as exc:
            raise SourceError(f"{self.paths[i]}: {exc}") from None
        return Frame(t=float(self.t_s[i]), rgb=rgb, K=self.info.K, index=i)

    def events(self) -> Iterator[Frame]:
        for i in range(len(self.paths)):
            yield self.read_frame(i)
