"""Process models of `Mekf`: pure functions on arrays, and the two motion strategies.

- Gyro model (visual + IMU, IMU only): `R_wc <- R_wc C_N` with `C_N` the product of `Exp(rate_k dt_k)`
  over a chunk of gyro samples; per sample `dtheta_{k+1} = M_k^T dtheta_k - dt_k db`, composed:
  `dtheta_N = C_N^T dtheta_0 - A_bias db` with `A_bias = C_N^T sum_k dt_k C_k`.
- Constant-rate model (visual only): `R_wc <- R_wc Exp(omega_c dt)`, `omega_c` a random walk.

The motion strategy is chosen once, when the filter's mode is known (`MekfMode`); an `auto` filter
resolves its mode once (see `filter.Mekf`), never switching back.
"""

from __future__ import annotations

import numpy as np

from uareme_fusion.rotations import WORLD_UP, exp_so3, log_so3
from uareme_fusion.backends.mekf.state import BG, I3, N_STATE, RATE, TH


def _block_pattern(*blocks: tuple[slice, slice]) -> np.ndarray:
    """(12, 12) zeros with I3 in the given blocks: process-noise terms are scalars times these."""
    E = np.zeros((N_STATE, N_STATE))
    for rows, cols in blocks:
        E[rows, cols] = I3
    E.setflags(write=False)
    return E


_E_TH_CROSS_BG = np.stack(
    [_block_pattern((TH, TH)), _block_pattern((TH, BG), (BG, TH)), _block_pattern((BG, BG))]
).reshape(3, -1)
"""Attitude, attitude-bias and bias process-noise patterns, flattened: `Q = (c @ this).reshape(12, 12)`."""


def prefix_products(M: np.ndarray) -> np.ndarray:
    """C_k = M_0 @ M_1 @ ... @ M_k for a stack (N, 3, 3), by a log-depth (Hillis-Steele) scan."""
    C = M.copy()
    shift = 1
    while shift < C.shape[0]:
        C[shift:] = C[:-shift] @ C[shift:]
        shift *= 2
    return C


def gyro_rates(gyro_c: np.ndarray, b_c: np.ndarray, trapezoid: bool) -> np.ndarray:
    """(N, 3) bias-corrected rates (rad/s, camera frame) over the N steps between N + 1 gyro
    readings `gyro_c` (N + 1, 3): the mean of each step's two readings (`trapezoid`, readings are
    instantaneous) or the reading at its end (readings are interval means)."""
    if trapezoid:
        rate_c = gyro_c[1:] + gyro_c[:-1]
        rate_c *= 0.5
        rate_c -= b_c
        return rate_c
    return gyro_c[1:] - b_c


def gyro_chunk(rate_c: np.ndarray, dt_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation increments of a chunk: rates (N, 3) rad/s held over steps `dt_s` (N,) s. Returns
    `(C (N, 3, 3), A_bias (3, 3))`: cumulative rotations `C_k = Exp(rate_0 dt_0) ... Exp(rate_k dt_k)`
    (`R_wc <- R_wc C[-1]`) and the bias block of the transition, `dtheta_N = C_N^T dtheta_0 - A_bias db`."""
    C = prefix_products(exp_so3(rate_c * dt_s[:, None]))
    A_bias = C[-1].T @ (dt_s @ C.reshape(-1, 9)).reshape(3, 3)
    return C, A_bias


def gyro_transition(C_N: np.ndarray, A_bias: np.ndarray, F: np.ndarray | None = None) -> np.ndarray:
    """(12, 12) error transition of a gyro chunk (`gyro_chunk`'s results); written into `F` when
    given (only its attitude rows change between chunks)."""
    F = np.eye(N_STATE) if F is None else F
    F[TH, TH] = C_N.T
    F[TH, BG] = -A_bias
    return F


def gyro_process_noise(T_s: float, q_gyro: float, q_bias: float, unknown_var_rad2: float = 0.0,
                       rate_var_rad2: float = 0.0) -> np.ndarray:
    """(12, 12) process noise of a gyro chunk of `T_s` seconds: white gyro noise `q_gyro`
    ((rad/s)^2/Hz, isotropic, so its rotated sum is `q_gyro T I`), bias random walk `q_bias`
    ((rad/s^2)^2/Hz) to second order, plus on each attitude axis the variance of unknown rates over
    gaps and that of the rate-proportional gyro error (rad^2)."""
    c = np.array([q_gyro * T_s + q_bias * T_s**3 / 3.0 + unknown_var_rad2 + rate_var_rad2, -q_bias * T_s**2 / 2.0,
                  q_bias * T_s])
    return (c @ _E_TH_CROSS_BG).reshape(N_STATE, N_STATE)


def manhattan_walk_noise(R_wm: np.ndarray, dt_s: float, yaw_rw_rad_per_sqrt_s: float,
                         tilt_rw_rad_per_sqrt_s: float) -> np.ndarray:
    """(3, 3) process noise of the Manhattan frame's right perturbation over `dt_s`: a random walk of
    its yaw about world up and of its tilt (densities in rad/sqrt(s))."""
    u = R_wm.T @ WORLD_UP
    uu = np.outer(u, u)
    return dt_s * (yaw_rw_rad_per_sqrt_s**2 * uu + tilt_rw_rad_per_sqrt_s**2 * (I3 - uu))


def constant_rate_model(omega_c: np.ndarray, dt_s: float, q_rate: float):
    """Constant-rate step over `dt_s` s with rate `omega_c` (3,) rad/s (camera frame) and rate random
    walk `q_rate` ((rad/s^2)^2/Hz): `(M (3, 3), F (12, 12), Q (12, 12))`, `R_wc <- R_wc M`."""
    M = exp_so3(omega_c * dt_s)
    F = np.eye(N_STATE)
    F[TH, TH] = M.T
    F[TH, RATE] = dt_s * I3
    Q = np.zeros((N_STATE, N_STATE))
    Q[TH, TH] = q_rate * dt_s**3 / 3.0 * I3
    Q[TH, RATE] = Q[RATE, TH] = q_rate * dt_s**2 / 2.0 * I3
    Q[RATE, RATE] = q_rate * dt_s * I3
    return M, F, Q



def image_rotation_model(R_cp: np.ndarray, var_rad2: float, dt_s: float, q_rate: float, P: np.ndarray):
    """The prediction by the image rotation `R_cp` (3, 3) of variance `var_rad2` (rad^2 per axis) over
    `dt_s` s (`kernel_image_rotation.py`): `(omega_c (3,), P (12, 12))`, with `F[TH, TH] = R_cp`,
    `Q[TH, TH] = var I`, and the rate measured afresh: `Log(R_cp^T) / dt`, variance
    `var / dt^2 + q_rate dt / 3`, cross-covariance with the attitude `var / dt`, none with the rest."""
    F = np.eye(N_STATE)
    F[TH, TH] = R_cp
    P = F @ P @ F.T
    P[TH, TH] += var_rad2 * I3
    P[RATE, :] = 0.0
    P[:, RATE] = 0.0
    P[RATE, RATE] = (var_rad2 / dt_s**2 + q_rate * dt_s / 3.0) * I3
    P[TH, RATE] = P[RATE, TH] = var_rad2 / dt_s * I3
    return log_so3(R_cp.T) / dt_s, P
