"""Accelerometer handling of `Mekf`: the period's statistics in the state buffer, and its chunks.

Specific force is summed time-weighted in a common camera frame (rotated along by the gyro), so its
mean is the inertial-frame average and translational accelerations cancel in it. With
`accel_lowpass_tau_s` two cascaded first-order stages filter the period means in that almost-inertial
frame; their sensitivity to the gyro-bias error (the frame they were carried in turned with the
estimated bias) is kept beside them, `lp_J`. Rest detection keeps raw gyro and accelerometer sums.
The kernels do all of it (`kernel_imu.integrate_chunks`, `kernel_update.accel_rows`); `AccelPeriod`
reads and writes the fields, and `chunk_bounds` cuts a batch at the period's boundaries.
"""

from __future__ import annotations

import numpy as np

from .state_buffer import BufferArray, BufferScalar, field_views, new_state_buffer

PERIOD_TOLERANCE_S = 1e-9
"""An accelerometer period counts as complete this close to its length (sums of sample steps round)."""


def chunk_bounds(t: np.ndarray, t_state_s: float, elapsed_s: float, period_s: float) -> np.ndarray:
    """Chunk limits of a batch `t` (n,) s that continues from `t_state_s` with `elapsed_s` of the
    current accelerometer period gone (chunk k is samples bounds[k]:bounds[k+1]): one chunk for a
    short batch (a frame's worth), else a cut after each sample whose interval crosses a period
    boundary (a sample belongs to the chunk in which its interval starts)."""
    n = t.shape[0]
    if n < 2 or t[n - 1] - t_state_s <= period_s:
        cuts = np.zeros(0, np.int64)
    else:
        elapsed_before = np.empty(n)
        elapsed_before[0] = elapsed_s
        elapsed_before[1:] = elapsed_s + (t[:-1] - t_state_s)
        periods = np.floor(elapsed_before / period_s)
        cuts = np.flatnonzero(periods[1:] != periods[:-1]) + 1
    bounds = np.empty(cuts.shape[0] + 2, np.int64)  # plain array code: the compiled kernels share it
    bounds[0], bounds[-1] = 0, n
    bounds[1:-1] = cuts
    return bounds


class AccelPeriod:
    """Accelerometer and rest statistics since the last update, in the current camera frame.

    `sum_c` (3,) m/s^2*s time-weighted specific force; `time_s` the time its samples cover;
    `elapsed_s` the time since the last update (frame extrapolations too); `due` a completed period
    waits for a frame's visual update; `lp_c` (2, 3) m/s^2 the low-pass stages (None until the first
    update) and `lp_J` (2, 3, 3) their sensitivity to the gyro-bias error (zeros until then): with the
    true bias they would read `lp + lp_J @ db`; `rest_sums` (8,) gyro, |gyro|^2, accel, |accel|^2 sums
    over `rest_n` samples; `rest_since_s` when rest began (None when moving).

    All of it lives in the filter's state buffer `x` (`state_buffer.py`), which the kernels update in
    place; without `x` the period has a buffer of its own.
    """

    sum_c = BufferArray("accel_sum")
    lp_J = BufferArray("lp_J")
    rest_sums = BufferArray("rest_sums")
    time_s = BufferScalar("accel_time_s")
    elapsed_s = BufferScalar("accel_elapsed_s")
    due = BufferScalar("accel_due", bool)
    rest_n = BufferScalar("rest_n", int)
    rest_since_s = BufferScalar("rest_since_s", optional=True)
    lp_valid = BufferScalar("lp_valid", bool)

    def __init__(self, x: np.ndarray | None = None):
        self.x = new_state_buffer() if x is None else x
        self.views = field_views(self.x)

    @property
    def lp_c(self) -> np.ndarray | None:
        return self.views["lp"] if self.lp_valid else None

    @lp_c.setter
    def lp_c(self, value) -> None:
        self.lp_valid = value is not None
        if value is not None:
            self.views["lp"][...] = value


def tilt_direction(accel_c: np.ndarray) -> np.ndarray:
    """Unit up direction (3,) in the camera frame from a mean specific force (3,) m/s^2 (down-the-image
    when there is none)."""
    if not np.linalg.norm(accel_c) > 0:
        accel_c = np.array([0.0, -1.0, 0.0])
    return accel_c / np.linalg.norm(accel_c)
