"""Video encoders for the overlay videos: H.264 through PyAV where it is installed, OpenCV otherwise.

    writer = open_video_encoder(Path("out.mp4"), fps=30.0, size_wh=(640, 480))
    writer.write(rgb_uint8); writer.close(); writer.name   # "h264 (PyAV libx264)" or "mp4v (OpenCV)"

H.264 (yuv420p) in .mp4/.mkv/.mov plays in browsers and phones; OpenCV's own writer only has
MPEG-4 Part 2 (`mp4v`), which browsers do not play, and is the fallback when PyAV (`av`) or its
libx264 is missing. yuv420p needs even sizes: an odd width or height is padded by one black pixel.
`.avi` is always Motion-JPEG through OpenCV.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError

OPENCV_CODECS = {".mp4": "mp4v", ".avi": "MJPG", ".mkv": "MJPG", ".mov": "mp4v"}
"""Fourcc of OpenCV's writer per extension (the fallback)."""
MUXERS = {".mp4": "mp4", ".mkv": "matroska", ".mov": "mov"}
"""libav muxer per extension written as H.264 (PyAV writes to a Python file, which has no name to
guess it from)."""
H264_SUFFIXES = tuple(MUXERS)
H264_CRF = "20"
"""x264 constant rate factor: visually near lossless for overlays, a few MB per minute at 640x480."""


class _PyAvEncoder:
    def __init__(self, path: Path, fps: float, size_wh: tuple[int, int]):
        import av
        from fractions import Fraction

        # Through a Python file: a write the disk refuses raises OSError here, where libav's own file
        # I/O crashed the process in close() (segfault on a full disk, measured with PyAV 14).
        self.file = open(path, "wb")
        self.container = av.open(self.file, mode="w", format=MUXERS[path.suffix.lower()])
        rate = Fraction(fps).limit_denominator(1001)
        self.stream = self.container.add_stream("libx264", rate=rate, options={"crf": H264_CRF})
        self.width, self.height = (size_wh[0] + 1) // 2 * 2, (size_wh[1] + 1) // 2 * 2
        self.stream.width, self.stream.height, self.stream.pix_fmt = self.width, self.height, "yuv420p"
        self.av, self.name = av, "h264 (PyAV libx264)"

    def write(self, rgb: np.ndarray) -> None:
        h, w = rgb.shape[:2]
        if (w, h) != (self.width, self.height):
            rgb = cv2.copyMakeBorder(rgb, 0, self.height - h, 0, self.width - w, cv2.BORDER_CONSTANT, value=0)
        frame = self.av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")
        for packet in self.stream.encode(frame):
            self.container.mux(packet)

    def close(self) -> None:
        try:
            for packet in self.stream.encode():
                self.container.mux(packet)
            self.container.close()
        finally:
            self.file.close()


class _OpenCvEncoder:
    def __init__(self, path: Path, fps: float, size_wh: tuple[int, int]):
        codec = OPENCV_CODECS[path.suffix.lower()]
        self.writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), fps, tuple(size_wh))
        if not self.writer.isOpened():
            raise InputError(f"{path}: OpenCV cannot write this video (codec {codec})")
        self.name = f"{codec} (OpenCV)"

    def write(self, rgb: np.ndarray) -> None:
        self.writer.write(np.ascontiguousarray(rgb[..., ::-1]))

    def close(self) -> None:
        self.writer.release()


def h264_available() -> bool:
    """True when PyAV with the libx264 encoder is installed."""
    try:
        import av
    except ImportError:
        return False
    return "libx264" in av.codecs_available


def open_video_encoder(path: Path, fps: float, size_wh: tuple[int, int]):
    """An encoder with `write(rgb_uint8)`, `close()` and `name`: H.264 when possible (module docstring)."""
    path = Path(path)
    if path.suffix.lower() not in OPENCV_CODECS:
        raise InputError(f"{path}: unsupported video extension; use one of {', '.join(OPENCV_CODECS)}")
    if path.suffix.lower() in H264_SUFFIXES and h264_available():
        return _PyAvEncoder(path, fps, size_wh)
    return _OpenCvEncoder(path, fps, size_wh)
