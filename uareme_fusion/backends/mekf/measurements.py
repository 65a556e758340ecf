"""Measurement models of `Mekf`, one contract for all: plain-array functions that the kernels
(`kernels.py`) compile and plain Python calls alike, each returning a `Measurement`.

A model compares a measurement with its prediction from the nominal state and returns
`Measurement(ok, residual, covariance, jacobian)`: whether it applies here, the residual (3,) between
the measurement and the prediction (its evaluation), the residual's covariance R (3, 3) (the
measurement noise) and its Jacobian H (3, 12) with `residual(x) - residual(x (+) dx) = H dx` to first
order for the error state `dx` (right perturbations, `state.py`); tests/backends/test_mekf_models.py
checks each H against finite differences.
- visual: the solver's `R_cm` measures `R_wc^T R_wm` (residual `Log(R_cm_pred^T R_cm)`;
  `kernel_visual.visual_model`);
- vertical: "the Manhattan z axis is world up" (`e_z - R_wm^T up`);
- gravity: the accelerometer direction measures up in the camera frame (`z - R_wc^T up`);
- zero rate: at rest the mean gyro reading measures the bias (`g_mean - b_c`).
"""

from __future__ import annotations

import collections
import math

import numpy as np

from .state import MF

Measurement = collections.namedtuple("Measurement", ("ok", "residual", "covariance", "jacobian"))
"""What every model returns: `ok` (bool: the model applies), `residual` (3,), `covariance` (3, 3) and
`jacobian` (3, 12) (module docstring); zeros when not `ok`. numba compiles it as a named tuple.
The models here call no other compiled function (the kernels rebind only their own modules' names):
the visual model, which draws on the 3x3 helpers, is `kernel_visual.visual_model`."""


def correlated_noise_scale(dt_s: float, correlation_s: float) -> float:
    """Factor on the covariance of a measurement whose errors persist for `correlation_s` s, taken
    `dt_s` s after the previous one: `max(1, correlation_s / dt_s)`, so that the updates within one
    correlation time carry the information of one independent measurement (1 when either is 0)."""
    if correlation_s <= 0 or not dt_s > 0:
        return 1.0
    return max(1.0, correlation_s / dt_s)


def vertical_model(R_wm, std_rad, max_rad):
    """Pseudo-measurement "the Manhattan z axis is (nearly) world up" (docs/design.md "Conventions"),
    std `std_rad` (covariance `std_rad^2 I`); not `ok` when m's z is farther than `max_rad` from up."""
    h = R_wm[2].copy()  # R_wm^T @ (0, 0, 1)
    if math.acos(min(1.0, max(-1.0, h[2]))) > max_rad:
        return Measurement(False, np.zeros(3), np.zeros((3, 3)), np.zeros((3, 12)))
    H = np.zeros((3, 12))
    # d/d(dtheta_m) of Exp(-dtheta_m) h at 0: skew(h)
    H[0, 7], H[0, 8], H[1, 8] = -h[2], h[1], -h[0]
    H[1, 6], H[2, 6], H[2, 7] = h[2], -h[1], h[0]
    r = -h
    r[2] += 1.0  # e_z - h
    return Measurement(True, r, std_rad**2 * np.eye(3), H)


def vertical_distance2(R_wm: np.ndarray, P_m: np.ndarray, std_rad: float, max_rad: float) -> float | None:
    """Squared Mahalanobis distance of "the Manhattan z axis is world up" (`vertical_model`) for a
    Manhattan frame `R_wm` whose error (right perturbation) has covariance `P_m` (3, 3, rad^2); None
    when that pseudo-measurement does not apply (m's z farther than `max_rad` from up). A frame
    that fails it contradicts gravity: the vertical pseudo-measurement would tilt the camera."""
    ok, r, R, H = vertical_model(R_wm, std_rad, max_rad)
    if not ok:
        return None
    H_m = H[:, MF]
    return float(r @ np.linalg.solve(H_m @ P_m @ H_m.T + R, r))


def gravity_model(accel_c, T_s, R_wc, lp_J1, use_lp_J, gravity_m_s2, noise_rad_sqrt_s, norm_scale,
                  innovation_scale_rad, flag_ratio):
    """Accelerometer direction as a tilt measurement: `accel_c` (3,) m/s^2 the mean (or low-passed)
    specific force over `T_s` s in the camera frame measures up, `R_wc^T up`. Its variance
    `noise_rad_sqrt_s^2 / T_s` grows by `1 + (dev / norm_scale)^2` (dev: relative deviation of |acc|
    from `gravity_m_s2`) and `1 + (angle / innovation_scale_rad)^2` (angle between measured and
    predicted up); the covariance is that variance times I. With `use_lp_J` the low-passed direction
    also measures the gyro-bias error through `lp_J1` (3, 3), its sensitivity to the bias. Not `ok`
    near free fall (no direction). Returns `(Measurement, downweighted)`, `downweighted` when the std
    exceeds `flag_ratio` times the nominal one."""
    norm = math.sqrt(accel_c[0] ** 2 + accel_c[1] ** 2 + accel_c[2] ** 2)
    if not (T_s > 0 and norm > 0.1 * gravity_m_s2):
        return Measurement(False, np.zeros(3), np.zeros((3, 3)), np.zeros((3, 12))), False
    H = np.zeros((3, 12))
    # |mean specific force| against gravity: the mean is taken in a common (rotating) camera frame,
    # so it is the inertial-frame average and translational accelerations cancel in it.
    norm_dev = abs(norm * (1.0 / gravity_m_s2) - 1.0)
    z = accel_c / norm
    h = R_wc[2].copy()  # R_wc^T @ (0, 0, 1)
    angle = math.acos(min(1.0, max(-1.0, z[0] * h[0] + z[1] * h[1] + z[2] * h[2])))
    var0 = noise_rad_sqrt_s**2 / T_s
    var = var0 * (1.0 + (norm_dev / norm_scale) ** 2) * (1.0 + (angle / innovation_scale_rad) ** 2)
    downweighted = var > (flag_ratio * math.sqrt(var0)) ** 2
    # d/d(dtheta) of Exp(-dtheta) h at 0: skew(h)
    H[0, 1], H[0, 2], H[1, 2] = -h[2], h[1], -h[0]
    H[1, 0], H[2, 0], H[2, 1] = h[2], -h[1], h[0]
    if use_lp_J:  # z = normalise(lp - J db)
        H[:, 3:6] = -(np.eye(3) - np.outer(z, z)) @ lp_J1 / norm
    return Measurement(True, z - h, var * np.eye(3), H), downweighted


def zero_rate_model(rest_sums, rest_n, T_s, b_c, q_gyro, rest_gyro_max_rad_s, rest_accel_max_m_s2,
                    rest_rate_std_rad_s):
    """At rest the period's mean gyro reading measures the bias `b_c` (3,) rad/s (camera frame).
    `rest_sums` (8,): sums over the period's `rest_n` samples of gyro (rad/s), |gyro|^2, accel (m/s^2)
    and |accel|^2. At rest when the mean gyro and the rms deviations of gyro and accel from their
    means are below the limits. The variance is the gyro white noise `q_gyro` ((rad/s)^2/Hz) of a
    `T_s`-second mean plus `rest_rate_std_rad_s^2` (covariance: that times I). Not `ok` unless at rest."""
    g_mean, a_mean = rest_sums[0:3] / rest_n, rest_sums[4:7] / rest_n
    g2 = g_mean[0] ** 2 + g_mean[1] ** 2 + g_mean[2] ** 2
    g_dev2 = max(rest_sums[3] / rest_n - g2, 0.0)
    a_dev2 = max(rest_sums[7] / rest_n - (a_mean[0] ** 2 + a_mean[1] ** 2 + a_mean[2] ** 2), 0.0)
    limit2 = rest_gyro_max_rad_s**2
    if g2 >= limit2 or g_dev2 >= limit2 or a_dev2 >= rest_accel_max_m_s2**2:
        return Measurement(False, np.zeros(3), np.zeros((3, 3)), np.zeros((3, 12)))
    H = np.zeros((3, 12))
    for i in range(3):
        H[i, 3 + i] = 1.0
    return Measurement(True, g_mean - b_c, (q_gyro / T_s + rest_rate_std_rad_s**2) * np.eye(3), H)
