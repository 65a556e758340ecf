"""Sinks that draw: the horizon overlay video and ground masks.

The overlay shows what the paper's demo shows: the horizon (from the estimate's up vector) and the
Manhattan axes (`R_cm = R_wc^T R_wm` from the estimate, or the frame's own visual rotation), with
optional panes of normals and confidence. Without intrinsics the focal length comes from an
assumed horizontal field of view, written on the overlay.
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, OutputError
from ..io.safe_files import cannot_write, discard, publish, refuse_link, temporary_sibling, write_image_atomic
from ..io.video_writer import OPENCV_CODECS, open_video_encoder
from ..overlay import draw_ground, ground_mask, side_by_side
from ..overlay.compose import draw_overlay
from ..types import FrameResult

VIDEO_CODECS = OPENCV_CODECS
"""The video extensions written (encoders in `io.video_writer`)."""


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


def _frames_in_video(path: Path) -> int:
    """The frame count a finished video file declares (0 when it cannot be opened), with FFmpeg's own
    complaints about a broken file kept off stderr (the caller reports it in one line)."""
    saved = os.dup(2)
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
        capture = cv2.VideoCapture(str(path))
        frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if capture.isOpened() else 0
        capture.release()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    return frames


class VideoFileWriter:
    """A video encoder (`io.video_writer`: H.264 when PyAV is installed, else OpenCV) opened on the
    first image (its size fixes the video's); `encoder` names the one used.

    It writes a hidden temporary file beside `path` and renames it into place on `close`, once the
    container is finished (an mp4's index written) and reads back with every frame, so `path` is
    never a half-written video. A frame of another size is resized to the first's and counted in
    `resized` (never dropped silently)."""

    def __init__(self, path: Path, fps: float):
        self.path, self.fps = Path(path), float(fps)
        if self.path.suffix.lower() not in VIDEO_CODECS:
            raise InputError(f"{self.path}: unsupported video extension; use one of {', '.join(VIDEO_CODECS)}")
        self._writer = None
        self.encoder: str | None = None
        self._tmp: Path | None = None
        self._size: tuple[int, int] | None = None
        self.frames = 0
        self.resized = 0

    def write_rgb(self, rgb: np.ndarray) -> None:
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            refuse_link(self.path)
            self._tmp = temporary_sibling(self.path)
            self._size = (rgb.shape[1], rgb.shape[0])
            try:
                self._writer = open_video_encoder(self._tmp, self.fps, self._size)
            except InputError:
                discard(self._tmp)
                raise
            self.encoder = self._writer.name
        if (rgb.shape[1], rgb.shape[0]) != self._size:
            rgb = cv2.resize(rgb, self._size, interpolation=cv2.INTER_AREA)
            self.resized += 1
        try:
            self._writer.write(rgb)
        except OSError as exc:  # the encoder names its temporary file; the user knows the video's name
            raise cannot_write(self.path, exc) from None
        self.frames += 1

    def summary(self) -> dict:
        """{"videos": {file name: encoder}, "video_frames": n, "video_frames_resized": n} for summary.json."""
        return {**({"videos": {self.path.name: self.encoder}} if self.encoder else {}),
                "video_frames": self.frames, "video_frames_resized": self.resized}

    def close(self) -> None:
        if self._writer is None:
            return
        try:
            self._writer.close()
        except OSError as exc:
            discard(self._tmp)
            raise cannot_write(self.path, exc) from None
        finally:
            self._writer = None
        readable = _frames_in_video(self._tmp)
        if readable != self.frames:
            discard(self._tmp)
            raise OutputError(f"{self.path}: could not be written (the finished video reads back {readable} of "
                              f"{self.frames} frames: disk full?)")
        publish(self._tmp, self.path)


class HorizonVideoSink:
    """Writes the overlay of every frame with an image into a video."""

    def __init__(self, path: Path, fps: float, fov_deg: float = 60.0, panes: bool = False):
        self.video, self.fov_deg, self.panes = VideoFileWriter(path, fps), fov_deg, panes

    def write(self, result: FrameResult) -> None:
        if result.frame is not None and result.frame.rgb is not None:
            self.video.write_rgb(overlay_image(result, self.fov_deg, self.panes))

    def summary(self) -> dict:
        return self.video.summary()

    def close(self) -> None:
        self.video.close()


class GroundSink:
    """Ground masks per frame: `masks/NNNNNN.png` (white = ground, at image size) and either overlay
    images (`overlay/NNNNNN.png`) or an overlay video (`video` path)."""

    def __init__(self, out_dir: Path, threshold_deg: float = 15.0, video: Path | None = None, fps: float = 30.0):
        self.out, self.threshold_deg = Path(out_dir), threshold_deg
        for sub in ("masks",) + (("overlay",) if video is None else ()):
            refuse_link(self.out / sub)
            (self.out / sub).mkdir(parents=True, exist_ok=True)
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
            # Bilinear, then at half: a map smaller than the image (learned normals) keeps smooth edges.
            mask = cv2.resize(mask.astype(np.uint8) * 255, (width, height), interpolation=cv2.INTER_LINEAR) >= 128
        name = f"{frame.index if frame.index >= 0 else self.count:06d}.png"
        overlay = draw_ground(frame.rgb, mask)
        write_image_atomic(self.out / "masks" / name, mask.astype(np.uint8) * 255)
        try:
            if self.video is not None:
                self.video.write_rgb(overlay)
            else:
                write_image_atomic(self.out / "overlay" / name, overlay[..., ::-1])
        except (InputError, OutputError):  # whole results only: no mask without its overlay
            (self.out / "masks" / name).unlink(missing_ok=True)
            raise
        self.count += 1

    def summary(self) -> dict:
        return {"ground_masks": self.count, **({} if self.video is None else self.video.summary())}

    def close(self) -> None:
        if self.video is not None:
            self.video.close()
