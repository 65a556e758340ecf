"""Video files and webcams through OpenCV.

    with VideoSource("clip.mp4") as src: ...      # n_frames and fps from the container
    with VideoSource("webcam:0") as src: ...      # live; n_frames None

Timestamps (float s): for files, the container's presentation time of each frame
(`CAP_PROP_POS_MSEC`) when it increases, else `index / fps`; for webcams, host monotonic time since
the first frame. Frames are RGB uint8 (OpenCV decodes BGR; grayscale and 16-bit video is converted).
K is unknown (None). Failures: a file or camera that cannot be opened -> `InputError`; a file that
stops decoding before its frame count, or a camera that stops delivering -> `SourceError` naming
the frame index.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

from uareme_fusion.errors import InputError, SourceError
from uareme_fusion.types import Frame

from ..formats.images import to_rgb8
from .base import Source, SourceInfo, spread_indices

WEBCAM_PATTERN = re.compile(r"^webcam(?::(\d+))?$")
DEFAULT_FPS = 30.0
"""Frame rate assumed when the container does not state one."""
WEBCAM_READ_RETRIES = 3
"""Consecutive failed reads after which a webcam counts as disconnected."""


MAX_CAMERA_INDEX = 9999
"""Largest `webcam:N` accepted (OpenCV takes a 32-bit index; real systems number cameras from 0)."""


def parse_webcam(spec: str) -> int | None:
    """Camera index of `webcam` / `webcam:N`, None for anything else; `InputError` for an index out of range."""
    match = WEBCAM_PATTERN.match(spec.strip())
    if match is None:
        return None
    index = int(match.group(1) or 0)
    if index > MAX_CAMERA_INDEX:
        raise InputError(f"{spec.strip()}: camera index {match.group(1)} is out of range (0 to {MAX_CAMERA_INDEX})")
    return index


class VideoSource(Source):
    """A video file or a webcam (`webcam:N`); see the module docstring."""

    def __init__(self, spec: str | Path, fps: float | None = None):
        self.spec = str(spec)
        self.camera = parse_webcam(self.spec)
        if self.camera is None:
            path = Path(self.spec)
            if not path.is_file():
                raise InputError(f"video {path}: no such file")
            self._cap = cv2.VideoCapture(str(path))
            if not self._cap.isOpened():
                self._cap.release()
                raise InputError(f"video {path}: OpenCV cannot open it (not a video, or a codec it lacks)")
        else:
            self._cap = cv2.VideoCapture(self.camera)
            if not self._cap.isOpened():
                self._cap.release()
                raise InputError(f"{self.spec}: cannot open camera {self.camera} (not connected, or in use)")
        count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT))
        container_fps = float(self._cap.get(cv2.CAP_PROP_FPS))
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise InputError(f"--fps must be > 0, got {fps}")
        self.fps = fps or (container_fps if np.isfinite(container_fps) and container_fps > 0 else None)
        width = int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH))
        height = int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        self.info = SourceInfo(
            name=self.spec,
            n_frames=count if self.camera is None and count > 0 else None,
            fps=self.fps,
            image_size=(height, width) if width > 0 and height > 0 else None,
        )
        self.notes: list[str] = []
        """What was left out or not used, for the run summary."""
        self.use_fps_times = fps is not None  # an explicit --fps overrides the container's clock

    def _file_time(self, index: int, last_t: float) -> float:
        t = self._cap.get(cv2.CAP_PROP_POS_MSEC) * 1e-3
        if not self.use_fps_times and np.isfinite(t) and (index == 0 and t >= 0 or t > last_t):
            return t
        return index / (self.fps or DEFAULT_FPS)

    def events(self) -> Iterator[Frame]:
        if self._cap is None:
            raise SourceError(f"{self.spec}: the source was closed")
        index, last_t, t0, failures = 0, -np.inf, None, 0
        while True:
            ok, image = self._cap.read()
            if not ok or image is None:
                if self.camera is not None:
                    failures += 1
                    if failures < WEBCAM_READ_RETRIES:
                        continue
                    raise SourceError(f"{self.spec}: the camera stopped delivering frames after frame {index - 1} "
                                      f"({index} frames read)")
                if self.info.n_frames is not None and index < self.info.n_frames:
                    raise SourceError(f"video {self.spec}: decoding stopped at frame {index} of "
                                      f"{self.info.n_frames} (truncated or corrupt file)")
                return
            failures = 0
            if self.camera is None:
                t = self._file_time(index, last_t)
            else:
                now = time.monotonic()
                t0 = now if t0 is None else t0
                t = now - t0
            yield Frame(t_s=float(t), rgb=to_rgb8(image), index=index)
            last_t = t
            index += 1

    def sample_frames(self, n: int, limit: int | None = None) -> list[Frame] | None:
        """`Source.sample_frames` for a file (a second reader seeking to every k-th frame); None for a
        webcam or a file whose frame count the container does not state."""
        if self.camera is not None or not self.info.n_frames:
            return None
        cap = cv2.VideoCapture(self.spec)
        try:
            frames = []
            for i in spread_indices(self.info.n_frames, n, limit):
                cap.set(cv2.CAP_PROP_POS_FRAMES, i)
                ok, image = cap.read()
                if ok and image is not None:
                    frames.append(Frame(t_s=i / (self.fps or DEFAULT_FPS), rgb=to_rgb8(image), index=i))
            return frames
        finally:
            cap.release()

    def close(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None
