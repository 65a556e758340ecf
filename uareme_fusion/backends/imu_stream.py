"""Cleaning an IMU stream before a filter sees it: reorder, drop and count, flag saturation.

`ImuStream.push` takes arrays of samples as they arrive (any order, possibly with NaN/Inf rows or
repeated stamps) and returns, in strictly increasing time order, the samples that are older than
the newest one by more than `reorder_window_s` (so a sample that arrives late by less than that
window is put back in its place). `release_until(t_s)` and `flush()` release the rest.

What is dropped is counted in `ImuStream.counts`, never silently skipped:
- `nonfinite`: a NaN or infinite time, gyro or accelerometer component;
- `duplicate`: a stamp equal to one already held or released (the first one is kept);
- `late`: a stamp older than what was already released (arrived after the reorder window).
Samples whose gyro reaches `gyro_range_rad_s` on any axis are kept and flagged in the release.

Units: seconds, rad/s, m/s^2, in whatever frame the caller uses (the IMU frame `i`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError


@dataclass
class ImuStreamCounts:
    """Samples dropped or flagged since the stream was created."""

    nonfinite: int = 0
    duplicate: int = 0
    late: int = 0
    saturated: int = 0

    @property
    def dropped(self) -> int:
        return self.nonfinite + self.duplicate + self.late


@dataclass(frozen=True)
class ImuBatch:
    """Released samples in strictly increasing time: `t_s` (N,), `gyro_rad_s` (N, 3),
    `accel_m_s2` (N, 3), `saturated` (N,) bool (gyro at or beyond its range on some axis)."""

    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    saturated: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.size)


def _empty_batch() -> ImuBatch:
    return ImuBatch(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, bool))


def check_imu_arrays(t_s, gyro_rad_s, accel_m_s2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shapes `(N,)`, `(N, 3)`, `(N, 3)` as float arrays, or an `InputError` naming what is wrong."""
    t = np.atleast_1d(np.asarray(t_s, dtype=float))
    gyro = np.asarray(gyro_rad_s, dtype=float)
    accel = np.asarray(accel_m_s2, dtype=float)
    if gyro.ndim == 1:
        gyro = gyro[None, :]
    if accel.ndim == 1:
        accel = accel[None, :]
    n = t.shape[0]
    if t.ndim != 1 or gyro.shape != (n, 3) or accel.shape != (n, 3):
        raise InputError(
            f"Expected IMU arrays t_s (N,), gyro_rad_s (N, 3), accel_m_s2 (N, 3); got "
            f"{np.shape(t_s)}, {np.shape(gyro_rad_s)}, {np.shape(accel_m_s2)}"
        )
    return t, gyro, accel


class ImuStream:
    """Small reorder buffer with drop counting; see the module docstring."""

    def __init__(self, reorder_window_s: float = 0.02, gyro_range_rad_s: float = np.inf):
        self.reorder_window_s = float(reorder_window_s)
        self.gyro_range_rad_s = float(gyro_range_rad_s)
        self.counts = ImuStreamCounts()
        self.watermark_s = -np.inf
        """Time of the newest released sample (or of the last `release_until`): older stamps are late."""
        self._held = _empty_batch()

    def push(self, t_s, gyro_rad_s, accel_m_s2) -> ImuBatch:
        """Add samples; return those now older than the newest by more than the reorder window."""
        t, gyro, accel = check_imu_arrays(t_s, gyro_rad_s, accel_m_s2)
        finite = np.isfinite(t) & np.isfinite(gyro).all(axis=1) & np.isfinite(accel).all(axis=1)
        if not finite.all():
            self.counts.nonfinite += int((~finite).sum())
            t, gyro, accel = t[finite], gyro[finite], accel[finite]
        held = self._held
        newest = held.t_s[-1] if len(held) else self.watermark_s
        if t.size and t[0] > newest and (t.size == 1 or bool((t[1:] > t[:-1]).all())):
            # In order (the usual case): append.
            saturated = (np.abs(gyro) >= self.gyro_range_rad_s).any(axis=1)
            self._held = ImuBatch(np.concatenate([held.t_s, t]), np.concatenate([held.gyro_rad_s, gyro]),
                                  np.concatenate([held.accel_m_s2, accel]), np.concatenate([held.saturated, saturated]))
            return self.release_until(t[-1] - self.reorder_window_s, move_watermark=False)
        stale = t <= self.watermark_s
        self.counts.duplicate += int(np.sum(t == self.watermark_s))
        self.counts.late += int(np.sum(t < self.watermark_s))
        t, gyro, accel = t[~stale], gyro[~stale], accel[~stale]
        if t.size:
            t_all = np.concatenate([held.t_s, t])
            gyro_all = np.concatenate([held.gyro_rad_s, gyro])
            accel_all = np.concatenate([held.accel_m_s2, accel])
            order = np.argsort(t_all, kind="stable")
            t_all, gyro_all, accel_all = t_all[order], gyro_all[order], accel_all[order]
            unique = np.ones(t_all.size, bool)
            unique[1:] = t_all[1:] != t_all[:-1]
            self.counts.duplicate += int((~unique).sum())
            saturated = (np.abs(gyro_all[unique]) >= self.gyro_range_rad_s).any(axis=1)
            self._held = ImuBatch(t_all[unique], gyro_all[unique], accel_all[unique], saturated)
        if not len(self._held):
            return _empty_batch()
        return self.release_until(self._held.t_s[-1] - self.reorder_window_s, move_watermark=False)

    def release_until(self, t_s: float, move_watermark: bool = True) -> ImuBatch:
        """Release every held sample stamped at or before `t_s`; later arrivals older than `t_s`
        then count as late when `move_watermark`."""
        held = self._held
        k = int(np.searchsorted(held.t_s, t_s, side="right"))
        out = ImuBatch(held.t_s[:k], held.gyro_rad_s[:k], held.accel_m_s2[:k], held.saturated[:k])
        self._held = ImuBatch(held.t_s[k:], held.gyro_rad_s[k:], held.accel_m_s2[k:], held.saturated[k:])
        if k:
            self.watermark_s = max(self.watermark_s, float(out.t_s[-1]))
            self.counts.saturated += int(out.saturated.sum())
        if move_watermark and np.isfinite(t_s):
            self.watermark_s = max(self.watermark_s, float(t_s))
        return out

    def flush(self) -> ImuBatch:
        """Release everything held."""
        return self.release_until(np.inf, move_watermark=False)
