"""The oracle's accelerometer period: the package's `AccelPeriod` (its fields in the state buffer)
with the reference numpy methods: averaging over a period in the gyro-carried frame, the two
low-pass stages and their bias sensitivity, rest detection."""

from __future__ import annotations

import numpy as np

from uareme_fusion.backends.mekf import accel as production
from uareme_fusion.rotations import skew

from .measurements import zero_rate_model


class AccelPeriod(production.AccelPeriod):
    """`production.AccelPeriod` with the reference methods."""

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
        at_rest, r, R, H = zero_rate_model(sums, n, T_s, b_c, q_gyro, cfg.rest_gyro_max_rad_s,
                                           cfg.rest_accel_max_m_s2, cfg.rest_rate_std_rad_s)
        if not at_rest:
            self.rest_since_s = None
            return None
        if self.rest_since_s is None:
            self.rest_since_s = t_state_s - T_s
        if t_state_s - self.rest_since_s < cfg.rest_min_duration_s:
            return None
        return r, R, H
