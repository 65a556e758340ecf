"""Accelerometer handling of `Mekf`: averaging over an update period, low-pass, rest detection.

Specific force is summed time-weighted in a common camera frame (rotated along by the gyro), so its
mean is the inertial-frame average and translational accelerations cancel in it. With
`accel_lowpass_tau_s` two cascaded first-order stages filter the period means in that almost-inertial
frame; their sensitivity to the gyro-bias error (the frame they were carried in turned with the
estimated bias) is kept beside them, `lp_J`. Rest detection keeps raw gyro and accelerometer sums.
"""

from __future__ import annotations

import numpy as np

from uareme_fusion.rotations import skew
from .measurements import zero_rate_model
from uareme_fusion.backends.mekf.state_buffer import (S_ACCEL_ELAPSED, S_ACCEL_TIME, S_ACCEL_DUE, S_LP_VALID, S_REST_N,
                                                      S_REST_SINCE, BufferArray,
                                                      BufferScalar, field_views, new_state_buffer)

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

    All of it lives in the filter's state buffer `x` (`state_buffer.py`), which the compiled kernels
    update in place; without `x` the period has a buffer of its own.
    """

    sum_c = BufferArray("accel_sum")
    lp_J = BufferArray("lp_J")
    rest_sums = BufferArray("rest_sums")
    time_s = BufferScalar(S_ACCEL_TIME)
    elapsed_s = BufferScalar(S_ACCEL_ELAPSED)
    due = BufferScalar(S_ACCEL_DUE, bool)
    rest_n = BufferScalar(S_REST_N, int)
    rest_since_s = BufferScalar(S_REST_SINCE, optional=True)

    def __init__(self, x: np.ndarray | None = None):
        self.x = new_state_buffer() if x is None else x
        self.views = field_views(self.x)

    @property
    def lp_c(self) -> np.ndarray | None:
        return self.views["lp"] if self.x[S_LP_VALID] else None

    @lp_c.setter
    def lp_c(self, value) -> None:
        self.x[S_LP_VALID] = value is not None
        if value is not None:
            self.views["lp"][...] = value

    def add_chunk(self, C: np.ndarray, accel_c: np.ndarray, dt_s: np.ndarray, time_s: float,
                  elapsed_s: float) -> None:
        """Add a chunk's samples `accel_c` (n, 3) m/s^2 held over `dt_s` (n,) s, turned by the chunk's
        cumulative rotations `C` (m >= n, 3, 3), and re-express the sum in the chunk's end frame;
        `time_s` is the time the samples cover, `elapsed_s` the chunk's length."""
        C_N, n = C[-1], accel_c.shape[0]
        if n:
            self.sum_c = C_N.T @ (self.sum_c + np.einsum("kjl,kl,k->j", C[:n], accel_c, dt_s[:n]))
        else:
            self.sum_c = C_N.T @ self.sum_c
        self.time_s += time_s
        self.elapsed_s += elapsed_s

    def carry_lowpass(self, C_N: np.ndarray, A_bias: np.ndarray) -> None:
        """Carry the low-pass stages through a chunk turning by `C_N` (3, 3) whose bias transition
        is `A_bias` (3, 3): with the true bias the chunk turns by `C_N Exp(-A_bias db)`, so a carried
        vector v reads `C_N^T v - skew(C_N^T v) A_bias db`."""
        if self.lp_c is None:
            return
        lp = self.lp_c = self.lp_c @ C_N  # rows v^T C_N = (C_N^T v)^T
        J = np.matmul(C_N.T, self.lp_J, out=self.lp_J)
        J[0] -= skew(lp[0]) @ A_bias
        J[1] -= skew(lp[1]) @ A_bias

    def lose_lowpass(self) -> None:
        """An IMU gap: the frame carried along by the gyro is lost."""
        self.lp_c = None

    def reinject(self, db_c: np.ndarray) -> None:
        """The bias estimate moved by `db_c` (3,) rad/s: re-carry the low-pass stages with it."""
        if self.lp_c is not None:
            self.lp_c += self.lp_J @ db_c

    def add_rest(self, gyro_c: np.ndarray, accel_c: np.ndarray) -> None:
        """Add raw readings `gyro_c` (n, 3) rad/s and `accel_c` (n, 3) m/s^2 to the rest statistics."""
        sums = self.rest_sums
        sums[0:3] += gyro_c.sum(axis=0)
        sums[3] += float(np.einsum("ki,ki->", gyro_c, gyro_c))
        sums[4:7] += accel_c.sum(axis=0)
        sums[7] += float(np.einsum("ki,ki->", accel_c, accel_c))
        self.rest_n += gyro_c.shape[0]

    def take_mean(self) -> tuple[np.ndarray, float]:
        """`(mean specific force (3,) m/s^2, time it covers s)` of the period, which restarts."""
        T = self.time_s
        accel_c = self.sum_c / T if T > 0 else self.sum_c.copy()
        self.sum_c, self.time_s, self.elapsed_s = 0.0, 0.0, 0.0
        return accel_c, T

    def lowpass(self, accel_c: np.ndarray, T_s: float, tau_s: float) -> np.ndarray:
        """Feed the period mean `accel_c` (3,) m/s^2 over `T_s` s to the two stages (time constant
        `tau_s` each) and return the second stage; the period's own mean is taken as bias-free (its
        age is ~T/2). `accel_c` unchanged when `tau_s` or `T_s` is 0."""
        if not (tau_s > 0 and T_s > 0):
            return accel_c
        lp = self.lp_c
        if lp is None:
            lp = self.lp_c = np.array([accel_c, accel_c])
            self.lp_J = np.zeros((2, 3, 3))
        else:
            alpha = 1.0 - np.exp(-T_s / tau_s)
            lp[0] += alpha * (accel_c - lp[0])
            lp[1] += alpha * (lp[0] - lp[1])
            J = self.lp_J
            J[0] *= 1.0 - alpha
            J[1] += alpha * (J[0] - J[1])
        return lp[1]

    def rest_measurement(self, T_s: float, t_state_s: float, b_c: np.ndarray, cfg, q_gyro: float):
        """Rest detection over the period just completed (`T_s` s, ending at `t_state_s`): after
        `cfg.rest_min_duration_s` of rest, the zero-rate measurement `(residual (3,), R (3, 3), H (3, 12))`
        of the bias `b_c` (3,) rad/s; None otherwise. Consumes the rest sums."""
        sums, n = self.rest_sums.copy(), self.rest_n
        self.rest_sums, self.rest_n = 0.0, 0
        if n < 2 or T_s <= 0:
            return None
        at_rest, r, var, H = zero_rate_model(sums, n, T_s, b_c, q_gyro, cfg.rest_gyro_max_rad_s,
                                             cfg.rest_accel_max_m_s2, cfg.rest_rate_std_rad_s)
        if not at_rest:
            self.rest_since_s = None
            return None
        if self.rest_since_s is None:
            self.rest_since_s = t_state_s - T_s
        if t_state_s - self.rest_since_s < cfg.rest_min_duration_s:
            return None
        return r, var * np.eye(3), H


def tilt_direction(accel_c: np.ndarray) -> np.ndarray:
    """Unit up direction (3,) in the camera frame from a mean specific force (3,) m/s^2 (down-the-image
    when there is none)."""
    if not np.linalg.norm(accel_c) > 0:
        accel_c = np.array([0.0, -1.0, 0.0])
    return accel_c / np.linalg.norm(accel_c)
