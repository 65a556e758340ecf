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

import math
from dataclasses import dataclass

import numpy as np

from .. import jit
from ..errors import InputError
from ..types import IMU_COLUMNS as COLUMNS
from ..types import ImuBatch


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


_EMPTY_ROWS = np.zeros((0, COLUMNS))


def rows_if_clean(t, gyro, accel, newest_s, gyro_range_rad_s, rows) -> bool:
    """Whether samples `t` (n,) s, `gyro` (n, 3) rad/s, `accel` (n, 3) m/s^2 are all finite, strictly
    later than `newest_s` and each other, with every gyro axis below `gyro_range_rad_s`; if so they
    are written into `rows` (n, 8) (`types.IMU_COLUMNS`, not saturated). One pass, for
    `ImuStream.add`'s common case (numba-compiled as `_ROWS_IF_CLEAN` when available)."""
    t_prev = newest_s
    for k in range(t.shape[0]):
        if not (t[k] > t_prev and abs(t[k]) < np.inf):  # False for NaN
            return False
        t_prev = t[k]
        rows[k, 0] = t[k]
        for i in range(3):
            g, a = gyro[k, i], accel[k, i]
            if not (abs(g) < gyro_range_rad_s and abs(a) < np.inf):
                return False
            rows[k, 1 + i], rows[k, 4 + i] = g, a
        rows[k, 7] = 0.0
    return True


_ROWS_IF_CLEAN = jit.Kernel(rows_if_clean, cache=True)


_FLOAT64 = np.dtype(np.float64)


def check_imu_arrays(t_s, gyro_rad_s, accel_m_s2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shapes `(N,)`, `(N, 3)`, `(N, 3)` as float arrays, or an `InputError` naming what is wrong."""
    if (type(t_s) is np.ndarray and type(gyro_rad_s) is np.ndarray and type(accel_m_s2) is np.ndarray
            and t_s.dtype is _FLOAT64 and gyro_rad_s.dtype is _FLOAT64 and accel_m_s2.dtype is _FLOAT64
            and t_s.ndim == 1 and gyro_rad_s.shape == accel_m_s2.shape == (t_s.shape[0], 3)):
        return t_s, gyro_rad_s, accel_m_s2  # already what is asked for: no conversion
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
    """Small reorder buffer with drop counting; see the module docstring. Held samples are rows of
    one (N, 8) array, so that appending and releasing cost one numpy call each."""

    def __init__(self, reorder_window_s: float = 0.02, gyro_range_rad_s: float = np.inf):
        self.reorder_window_s = float(reorder_window_s)
        self.gyro_range_rad_s = float(gyro_range_rad_s)
        self.counts = ImuStreamCounts()
        self.watermark_s = -np.inf
        """Time of the newest released sample (or of the last `release_until`): older stamps are late."""
        self._held = _EMPTY_ROWS
        self._saturation_seen = False  # whether any sample reached the gyro range (else no column scan)

    @property
    def held_span_s(self) -> float:
        """Time from the oldest to the newest held sample, s (0 when fewer than two are held)."""
        held = self._held
        return float(held[-1, 0] - held[0, 0]) if held.shape[0] > 1 else 0.0

    @property
    def held_count(self) -> int:
        """Samples held (not yet released)."""
        return self._held.shape[0]

    @property
    def newest_s(self) -> float:
        """Stamp of the newest sample held or released, s (-inf before any)."""
        return float(self._held[-1, 0]) if self._held.shape[0] else self.watermark_s

    def push(self, t_s, gyro_rad_s, accel_m_s2) -> ImuBatch:
        """Add samples; return those now older than the newest by more than the reorder window."""
        self.add(t_s, gyro_rad_s, accel_m_s2)
        if not self._held.shape[0]:
            return ImuBatch.from_rows(_EMPTY_ROWS)
        return self.release_until(self._held[-1, 0] - self.reorder_window_s, move_watermark=False)

    def add(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        """Add samples to the buffer (dropping and counting non-finite, duplicate and late ones)
        without releasing any."""
        t, gyro, accel = check_imu_arrays(t_s, gyro_rad_s, accel_m_s2)
        n = t.shape[0]
        if not n:
            return
        held = self._held
        if _ROWS_IF_CLEAN and self._rows_if_clean(t, gyro, accel, held):
            return
        rows = np.concatenate((t[:, None], gyro, accel, np.zeros((t.shape[0], 1))), axis=1)
        # One pass for both checks: the largest |value| per column (NaN propagates, inf is not finite).
        largest = np.abs(rows).max(axis=0).tolist()
        if not all(map(math.isfinite, largest)):
            finite = np.isfinite(rows).all(axis=1)
            self.counts.nonfinite += int((~finite).sum())
            rows = rows[finite]
            if not rows.shape[0]:
                return
            largest = np.abs(rows).max(axis=0).tolist()
        if max(largest[1:4]) >= self.gyro_range_rad_s:
            rows[:, 7] = np.abs(rows[:, 1:4]).max(axis=1) >= self.gyro_range_rad_s
            self._saturation_seen = True
        held = self._held
        t = rows[:, 0]
        newest = held[-1, 0] if held.shape[0] else self.watermark_s
        if t[0] > newest and (t.shape[0] == 1 or bool((t[1:] > t[:-1]).all())):
            self._append(rows)  # in order
            return
        stale = t <= self.watermark_s
        self.counts.duplicate += int(np.sum(t == self.watermark_s))
        self.counts.late += int(np.sum(t < self.watermark_s))
        rows = rows[~stale]
        if rows.shape[0]:
            rows = np.concatenate([held, rows])
            rows = rows[np.argsort(rows[:, 0], kind="stable")]
            unique = np.ones(rows.shape[0], bool)
            unique[1:] = rows[1:, 0] != rows[:-1, 0]
            self.counts.duplicate += int((~unique).sum())
            self._held = rows[unique]

    def add_checked_rows(self, rows: np.ndarray) -> None:
        """Add rows (n, 8) (`types.IMU_COLUMNS`) already checked as `add` checks them (`rows_if_clean`
        against `newest_s` and the gyro range: finite, in order, later than what is held, not saturated),
        so none is dropped or counted; copied (the caller may reuse its array). `Mekf` puts back a
        batch staged for a frame this way, with nothing held."""
        self._append(rows.copy())

    def _rows_if_clean(self, t, gyro, accel, held) -> bool:
        """The common case of `add` in one compiled pass: samples clean and in order are appended
        (True). False leaves them to the checks of `add`; so does a kernel that fails to compile
        (one warning, and the checks of `add` from then on)."""
        rows = np.empty((t.shape[0], COLUMNS))
        clean = _ROWS_IF_CLEAN(t, gyro, accel, held[-1, 0] if held.shape[0] else self.watermark_s,
                               self.gyro_range_rad_s, rows)
        if clean is jit.FALLBACK:
            return False
        if clean:
            self._append(rows)
        return clean

    def _append(self, rows: np.ndarray) -> None:
        """Put `rows` (n, 8), later than every held row, after them; kept as they are when nothing is held."""
        held = self._held
        self._held = np.concatenate([held, rows]) if held.shape[0] else rows

    @property
    def saturation_seen(self) -> bool:
        """Whether any sample so far reached the gyro range (else no release holds a saturated one)."""
        return self._saturation_seen

    def release_until(self, t_s: float, move_watermark: bool = True) -> ImuBatch:
        """Release every held sample stamped at or before `t_s`; later arrivals older than `t_s`
        then count as late when `move_watermark`."""
        return ImuBatch.from_rows(self.release_rows_until(t_s, move_watermark))

    def release_rows_until(self, t_s: float, move_watermark: bool = True) -> np.ndarray:
        """`release_until`'s samples as rows (N, 8) (`types.IMU_COLUMNS`)."""
        held = self._held
        if not held.shape[0]:
            k = 0
        elif held[-1, 0] <= t_s:  # all of it (a frame after its samples): no search
            k = held.shape[0]
        else:
            k = int(np.searchsorted(held[:, 0], t_s, side="right"))
        out = held[:k]
        self._held = held[k:]
        if k:
            self.watermark_s = max(self.watermark_s, float(out[-1, 0]))
            if self._saturation_seen:
                self.counts.saturated += int(np.count_nonzero(out[:, 7]))
        if move_watermark and math.isfinite(t_s):
            self.watermark_s = max(self.watermark_s, float(t_s))
        return out

    def released_elsewhere(self, t_s: float) -> None:
        """Samples up to `t_s`, checked as `add` checks them (finite, in order, later than the
        watermark, below the gyro range), went to their consumer without this buffer (nothing held):
        later stamps at or before `t_s` now count as late, as after `release_until(t_s)`."""
        self.watermark_s = max(self.watermark_s, float(t_s))

    def flush(self) -> ImuBatch:
        """Release everything held."""
        return self.release_until(np.inf, move_watermark=False)
