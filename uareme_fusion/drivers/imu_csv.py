"""An IMU log on its own (EuRoC CSV format) and merged into a camera source.

    with ImuCsvSource("imu.csv") as src: ...                  # IMU-only: batches of 1/30 s
    with merge_imu(VideoSource("clip.mp4"), ImuCsvSource("imu.csv"), time_offset_s=0.12) as src: ...

Format (`formats.euroc.read_euroc_imu`): `timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y, a_z [m/s^2]`,
comma- or whitespace-separated (any file extension), `#` header (or a line of column names), timestamps
as integer ns (or seconds with decimals, see `imu_checks`); gyro and specific force in the IMU frame. A file with
other columns is refused with an `InputError` naming the file, line and column.
`read_imu_log` then checks the data for wrong units, column order and time running backwards
(`imu_checks.check_imu_log`): the source's `fixes` list what it repaired.

A table of 4 columns (`timestamp, a_x, a_y, a_z`: a phone's or board's accelerometer without gyro) is
not an IMU (`has_imu` False): it is `source.accelerometer`, which a run feeds to the EKF as gravity only
beside a camera (`--imu`); alone it is refused.

`merge_imu` puts the log's samples between the camera source's frames by camera time: a sample
stamped `t` (IMU clock, kept as written) happened at camera time `t + time_offset_s`, which becomes
`info.imu_time_offset_s`. The camera source must not carry an IMU of its own. A log whose samples
do not overlap the frames' span at all (another clock: epoch ns against a video's seconds) is
refused when the first frame arrives (`InputError` naming the log).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.io.text_tables import sniff_delimiter
from uareme_fusion.types import ImuBatch

from ..formats.euroc import EurocImu, read_accelerometer_table, read_euroc_imu
from .base import GroundTruth, Source, SourceInfo
from .imu_checks import check_imu_log
from .interleave import IMU_ONLY_BATCH_S, count_spans, interleave, split_by_span


def read_imu_log(path: str | Path) -> tuple[EurocImu, list[str]]:
    """An IMU table in EuRoC columns (commas, or whitespace when a file's first data line has no
    comma), checked and repaired by `check_imu_log`: (imu, fixes)."""
    path = Path(path)
    return check_imu_log(read_euroc_imu(path, sniff_delimiter(path) if path.is_file() else ",", exports=True))


def non_increasing_note(imu: EurocImu) -> list[str]:
    """The note for an IMU log whose timestamps step back (the backends reorder, drop and count them)."""
    if not imu.n_non_increasing:
        return []
    return [f"{imu.path}: {imu.n_non_increasing} IMU timestamps do not increase (passed on; the backend drops "
            "and counts them)"]


ACCELEROMETER_ALONE = ("{path}: 4 columns (timestamp, a_x, a_y, a_z) are an accelerometer without gyro, which gives "
                       "tilt only beside a camera: pass it with --imu to a video or image folder")


class ImuCsvSource(Source):
    """An EuRoC-format IMU CSV as an IMU-only source (`has_frames` False)."""

    def __init__(self, path: str | Path, batch_s: float = IMU_ONLY_BATCH_S, R_ci: np.ndarray | None = None,
                 accelerometer_only: bool = False):
        """`accelerometer_only`: a 4-column log (no gyro) is taken, to be merged beside a camera; else refused."""
        self.path = Path(path)
        self.accelerometer = (read_accelerometer_table(self.path, sniff_delimiter(self.path))
                              if self.path.is_file() else None)
        if self.accelerometer is not None and not accelerometer_only:
            raise InputError(ACCELEROMETER_ALONE.format(path=self.path))
        self.imu, self.fixes = (None, []) if self.accelerometer is not None else read_imu_log(path)
        self.batch_s = float(batch_s)
        self.notes = non_increasing_note(self.imu) if self.imu is not None else []
        self.info = SourceInfo(name=str(path), n_frames=0, has_frames=False, has_imu=self.imu is not None,
                               R_ci=np.eye(3) if R_ci is None else np.asarray(R_ci, float))

    @property
    def span_s(self) -> tuple[float, float]:
        """First and last timestamp of the log (IMU clock), s."""
        t_s = self.imu.t_s if self.imu is not None else self.accelerometer[0]
        return float(t_s.min()), float(t_s.max())

    def batches(self) -> Iterator[ImuBatch]:
        if self.imu is None:
            raise InputError(ACCELEROMETER_ALONE.format(path=self.path))
        yield from split_by_span(self.imu.t_s, self.imu.gyro_rad_s, self.imu.accel_m_s2, self.batch_s)

    @property
    def n_batches(self) -> int:
        """Batches (so estimates) the run will give: the progress bar's length."""
        return count_spans(self.imu.t_s, self.batch_s) if self.imu is not None else 0

    def events(self) -> Iterator[ImuBatch]:
        yield from self.batches()


CLOCK_TOLERANCE_S = 1.0
"""IMU samples may end or start this long beyond the frames before the clocks count as different."""


def spans_overlap(imu_span_s: tuple[float, float], frame_span_s: tuple[float, float]) -> bool:
    """Whether IMU samples spanning `imu_span_s` (camera clock) meet frames spanning `frame_span_s`,
    within `CLOCK_TOLERANCE_S`: False means the two are on different clocks."""
    return not (imu_span_s[1] < frame_span_s[0] - CLOCK_TOLERANCE_S or imu_span_s[0] > frame_span_s[1] + CLOCK_TOLERANCE_S)


class MergedSource(Source):
    """A camera source with the samples of an IMU-only source put between its frames."""

    def __init__(self, camera: Source, imu: Source, time_offset_s: float = 0.0):
        if camera.info.has_imu:
            raise InputError(f"{camera.info.name} already has an IMU; cannot merge the IMU of {imu.info.name}")
        if not imu.info.has_imu and imu.accelerometer is None:
            raise InputError(f"{imu.info.name} holds no IMU samples to merge")
        if not np.isfinite(time_offset_s):
            raise InputError(f"IMU time offset must be a finite number of seconds, got {time_offset_s}")
        self.camera, self.imu = camera, imu
        (camera_notes, camera_fixes), (imu_notes, imu_fixes) = camera.report(), imu.report()
        self.notes, self.fixes = camera_notes + imu_notes, camera_fixes + imu_fixes
        self.accelerometer = imu.accelerometer  # an accelerometer without gyro: fed beside the events
        self.info = dataclasses.replace(camera.info, has_imu=imu.info.has_imu, R_ci=imu.info.R_ci,
                                        imu_time_offset_s=float(time_offset_s))

    def _imu_batches(self) -> Iterator[ImuBatch]:
        if not self.imu.info.has_imu:
            return
        for event in self.imu.events():
            if isinstance(event, ImuBatch):
                yield event

    def _frames_checked(self) -> Iterator:
        """The camera's events; the first frame's time is checked against the IMU log's span."""
        checked = False
        for event in self.camera.events():
            if not checked and not isinstance(event, ImuBatch):
                self._check_overlap(float(event.t_s))
                checked = True
            yield event

    def _check_overlap(self, t_first_frame_s: float) -> None:
        """`InputError` when no IMU sample falls within the frames' time span (another clock)."""
        span = getattr(self.imu, "span_s", None)
        if span is None:
            return
        info = self.camera.info
        t_last = t_first_frame_s + (info.n_frames / info.fps if info.n_frames and info.fps else 0.0)
        start, end = span[0] + self.info.imu_time_offset_s, span[1] + self.info.imu_time_offset_s
        if not spans_overlap((start, end), (t_first_frame_s, t_last)):
            raise InputError(f"{self.imu.info.name}: column 1 (timestamp): the IMU samples span {start:.6g} to "
                             f"{end:.6g} s and the frames {t_first_frame_s:.6g} to {t_last:.6g} s, with no overlap: "
                             "the IMU log is on another clock than the video (shift its timestamps to the video's)")

    def events(self) -> Iterator:
        yield from interleave(self._frames_checked(), self._imu_batches(), self.info.imu_time_offset_s)

    def sample_frames(self, n: int, limit: int | None = None):
        return self.camera.sample_frames(n, limit)

    def ground_truth(self) -> GroundTruth | None:
        return self.camera.ground_truth() or self.imu.ground_truth()

    def close(self) -> None:
        self.camera.close()
        self.imu.close()


def merge_imu(source: Source, imu_source: Source, time_offset_s: float = 0.0) -> Source:
    """`source`'s frames with `imu_source`'s samples between them (see the module docstring)."""
    return MergedSource(source, imu_source, time_offset_s)
