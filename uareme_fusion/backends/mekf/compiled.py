"""`Mekf`'s compiled IMU path: packs the filter's state for `kernels.integrate_batch` and back.

Used for released batches without gaps, saturated samples or a resumed stream (those keep the
reference path in `motion.GyroMotion`, which handles them); tests check both paths agree.
"""

from __future__ import annotations

import math

import numpy as np

from ...types import Status
from . import kernels as K
from .accel import PERIOD_TOLERANCE_S, chunk_bounds
from .kernels import KERNEL
from .state import ORTHONORMALISE_EVERY


def compiled_path_applies(filt, t: np.ndarray, saturated: np.ndarray, extra_s: float) -> bool:
    """Whether a batch (camera clock) can take the compiled path: samples present, not just after an
    IMU gap, no saturated sample, no extrapolation past `imu_gap_limit_s` (the kernel itself refuses
    a batch with a longer step between samples)."""
    if not t.size or filt.in_imu_gap or extra_s > filt.config.imu_gap_limit_s:
        return False
    return not (filt.stream.counts.saturated and saturated.any())


def _parameters(filt, defer: bool) -> np.ndarray:
    """The kernels' parameter vector (cached per filter: only two entries change over a run)."""
    cache = filt.__dict__.get("_kernel_parameters")
    if cache is None:  # all four at once, so that the cache never grows later in a run
        cache = filt._kernel_parameters = {}
        for manhattan in (False, True):
            for deferred in (False, True):
                p = parameter_vector(filt, deferred)
                p[K.P_MF_INIT] = float(manhattan)
                cache[manhattan, deferred] = p
    return cache[filt.manhattan_initialised, defer]


def parameter_vector(filt, defer: bool) -> np.ndarray:
    """The kernels' parameter vector (`K.P_SIZE`,) for filter `filt`, from its configuration; `defer`:
    an update due at the end of a batch waits for the frame."""
    cfg = filt.config
    p = np.empty(K.P_SIZE)
    p[K.P_Q_GYRO], p[K.P_Q_BIAS], p[K.P_Q_RATE] = filt.q_gyro, filt.q_bias, filt.q_rate
    p[K.P_TRAPEZOID] = float(filt.trapezoid)
    p[K.P_PERIOD] = cfg.accel_update_period_s
    p[K.P_DUE] = cfg.accel_update_period_s - PERIOD_TOLERANCE_S
    p[K.P_DEFER] = float(defer)
    p[K.P_LP_TAU] = cfg.accel_lowpass_tau_s
    p[K.P_INV_G], p[K.P_GRAVITY] = 1.0 / cfg.gravity_m_s2, cfg.gravity_m_s2
    p[K.P_ACC_NOISE] = cfg.accel_tilt_noise_rad_sqrt_s
    p[K.P_NORM_SCALE], p[K.P_INNOV_SCALE] = cfg.accel_norm_scale, cfg.accel_innovation_scale_rad
    p[K.P_FLAG_RATIO] = cfg.accel_downweight_flag_ratio
    p[K.P_REST_GYRO], p[K.P_REST_ACCEL] = cfg.rest_gyro_max_rad_s, cfg.rest_accel_max_m_s2
    p[K.P_REST_MIN_S], p[K.P_REST_STD] = cfg.rest_min_duration_s, cfg.rest_rate_std_rad_s
    p[K.P_MF_INIT] = float(filt.manhattan_initialised)
    walks = filt.manhattan_walks
    p[K.P_MF_YAW_RW] = cfg.manhattan_yaw_rw_rad_sqrt_s if walks else 0.0
    p[K.P_MF_TILT_RW] = cfg.manhattan_tilt_rw_rad_sqrt_s if walks else 0.0
    p[K.P_ORTHO_EVERY] = ORTHONORMALISE_EVERY
    p[K.P_RECORD] = float(cfg.record_imu_estimates)
    p[K.P_GAP_LIMIT] = cfg.imu_gap_limit_s
    return p


_COUNTERS = ((K.S_ACCEL_UPDATES, "accel_updates"), (K.S_ACCEL_SKIPPED, "accel_skipped"),
             (K.S_ACCEL_DOWNWEIGHTED, "accel_downweighted"), (K.S_REST_UPDATES, "rest_updates"),
             (K.S_NONFINITE, "nonfinite_updates"))


def _pack(filt):
    """The filter's state as the kernels' arguments: (s, R_wc, R_wm, b_c, P, last_gyro, acc_sum, lp,
    lp_J, rest_sums), fresh float64 arrays that the kernels update in place."""
    acc = filt.accel
    s = np.zeros(K.S_SIZE)
    s[K.S_T_STATE] = filt.t_state
    s[K.S_ACC_TIME], s[K.S_ACC_ELAPSED] = acc.time_s, acc.elapsed_s
    s[K.S_PRODUCTS] = filt.products_unnormalised
    s[K.S_LP_VALID] = float(acc.lp_c is not None)
    s[K.S_REST_N] = acc.rest_n
    s[K.S_REST_SINCE] = np.nan if acc.rest_since_s is None else acc.rest_since_s
    lp = np.array(acc.lp_c, float) if acc.lp_c is not None else np.zeros((2, 3))
    lp_J = np.array(acc.lp_J, float) if acc.lp_J is not None else np.zeros((2, 3, 3))
    return (s, np.array(filt.R_wc, float), np.array(filt.R_wm, float), np.array(filt.b_c, float),
            np.array(filt.P, float), np.array(filt.last_gyro_c, float), np.array(acc.sum_c, float),
            lp, lp_J, np.array(acc.rest_sums, float))


def _unpack(filt, state, downweighted: bool) -> None:
    """Write the kernels' results back into the filter (counters and flags included)."""
    s, R_wc, R_wm, b_c, P, last_gyro, acc_sum, lp, lp_J, rest_sums = state
    acc = filt.accel
    filt.R_wc, filt.R_wm, filt.b_c, filt.P = R_wc, R_wm, b_c, P
    filt.last_gyro_c, acc.sum_c, acc.rest_sums = last_gyro, acc_sum, rest_sums
    filt.t_state = float(s[K.S_T_STATE])
    acc.time_s, acc.elapsed_s = float(s[K.S_ACC_TIME]), float(s[K.S_ACC_ELAPSED])
    filt.products_unnormalised = int(s[K.S_PRODUCTS])
    acc.rest_n = int(s[K.S_REST_N])
    acc.rest_since_s = None if math.isnan(s[K.S_REST_SINCE]) else float(s[K.S_REST_SINCE])
    if s[K.S_LP_VALID] > 0:
        acc.lp_c, acc.lp_J = lp, lp_J
    for index, name in _COUNTERS:
        filt.counters[name] += int(s[index])
    if downweighted:
        filt.flags |= Status.ACCEL_DOWNWEIGHTED
    if s[K.S_NONFINITE] > 0:
        filt.flags |= Status.UPDATE_NONFINITE
    if s[K.S_ACCEL_DUE] > 0:
        acc.due = True


def integrate_compiled(filt, t, gyro_c, accel_c, extra_s: float, defer: bool) -> bool:
    """Integrate a batch (camera frame) with the kernel and write the state back into `filt`; False
    (nothing changed) when the batch holds an IMU gap, which the reference path then handles."""
    state = _pack(filt)
    record = filt.config.record_imu_estimates
    record_R = np.empty((t.size if record else 0, 3, 3))
    record_P = np.empty_like(record_R)
    bounds = chunk_bounds(t, filt.t_state, filt.accel.elapsed_s, filt.config.accel_update_period_s)
    done = KERNEL(*state, np.ascontiguousarray(t, float), np.ascontiguousarray(gyro_c, float),
                  np.ascontiguousarray(accel_c, float), bounds, float(extra_s), _parameters(filt, defer),
                  record_R, record_P)
    if done < 0:
        return False  # a step longer than the gap limit: nothing was changed
    if record:
        filt.record_t.append(np.array(t, float))
        filt.record_R.append(record_R)
        filt.record_P.append(record_P)
    filt.imu_t_s = float(t[-1])
    _unpack(filt, state, done > 0)
    return True


def integrate_segments_compiled(filt, t, gyro_c, accel_c, ends: np.ndarray):
    """An IMU-only stream (camera frame, clean: see `kernels.integrate_segments`) integrated with an
    estimate after each segment `ends` (M,) (exclusive sample ends); writes the state back into `filt`
    and returns `(R_wc (M, 3, 3), attitude cov (M, 3, 3), b_c (M, 3), flags (M,) Status bits)`, or
    None (nothing changed) when the stream holds an IMU gap. `filt.flags` is left to the caller: the
    per-estimate flags already say what happened."""
    state = _pack(filt)
    m = ends.shape[0]
    record = filt.config.record_imu_estimates
    record_R = np.empty((t.size if record else 0, 3, 3))
    record_P = np.empty_like(record_R)
    out_R, out_cov, out_b, out_flags = np.empty((m, 3, 3)), np.empty((m, 3, 3)), np.empty((m, 3)), np.empty(m, np.int64)
    done = K.SEGMENTS(*state, np.ascontiguousarray(t, float), np.ascontiguousarray(gyro_c, float),
                      np.ascontiguousarray(accel_c, float), ends, _parameters(filt, False), record_R, record_P,
                      out_R, out_cov, out_b, out_flags)
    if done < 0:
        return None
    if record:
        filt.record_t.append(np.array(t, float))
        filt.record_R.append(record_R)
        filt.record_P.append(record_P)
    filt.imu_t_s = float(t[-1])
    _unpack(filt, state, False)
    flags = np.where(out_flags & 1, int(Status.ACCEL_DOWNWEIGHTED), 0) | np.where(
        out_flags & 2, int(Status.UPDATE_NONFINITE), 0)
    return out_R, out_cov, out_b, flags


def accel_update_compiled(filt) -> None:
    """The accelerometer (and at-rest) update of the period just completed, compiled: as
    `Mekf.accel_update`."""
    state = _pack(filt)
    s, R_wc, R_wm, b_c, P, _, acc_sum, lp, lp_J, rest_sums = state
    downweighted = K.ACCEL_UPDATE(s, R_wc, R_wm, b_c, P, acc_sum, lp, lp_J, rest_sums, _parameters(filt, False))
    _unpack(filt, state, downweighted)
