"""Sinks that draw: the horizon overlay video and ground masks.

The overlay shows what the paper's demo shows: the horizon (from the estimate's up vector) and the
Manhattan axes (`R_cm = R_wc^T R_wm` from the estimate, or the frame's own visual rotation), with
optional panes of normals and confidence. Without intrinsics the focal length comes from an
assumed horizontal field of view, written on the overlay.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..overlay import draw_ground, ground_mask, side_by_side
from ..overlay.compose import draw_overlay
from .runner import FrameResult

VIDEO_CODECS = {".mp4": "mp4v", ".avi": "MJPG", ".mkv": "MJPG", ".mov": "mp4v"}


def estimate_R_cm(result: FrameResult) -> np.ndarray | None:
    """The scene axes in the camera frame: from the estimate when it has `R_wm`, else the visual rotation."""
    est = result.estimate
    if est.R_wm is not None:
        return est.R_wc.T @ est.R_wm
    return None if result.visual is None else result.visual.R_cm


def overlay_image(result: FrameResult, fov_deg: float, panes: bool) -> np.ndarray:
    """The frame with horizon and Manhattan axes drawn (and normal/confidence panes when `panes`)."""
    image = draw_overlay(result.frame.rgb, result.estimate.up_c, estimate_R_cm(result), result.K, fov_deg)
    return side_by_side(image, result.normal_map) if panes and result.normal_map is not None else image


class VideoFileWriter:
    """An OpenCV video writer opened on the first image (its size fixes the video's)."""

    def __init__(self, path: Path, fps: float):
        self.path, self.fps = Path(path), float(fps)
        codec = VIDEO_CODECS.get(self.path.suffix.lower())
        if codec is None:
            raise InputError(f"{self.path}: unsupported video extension; use one of {', '.join(VIDEO_CODECS)}")
        self._fourcc = cv2.VideoWriter_fourcc(*codec)
        self._writer = None
        self.frames = 0

    def write_rgb(self, rgb: np.ndarray) -> None:
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = cv2.VideoWriter(str(self.path), self._fourcc, self.fps, (rgb.shape[1], rgb.shape[0]))
            if not self._writer.isOpened():
                raise InputError(f"{self.path}: OpenCV cannot write this video (codec {self._fourcc})")
        self._writer.write(np.ascontiguousarray(rgb[..., ::-1]))
        self.frames += 1

    def close(self) -> None:
        if self._writer is not None:
            self._writer.release()
            self._writer = None


class HorizonVideoSink:
    """Writes the overlay of every frame with an image into a video."""

    def __init__(self, path: Path, fps: float, fov_deg: float = 60.0, panes: bool = False):
        self.video, self.fov_deg, self.panes = VideoFileWriter(path, fps), fov_deg, panes

    def write(self, result: FrameResult) -> None:
        if result.frame is not None and result.frame.rgb is not None:
            self.video.write_rgb(overlay_image(result, self.fov_deg, self.panes))

    def close(self) -> None:
        self.video.close()


class GroundSink:
    """Ground masks per frame: `masks/NNNNNN.png` (white = ground, at image size) and either overlay
    images (`overlay/NNNNNN.png`) or an overlay video (`video` path)."""

    def __init__(self, out_dir: Path, threshold_deg: float = 15.0, video: Path | None = None, fps: float = 30.0):
        self.out, self.threshold_deg = Path(out_dir), threshold_deg
        (self.out / "masks").mkdir(parents=True, exist_ok=True)
        if video is None:
            (self.out / "overlay").mkdir(exist_ok=True)
        self.video = None if video is None else VideoFileWriter(video, fps)
        self.count = 0

    def write(self, result: FrameResult) -> None:
        frame = result.frame
        if frame is None or frame.rgb is None:
            return
        height, width = frame.rgb.shape[:2]
        if result.normal_map is None:
            mask = np.zeros((height, width), bool)
        else:
            mask, _ = ground_mask(result.normal_map, result.estimate.up_c, self.threshold_deg)
            mask = cv2.resize(mask.astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST) > 0
        name = f"{frame.index if frame.index >= 0 else self.count:06d}.png"
        cv2.imwrite(str(self.out / "masks" / name), mask.astype(np.uint8) * 255)
        overlay = draw_ground(frame.rgb, mask)
        if self.video is not None:
            self.video.write_rgb(overlay)
        else:
            cv2.imwrite(str(self.out / "overlay" / name), overlay[..., ::-1])
        self.count += 1

    def close(self) -> None:
        if self.video is not None:
            self.video.close()
