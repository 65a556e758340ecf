"""An IMU log on its own (EuRoC CSV format) and merged into a camera source.

    with ImuCsvSource("imu.csv") as src: ...                  # IMU-only: batches of 1/30 s
    with merge_imu(VideoSource("clip.mp4"), ImuCsvSource("imu.csv"), time_offset_s=0.12) as src: ...

Format (`euroc_imu.read_euroc_imu`): `timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]`,
comma-separated, `#` header; gyro and specific force in the IMU frame. A file with other columns
is refused with an `InputError` naming the file, line and column.

`merge_imu` puts the log's samples between the camera source's frames by camera time: a sample
stamped `t` (IMU clock, kept as written) happened at camera time `t + time_offset_s`, which becomes
`info.imu_time_offset_s`. The camera source must not carry an IMU of its own.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from uareme_fusion.errors import InputError

from .base import GroundTruth, ImuBatch, Source, SourceInfo
from .euroc_imu import read_euroc_imu
from .interleave import IMU_ONLY_BATCH_S, count_spans, interleave, split_by_span


class ImuCsvSource(Source):
    """An EuRoC-format IMU CSV as an IMU-only source (`has_frames` False)."""

    def __init__(self, path: str | Path, batch_s: float = IMU_ONLY_BATCH_S, R_ci: np.ndarray | None = None):
        self.imu = read_euroc_imu(path)
        self.batch_s = float(batch_s)
        self.notes: list[str] = []
        if self.imu.n_non_increasing:
            self.notes.append(f"{self.imu.path}: {self.imu.n_non_increasing} IMU timestamps do not increase "
                              "(passed on; the backend drops and counts them)")
        self.info = SourceInfo(name=str(path), n_frames=0, has_frames=False, has_imu=True,
                               R_ci=np.eye(3) if R_ci is None else np.asarray(R_ci, float))

    def batches(self) -> Iterator[ImuBatch]:
        yield from split_by_span(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2, self.batch_s)

    @property
    def n_batches(self) -> int:
        """Batches (so estimates) the run will give: the progress bar's length."""
        return count_spans(self.imu.t_s, self.batch_s)

    def events(self) -> Iterator[ImuBatch]:
        yield from self.batches()


class MergedSource(Source):
    """A camera source with the samples of an IMU-only source put between its frames."""

    def __init__(self, camera: Source, imu: Source, time_offset_s: float = 0.0):
        if camera.info.has_imu:
            raise InputError(f"{camera.info.name} already has an IMU; cannot merge the IMU of {imu.info.name}")
        if not imu.info.has_imu:
            raise InputError(f"{imu.info.name} holds no IMU samples to merge")
        if not np.isfinite(time_offset_s):
            raise InputError(f"IMU time offset must be a finite number of seconds, got {time_offset_s}")
        self.camera, self.imu = camera, imu
        self.notes = list(getattr(camera, "notes", [])) + list(getattr(imu, "notes", []))
        self.info = dataclasses.replace(camera.info, has_imu=True, R_ci=imu.info.R_ci,
                                        imu_time_offset_s=float(time_offset_s))

    def _imu_batches(self) -> Iterator[ImuBatch]:
        for event in self.imu.events():
            if isinstance(event, ImuBatch):
                yield event

    def events(self) -> Iterator:
        yield from interleave(self.camera.events(), self._imu_batches(), self.info.imu_time_offset_s)

    def ground_truth(self) -> GroundTruth | None:
        return self.camera.ground_truth() or self.imu.ground_truth()

    def close(self) -> None:
        self.camera.close()
        self.imu.close()


def merge_imu(source: Source, imu_source: Source, time_offset_s: float = 0.0) -> Source:
    """`source`'s frames with `imu_source`'s samples between them (see the module docstring)."""
    return MergedSource(source, imu_source, time_offset_s)
