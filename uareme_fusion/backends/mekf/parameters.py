"""The kernels' parameters: one record of named float64 fields, built once per filter from its
`MekfConfig` (`kernel_parameters`), read by name in the kernels (`p.q_gyro`).

numba reads the record from a one-element structured array (`params[0]` in a driver); as plain Python
the drivers get the same array as a `np.recarray`, whose element reads fields by attribute too.
Only two fields change over a run (`manhattan_initialised`, `defer`): a filter keeps the four
variants (`KernelParameters.get`).
"""

from __future__ import annotations

import numpy as np

from .accel import PERIOD_TOLERANCE_S
from .state import ORTHONORMALISE_EVERY

FIELDS = (
    "q_gyro",  # white gyro noise, (rad/s)^2/Hz
    "q_bias",  # gyro bias random walk, (rad/s^2)^2/Hz
    "q_rate",  # rate-proportional gyro error, 1/s (`gyro_rate_noise_sqrt_s` squared)
    "trapezoid",  # 1: instantaneous gyro readings (trapezoid), 0: interval means
    "period_s",  # accelerometer update period
    "due_s",  # the period less its rounding tolerance
    "defer",  # 1: an update due at the end of a batch waits for the frame
    "lowpass_tau_s",  # accelerometer low-pass time constant (0: off)
    "gravity_m_s2",
    "accel_tilt_noise",  # rad*sqrt(s)
    "accel_norm_scale",
    "accel_innovation_scale_rad",
    "accel_downweight_flag_ratio",
    "rest_gyro_max_rad_s",  # 0: no rest detection
    "rest_accel_max_m_s2",
    "rest_min_duration_s",
    "rest_rate_std_rad_s",
    "manhattan_initialised",  # 1 once the Manhattan frame is known
    "manhattan_yaw_rw",  # rad/sqrt(s), 0 unless the Manhattan frame walks
    "manhattan_tilt_rw",  # rad/sqrt(s)
    "orthonormalise_every",  # products between re-orthonormalisations
    "record",  # 1: record R_wc and the attitude covariance after each IMU sample
    "gap_limit_s",  # a longer step between IMU samples is a gap
    "unknown_rate_std_rad_s",  # rate std over gaps and saturated samples
    "visual_gate_chi2",
    "visual_huber_k",
    "vertical_std_rad",
    "vertical_max_rad",
    "visual_correlation_s",
    "bias_visual_correlation_s",
    "visual_trust_frames",
    "visual_trust_min_share",
    "uses_imu",  # 1: gyro-driven (relabel nearest the prediction, trust, vertical, accelerometer rows)
    "estimates_rate",  # 1: visual only, the rate is part of the state
)
DTYPE = np.dtype([(name, np.float64) for name in FIELDS])


def kernel_parameters(filt, defer: bool, manhattan_initialised: bool) -> np.ndarray:
    """The parameter record (1,) `DTYPE` of filter `filt` (a `Mekf`) from its configuration."""
    cfg = filt.config
    walks = filt.manhattan_walks
    values = dict(
        q_gyro=filt.q_gyro, q_bias=filt.q_bias, q_rate=filt.q_rate, trapezoid=float(filt.trapezoid),
        period_s=cfg.accel_update_period_s, due_s=cfg.accel_update_period_s - PERIOD_TOLERANCE_S, defer=float(defer),
        lowpass_tau_s=cfg.accel_lowpass_tau_s, gravity_m_s2=cfg.gravity_m_s2,
        accel_tilt_noise=cfg.accel_tilt_noise_rad_sqrt_s, accel_norm_scale=cfg.accel_norm_scale,
        accel_innovation_scale_rad=cfg.accel_innovation_scale_rad,
        accel_downweight_flag_ratio=cfg.accel_downweight_flag_ratio, rest_gyro_max_rad_s=cfg.rest_gyro_max_rad_s,
        rest_accel_max_m_s2=cfg.rest_accel_max_m_s2, rest_min_duration_s=cfg.rest_min_duration_s,
        rest_rate_std_rad_s=cfg.rest_rate_std_rad_s, manhattan_initialised=float(manhattan_initialised),
        manhattan_yaw_rw=cfg.manhattan_yaw_rw_rad_per_sqrt_s if walks else 0.0,
        manhattan_tilt_rw=cfg.manhattan_tilt_rw_rad_per_sqrt_s if walks else 0.0,
        orthonormalise_every=ORTHONORMALISE_EVERY, record=float(cfg.record_imu_estimates),
        gap_limit_s=cfg.imu_gap_limit_s, unknown_rate_std_rad_s=cfg.unknown_rate_std_rad_s,
        visual_gate_chi2=cfg.visual_gate_chi2, visual_huber_k=cfg.visual_huber_k,
        vertical_std_rad=cfg.manhattan_vertical_std_rad, vertical_max_rad=cfg.manhattan_vertical_max_rad,
        visual_correlation_s=cfg.visual_error_correlation_s,
        bias_visual_correlation_s=cfg.gyro_bias_visual_correlation_s, visual_trust_frames=cfg.visual_trust_frames,
        visual_trust_min_share=cfg.visual_trust_min_share, uses_imu=float(filt.motion.uses_imu),
        estimates_rate=float(filt.motion.estimates_rate))
    record = np.zeros(1, DTYPE)
    for name in FIELDS:
        record[name] = values[name]
    return record


class KernelParameters:
    """A filter's four parameter records (Manhattan frame known or not, update deferred or not),
    built at once when its motion is set, so that none is built later in a run."""

    def __init__(self, filt):
        self.records = {(known, defer): kernel_parameters(filt, defer, known)
                        for known in (False, True) for defer in (False, True)}
        self.python = False

    def get(self, manhattan_initialised: bool, defer: bool) -> np.ndarray:
        return self.records[manhattan_initialised, defer]

    def as_python(self) -> None:
        """The records as `np.recarray`s, whose elements read fields by attribute (plain-Python kernels)."""
        self.records = {key: record.view(np.recarray) for key, record in self.records.items()}
        self.python = True
