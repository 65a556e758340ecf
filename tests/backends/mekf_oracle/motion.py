"""The oracle's motion: the reference propagation (numpy chunks, filterpy `predict`) in the motion
strategies of the package, whose scheduling (release, initialisation, re-initialisation) it keeps.

- `GyroMotion`: samples integrated chunk by chunk (`propagation.gyro_chunk`), gaps, saturated samples
  and stale extrapolations as unknown rotations, the accelerometer updates falling due per period;
- `ConstantRateMotion`: `propagation.constant_rate_model` between frames;
- `ImageRotationMotion`: `propagation.image_rotation_model` for a frame with an image rotation.
"""

from __future__ import annotations

import math

import numpy as np
from filterpy.kalman import predict as kf_predict

from uareme_fusion.backends.mekf import image_rotation_motion
from uareme_fusion.backends.mekf import motion as production
from uareme_fusion.backends.mekf import status_bits
from uareme_fusion.backends.mekf.accel import PERIOD_TOLERANCE_S, chunk_bounds
from uareme_fusion.backends.mekf.state import MF, N_STATE, TH, ZERO_STATE, orthonormal
from uareme_fusion.types import IMU_COLUMNS as COLUMNS
from uareme_fusion.types import ImuBatch

from .propagation import constant_rate_model, gyro_chunk, gyro_process_noise, gyro_rates, gyro_transition
from .propagation import image_rotation_model
from .propagation import manhattan_walk_noise

_NO_ROWS = np.zeros((0, COLUMNS))


class ConstantRateMotion(production.ConstantRateMotion):
    """Visual only, the reference constant-rate prediction."""

    def propagate_to(self, filt, t_s: float, visual=None) -> None:
        """`R_wc <- R_wc Exp(omega_c dt)` and the covariance prediction, to `t_s` (s)."""
        if filt.initialised and t_s > filt.t_state:
            M, F, Q = constant_rate_model(filt.omega_c, t_s - filt.t_state, filt.config.rate_rw_rad_s2_sqrt_hz**2)
            filt.R_wc = orthonormal(filt.R_wc @ M)
            _, filt.P = kf_predict(np.zeros(N_STATE), filt.P, F, Q)
            filt.t_state = t_s


class ImageRotationMotion(image_rotation_motion.ImageRotationMotion):
    """Visual only by the image rotation, the reference predictions: `propagation.constant_rate_model`
    without one, `propagation.image_rotation_model` with."""

    def predict_by_rate(self, filt, t_s: float) -> None:
        M, F, Q = constant_rate_model(filt.omega_c, t_s - filt.t_state, filt.config.rate_rw_rad_s2_sqrt_hz**2)
        filt.R_wc = orthonormal(filt.R_wc @ M)
        _, filt.P = kf_predict(np.zeros(N_STATE), filt.P, F, Q)
        filt.t_state = t_s

    def predict_by_image(self, filt, t_s: float, R_cp: np.ndarray, var_rad2: float) -> None:
        dt_s = t_s - filt.t_state
        filt.R_wc = orthonormal(filt.R_wc @ R_cp.T)
        filt.omega_c, filt.P = image_rotation_model(R_cp, var_rad2, dt_s, filt.config.rate_rw_rad_s2_sqrt_hz**2, filt.P)
        filt.t_state = t_s


class GyroMotion(production.GyroMotion):
    """Gyro-driven, the reference integration."""

    def propagate_to(self, filt, t_s: float, visual=None) -> None:
        """Integrate IMU samples up to `t_s` (camera clock, s), then hold the last rate."""
        rows = filt.stream.release_rows_until(t_s)
        filt.queue(ImuBatch.from_rows(rows))
        self.integrate_pending(filt, extrapolate_to_s=t_s, force_init=True)

    def integrate_rows(self, filt, rows: np.ndarray, extra_s: float, defer: bool) -> None:
        """The reference integration of camera-frame rows: chunk by chunk, the updates falling due."""
        t, gyro_c, accel_c, saturated = rows[:, 0], rows[:, 1:4], rows[:, 4:7], rows[:, 7]
        acc = filt.accel
        period = filt.config.accel_update_period_s
        due_s = period - PERIOD_TOLERANCE_S
        bounds = chunk_bounds(t, filt.t_state, filt.accel.elapsed_s, period).tolist()
        # A long batch is split at accelerometer-update boundaries: every chunk but the last one
        # crossed one and ends with an update (each update then averages between `period` and
        # `period` + one sample step); a short one (a frame's worth) is one chunk.
        for i in range(len(bounds) - 1):
            a, b = bounds[i], bounds[i + 1]
            last = i == len(bounds) - 2
            self._integrate_chunk(filt, t[a:b], gyro_c[a:b], accel_c[a:b], saturated[a:b], extra_s if last else 0.0)
            if not last or acc.elapsed_s >= due_s:
                acc.due = True
                if not (last and defer):
                    filt.accel_update()

    def _integrate_chunk(self, filt, t, gyro_c, accel_c, saturated, extra_s: float = 0.0) -> None:
        """Integrate samples (camera frame) over (t_state, t[-1]]: sample k covers (t_{k-1}, t_k]
        with the mean of its rate and the previous one (trapezoid), or its own rate (`interval`);
        then, for `extra_s` > 0, hold the last rate that much longer (to a frame's time; no
        accelerometer reading there). Gaps and saturated samples are not integrated: the attitude
        variance grows by `unknown_rate_std_rad_s` over them instead."""
        cfg = filt.config
        n = t.size
        m = n + 1 if extra_s > 0 else n
        resumed = bool(n and filt.in_imu_gap)  # first samples after frames bridged an IMU gap
        any_saturated = bool(n and filt.stream.counts.saturated and saturated.any())
        if n:
            filt.imu_t_s = float(t[-1])
            filt.in_imu_gap = False
            if any_saturated:
                gyro_c = self._hold_unsaturated(filt.last_gyro_c, gyro_c, saturated)
        # A frame more than `imu_gap_limit_s` past the newest IMU sample: the IMU stopped, so the
        # extrapolation is an unknown rotation, not the last rate held.
        stale = (m > n and math.isfinite(filt.imu_t_s)
                 and filt.t_state + extra_s - filt.imu_t_s > cfg.imu_gap_limit_s)
        # Sample times from the state time (and to the extrapolated end), and the gyro readings with
        # the previous one in front (and the last one held over the extrapolation).
        t_all = np.empty(m + 1)
        t_all[0], t_all[1:n + 1] = filt.t_state, t
        g_all = np.empty((m + 1, 3))
        g_all[0], g_all[1:n + 1] = filt.last_gyro_c, gyro_c
        if m > n:
            t_all[m], g_all[m] = t_all[n] + extra_s, g_all[n]
        if resumed:  # the reading before the gap is stale: the step to the first new one is unknown
            g_all[0] = g_all[1]
        dt = t_all[1:] - t_all[:-1]
        rate_c = gyro_rates(g_all, filt.b_c, filt.trapezoid)
        filt.last_gyro_c = g_all[n]
        unknown_var = 0.0
        T_elapsed = float(dt.sum())
        if stale or resumed or dt.max() > cfg.imu_gap_limit_s or any_saturated:
            gap = dt > cfg.imu_gap_limit_s
            if stale:
                gap[m - 1] = True
            unknown = gap.copy()
            unknown[:n] |= saturated > 0
            unknown[0] |= resumed
            unknown_var = float(np.sum((cfg.unknown_rate_std_rad_s * dt[unknown]) ** 2))
            if gap.any():
                filt.flags |= status_bits.IMU_GAP
                filt.counters["imu_gaps"] += int(gap[:n].sum()) + int(stale and not filt.in_imu_gap)
                filt.in_imu_gap |= bool(stale)
            if saturated.any():
                filt.flags |= status_bits.GYRO_SATURATED
            dt[gap] = 0.0
            filt.accel.lose_lowpass()
        C, A_bias = gyro_chunk(rate_c, dt)
        C_N = C[-1]
        if cfg.record_imu_estimates and n:
            filt.record_t.append(t.copy())
            filt.record_R.append(filt.R_wc @ C[:n])
        filt.R_wc = filt.R_wc @ C_N
        filt.count_product()
        T = T_elapsed if unknown_var == 0.0 else float(dt.sum())
        F = gyro_transition(C_N, A_bias, filt.F_buffer)
        rate_var = filt.q_rate * float(np.einsum("ki,ki,k->", rate_c, rate_c, dt)) if filt.q_rate else 0.0
        Q = gyro_process_noise(T, filt.q_gyro, filt.q_bias, unknown_var, rate_var)
        if filt.manhattan_walks and filt.manhattan_initialised and T_elapsed > 0:
            Q[MF, MF] += manhattan_walk_noise(filt.R_wm, T_elapsed, cfg.manhattan_yaw_rw_rad_per_sqrt_s,
                                              cfg.manhattan_tilt_rw_rad_per_sqrt_s)
        _, filt.P = kf_predict(ZERO_STATE, filt.P, F, Q)
        if cfg.record_imu_estimates and n:
            filt.record_P.append(np.repeat(filt.P[None, TH, TH], n, axis=0))
        accel_time_s = T_elapsed - extra_s if unknown_var == 0.0 else float(dt[:n].sum())
        filt.accel.add_chunk(C, accel_c, dt, accel_time_s if n else 0.0, T_elapsed)
        filt.accel.carry_lowpass(C_N, A_bias)
        if cfg.rest_gyro_max_rad_s > 0 and n:
            filt.accel.add_rest(gyro_c, accel_c)
        filt.t_state = float(t[-1]) + extra_s if n else filt.t_state + extra_s

    @staticmethod
    def _hold_unsaturated(last_gyro_c: np.ndarray, gyro_c: np.ndarray, saturated: np.ndarray) -> np.ndarray:
        """Gyro readings (n, 3) rad/s with each saturated sample replaced by the last unsaturated
        reading before it (`last_gyro_c` (3,) before the first): beyond the range the true rate is
        unknown, and a reading pinned at full scale would spin the attitude by its whole range."""
        index = np.where(saturated > 0, -1, np.arange(saturated.size))
        np.maximum.accumulate(index, out=index)
        return np.where((index >= 0)[:, None], gyro_c[np.maximum(index, 0)], last_gyro_c)
