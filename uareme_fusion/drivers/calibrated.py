"""Any camera source with intrinsics the user gave (`--intrinsics`): frames undistorted, carrying that K.

    source = with_intrinsics(open_source("clip.mp4"), parse_intrinsics("600,600,320,240"))

The given intrinsics replace whatever the source knew (a note says so when it knew other values);
`info.K_origin` says where they came from. The principal point is checked against the image size at
open when the source knows it, else on the first frame (`InputError` naming the option).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.types import Frame

from .base import GroundTruth, Source
from .intrinsics import CameraModel, Undistorter, check_camera


class CalibratedSource(Source):
    """`source` with its frames undistorted by `camera` and carrying `camera.K`."""

    def __init__(self, source: Source, camera: CameraModel):
        if not source.info.has_frames:
            raise InputError(f"{camera.origin}: intrinsics apply to camera frames, and {source.info.name} has none "
                             "(IMU only)")
        self.source, self.camera = source, check_camera(camera, camera.origin, source.info.image_size)
        self.notes, self.fixes = source.report()
        self.accelerometer = source.accelerometer
        K_before = source.info.K
        if K_before is not None and not np.allclose(K_before, camera.K):
            self.notes.append(f"{camera.origin} replaces the source's own K "
                              f"({source.info.K_origin or 'unknown origin'})")
        self.info = dataclasses.replace(source.info, K=camera.K, K_origin=camera.origin)
        self._checked = False
        self._undistorter: Undistorter | None = None

    def _calibrated(self, frame: Frame) -> Frame:
        if not self._checked:
            size = frame.rgb.shape[:2] if frame.rgb is not None else frame.depth.shape[:2]
            check_camera(self.camera, self.camera.origin, size)
            self._undistorter = Undistorter(self.camera, size) if self.camera.distorted else None
            self._checked = True
        if self._undistorter is not None:
            return self._undistorter.frame(frame)
        return dataclasses.replace(frame, K=self.camera.K)

    def events(self) -> Iterator:
        for event in self.source.events():
            yield self._calibrated(event) if isinstance(event, Frame) else event

    def ground_truth(self) -> GroundTruth | None:
        return self.source.ground_truth()

    def close(self) -> None:
        self.source.close()


def with_intrinsics(source: Source, camera: CameraModel) -> Source:
    """`source` with `camera`'s intrinsics (see the module docstring); closes `source` on failure."""
    try:
        return CalibratedSource(source, camera)
    except BaseException:
        source.close()
        raise
