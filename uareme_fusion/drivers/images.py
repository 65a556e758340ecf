"""A single image, a folder of images or a glob, as a stream of frames.

    ImageSource("frames/")            # every image file in the folder, natural order (2.png before 10.png)
    ImageSource("shots/*.jpg", fps=10)

Timestamps (s): with `fps` given, `index / fps`. Otherwise from the file names when every stem is a
number: names with a decimal point are seconds (`1305031102.175304.png`, TUM style); integers that
are epoch times say their unit by their size (19 digits ns as EuRoC, 16 us, 13 ms); other integers
stepping by 10-1000 are milliseconds and by 10^4-10^6 microseconds since the start (1-100 fps);
the rest are frame numbers at 30 fps (`17.png` -> 17 / 30 s). A note says when names were read as
times. Any other names: `index / 30`. Images are converted to RGB uint8 (grayscale, RGBA and
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
from uareme_fusion.types import Frame

from ..formats.images import IMAGE_SUFFIXES, images_in_folder, natural_key, read_rgb
from .base import Source, SourceInfo, spread_indices

DEFAULT_FPS = 30.0
EPOCH_UNITS = {"ns": (1e-9, 10**17, 10**19), "us": (1e-6, 10**14, 10**16), "ms": (1e-3, 10**11, 10**13)}
"""Integer names in [lo, hi) are epoch times in this unit (seconds per unit, lo, hi): 1973 to 2286."""
RELATIVE_UNITS = {"ms": (1e-3, 10, 1000), "us": (1e-6, 10_000, 1_000_000)}
"""Integer names whose median step lies in [lo, hi] are times in this unit from the recording's start
(1 to 100 fps); names stepping by 1 to 9 are frame numbers."""
_NUMBER = re.compile(r"^\d+(\.\d+)?$")


def list_images(spec: str | Path) -> list[Path]:
    """The image files a folder, a single file or a glob pattern names, in natural order."""
    text = str(spec)
    path = Path(text)
    if path.is_dir():
        files = images_in_folder(path)
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


def _integer_name_unit(values: np.ndarray) -> tuple[float, str] | None:
    """(seconds per unit, unit name) for integer file names that are timestamps, None for frame numbers.

    Epoch stamps say their unit by their size (`EPOCH_UNITS`: the year 1973-2286 in that unit);
    stamps counted from the recording's start by their median step (`RELATIVE_UNITS`: 1-100 fps)."""
    smallest = int(values.min())
    for unit, (scale, lo, hi) in EPOCH_UNITS.items():
        if lo <= smallest and int(values.max()) < hi:
            return scale, unit
    steps = np.diff(values)
    step = float(np.median(steps)) if len(steps) else 1.0
    for unit, (scale, lo, hi) in RELATIVE_UNITS.items():
        if lo <= step <= hi:
            return scale, unit
    return None


def timestamps_from_names(paths: list[Path], fps: float | None) -> tuple[np.ndarray, str | None]:
    """Frame times in seconds, and how the names were read when they were read as times (a note for
    the run summary); see the module docstring for the rules."""
    n = len(paths)
    if fps is not None:
        return np.arange(n) / fps, None
    stems = [p.stem for p in paths]
    if n and all(_NUMBER.match(s) for s in stems):
        how = None
        if any("." in s for s in stems):
            t = np.array([float(s) for s in stems])
        else:
            values = np.array([int(s) for s in stems], dtype=np.int64)
            unit = _integer_name_unit(values)
            if unit is None:
                t = values / DEFAULT_FPS
            else:
                scale, name = unit
                t = values * scale
                how = f"image names read as timestamps in {name} (pass --fps to number the frames instead)"
        if np.all(np.diff(t) > 0):
            return t, how
    return np.arange(n) / DEFAULT_FPS, None


class ImageSource(Source):
    """Frames from image files; see the module docstring."""

    def __init__(self, spec: str | Path, fps: float | None = None, K: np.ndarray | None = None):
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise InputError(f"--fps must be > 0, got {fps}")
        self.paths = list_images(spec)
        self.t_s, how = timestamps_from_names(self.paths, fps)
        span = self.t_s[-1] - self.t_s[0]
        rate = fps or ((len(self.t_s) - 1) / span if span > 0 else DEFAULT_FPS)
        self.notes: list[str] = [] if how is None else [f"{spec}: {how}, {rate:.4g} fps"]
        """What was left out or not used, or how the names were read, for the run summary."""
        self.info = SourceInfo(name=str(spec), n_frames=len(self.paths), fps=float(rate),
                               K=None if K is None else np.asarray(K, float))

    def read_frame(self, i: int) -> Frame:
        """Frame i, RGB uint8; `SourceError` naming the file when it cannot be decoded."""
        try:
            rgb = read_rgb(self.paths[i])
        except InputError as exc:
            raise SourceError(str(exc)) from None
        return Frame(t_s=float(self.t_s[i]), rgb=rgb, K=self.info.K, index=i)

    def events(self) -> Iterator[Frame]:
        for i in range(len(self.paths)):
            yield self.read_frame(i)

    def sample_frames(self, n: int, limit: int | None = None) -> list[Frame]:
        """`Source.sample_frames`: every k-th image."""
        frames = []
        for i in spread_indices(len(self.paths), n, limit):
            try:
                frames.append(self.read_frame(i))
            except SourceError:
                continue
        return frames
