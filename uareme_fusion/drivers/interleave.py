"""Putting IMU samples between frames: the time-ordering every source with an IMU needs.

    imu = ImuInterleaver(batches, time_offset_s=info.imu_time_offset_s)
    for frame in frames:
        batch = imu.until(frame.t_s)          # every sample no later than the frame (camera clock)
        if batch is not None:
            yield batch
        yield frame
    yield from imu.rest()

Clocks: batches carry IMU-clock stamps (as the IMU wrote them); a sample stamped `t` happened at
camera time `t + time_offset_s` (`SourceInfo.imu_time_offset_s`), and that camera time decides
where it goes in the stream. Stamps are never rewritten, so a recording keeps the IMU clock.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator

import numpy as np

from ..types import ImuBatch

IMU_ONLY_BATCH_S = 1.0 / 30.0
"""Span of the batches IMU-only sources yield: the pipeline reports one estimate per batch."""


SPLIT_BLOCK_BATCHES = 256
"""`split_by_span` copies the arrays into batch rows this many batches at a time (one copy per block,
batches are views of it): bounded memory, and no per-batch copy."""


def split_by_span(t_s: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray,
                  span_s: float = IMU_ONLY_BATCH_S) -> Iterator[ImuBatch]:
    """In-memory IMU arrays as consecutive batches each covering about `span_s` seconds; the stream
    IMU-only sources yield."""
    cuts = _span_cuts(t_s, span_s).tolist()
    for first in range(0, max(len(cuts) - 1, 0), SPLIT_BLOCK_BATCHES):
        block = cuts[first:first + SPLIT_BLOCK_BATCHES + 1]
        start = block[0]
        rows = ImuBatch(t_s[start:block[-1]], gyro_rad_s[start:block[-1]], accel_m_s2[start:block[-1]]).rows
        for a, b in zip(block[:-1], block[1:]):
            yield ImuBatch.from_rows(rows[a - start:b - start])


def count_spans(t_s: np.ndarray, span_s: float = IMU_ONLY_BATCH_S) -> int:
    """How many batches `split_by_span` yields for stamps `t_s` (an IMU-only run's estimates)."""
    return max(len(_span_cuts(t_s, span_s)) - 1, 0)


def _span_cuts(t_s: np.ndarray, span_s: float) -> np.ndarray:
    """Indices where `split_by_span`'s batches start, and `len(t_s)` at the end."""
    if len(t_s) == 0:
        return np.zeros(0, int)
    edges = np.arange(t_s[0] + span_s, t_s[-1] + span_s, span_s)
    return np.unique(np.concatenate([[0], np.searchsorted(t_s, edges, side="right"), [len(t_s)]]))


def release_until(pending: list[ImuBatch], t_s: float) -> tuple[ImuBatch | None, list[ImuBatch]]:
    """Split held batches at stamp `t_s`: (the samples stamped <= `t_s` as one batch, or None when
    there are none; the batches still held)."""
    if not pending:
        return None, []
    held = ImuBatch.concat(pending)
    cut = int(np.searchsorted(held.t_s, t_s, side="right"))
    return (held[:cut] if cut else None), ([held[cut:]] if cut < len(held) else [])


class AccelerometerFeed:
    """Samples of an accelerometer without gyro (`Source.accelerometer`, IMU clock) handed out up to each
    frame's time (camera clock: a sample stamped `t` happened at `t + time_offset_s`)."""

    def __init__(self, t_s: np.ndarray, accel_m_s2: np.ndarray, time_offset_s: float = 0.0):
        self.t_s, self.accel_m_s2 = np.asarray(t_s, float), np.asarray(accel_m_s2, float)
        self.time_offset_s = float(time_offset_s)
        self._next = 0

    def until(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """The samples not handed out yet that happened no later than camera time `t_s`: (t_s (n,), accel (n, 3))."""
        end = max(int(np.searchsorted(self.t_s, t_s - self.time_offset_s, side="right")), self._next)
        start, self._next = self._next, end
        return self.t_s[start:end], self.accel_m_s2[start:end]


class ImuInterleaver:
    """Hands out IMU samples in camera-time order, pulling batches from an iterator only as far as
    needed (a live IMU is never read ahead by more than one batch)."""

    def __init__(self, batches: Iterable[ImuBatch], time_offset_s: float = 0.0):
        self._source = iter(batches)
        self.time_offset_s = float(time_offset_s)
        self._pending: list[ImuBatch] = []
        self._exhausted = False
        self.n_samples = 0
        """Samples handed out so far."""

    def _newest_cam_s(self) -> float:
        return self._pending[-1].t_s[-1] + self.time_offset_s if self._pending else -np.inf

    def until(self, t_cam_s: float) -> ImuBatch | None:
        """All not yet released samples whose camera time is <= `t_cam_s`, as one batch (None when
        there are none)."""
        while not self._exhausted and self._newest_cam_s() <= t_cam_s:
            batch = next(self._source, None)
            if batch is None:
                self._exhausted = True
            elif len(batch):
                self._pending.append(batch)
        released, self._pending = release_until(self._pending, t_cam_s - self.time_offset_s)
        if released is not None:
            self.n_samples += len(released)
        return released

    def rest(self) -> Iterator[ImuBatch]:
        """The samples after the last frame, batch by batch."""
        yield from self._pending
        self.n_samples += sum(len(b) for b in self._pending)
        self._pending = []
        if not self._exhausted:
            for batch in self._source:
                if len(batch):
                    self.n_samples += len(batch)
                    yield batch
            self._exhausted = True


def interleave(frames: Iterable, imu_batches: Iterable[ImuBatch] | None, time_offset_s: float = 0.0) -> Iterator:
    """Frames with the IMU samples due before each one (see the module docstring); the IMU's tail
    after the last frame comes last."""
    if imu_batches is None:
        yield from frames
        return
    imu = ImuInterleaver(imu_batches, time_offset_s)
    for frame in frames:
        batch = imu.until(frame.t_s)
        if batch is not None:
            yield batch
        yield frame
    yield from imu.rest()
