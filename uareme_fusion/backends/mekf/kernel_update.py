"""The EKF's updates on the state buffer: the Joseph-form Kalman update with injection and reset, and
the accelerometer period's zero-rate and gravity updates (numba-compiled by `kernels`, plain Python
without numba). Measurement models are those of `measurements`; the reset that of `state`.

Conventions as in `mekf`: right perturbations, error state `[dtheta_c, db_c, dtheta_m, domega_c]`,
`R_wc` camera to world (z up), rates in rad/s in the camera frame, times in s. `p` is the filter's
parameter record (`parameters.py`), `x` its state buffer (`state_buffer.py`).
"""

from __future__ import annotations

import math

import numpy as np

from . import status_bits
from .matrix3 import exp3_into, matmul3_into
from .measurements import gravity_model, zero_rate_model
from .source_trust import note_accel_information
from .state import ROTATION_BLOCKS, orthonormal, reset_jacobian

DOWNWEIGHTED, NONFINITE = status_bits.ACCEL_DOWNWEIGHTED, status_bits.UPDATE_NONFINITE
"""An accelerometer update was down-weighted; an update's result was not finite (and dropped): the
bits of the `Status` flags that say so, so that a result is or-ed into the filter's flags as it is."""


def state_views(x):
    """The array fields of the state record `x[0]` (`state_buffer.py`) as views: (R_wc, R_wm, b_c, P,
    last_gyro, accel_sum, lp, lp_J, rest_sums, omega_c). The record itself is not returned (numba
    cannot return a record by value): a kernel reads the scalar fields from `s = x[0]`."""
    s = x[0]
    return s.R_wc, s.R_wm, s.b_c, s.P, s.last_gyro, s.accel_sum, s.lp, s.lp_J, s.rest_sums, s.omega_c


def matmul_into(A, B, out):
    """`out = A @ B` by scalar loops (small matrices: no BLAS call), summed in index order."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            acc = 0.0
            for k in range(A.shape[1]):
                acc += A[i, k] * B[k, j]
            out[i, j] = acc
    return out


def solve_into(A, B, X):
    """`X = A^-1 B` for `A` (m, m) and `B` (m, n), by Gauss-Jordan elimination with partial pivoting on
    copies (m is at most 9 here: no LAPACK call); a singular or non-finite `A` gives non-finite `X`
    instead of an exception, as the filter checks its results for that."""
    m, n = A.shape[0], B.shape[1]
    M = A.copy()
    X[:, :] = B
    for col in range(m):
        pivot = col
        for row in range(col + 1, m):
            if abs(M[row, col]) > abs(M[pivot, col]):
                pivot = row
        if pivot != col:
            for j in range(m):
                M[col, j], M[pivot, j] = M[pivot, j], M[col, j]
            for j in range(n):
                X[col, j], X[pivot, j] = X[pivot, j], X[col, j]
        inv = 1.0 / M[col, col]
        for j in range(m):
            M[col, j] *= inv
        for j in range(n):
            X[col, j] *= inv
        for row in range(m):
            f = M[row, col]
            if row != col and f != 0.0:
                for j in range(m):
                    M[row, j] -= f * M[col, j]
                for j in range(n):
                    X[row, j] -= f * X[col, j]
    return X


def kalman_update(x, residual, R, H, p, bias_gain):
    """Joseph-form update with the measurement `residual` (m,), noise `R` (its leading (m, m) block: a
    stacked update passes its whole work array, so that every caller passes a C-contiguous `R` and
    numba compiles this function once) and `H` (m, 12), the gyro bias's gain on the first three rows (a
    frame's rotation, stacked first) scaled by `bias_gain` (1: the Kalman gain; below, a partial update of
    the bias from those rows, which the Joseph form allows; the rows stacked after keep theirs), then
    injection into the nominal state and the reset of the error , all in
    place; nothing changes but `s.nonfinite_updates` when the result is not finite.
    Scalar loops that use the structure (a BLAS call per small product costs more than the product,
    and more still out of the caches, after a solver call): the Joseph form expanded,
    `(I - K H) P (I - K H)^T + K R K^T = P - K (P H^T)^T - (P H^T) K^T + K S K^T` (any gain K) with `S` the
    innovation covariance, and the reset `G P G^T` on the rotation blocks only."""
    s = x[0]
    P = s.P
    m = residual.shape[0]
    PHt = matmul_into(P, H.T, np.empty((12, m)))
    S = matmul_into(H, PHt, np.empty((m, m)))
    for i in range(m):
        for j in range(m):
            S[i, j] += R[i, j]
    K = solve_into(S, PHt.T, np.empty((m, 12))).T  # S symmetric: K^T = S^-1 (P H^T)^T
    if bias_gain != 1.0:
        for i in range(3, 6):  # BG
            for k in range(3):
                K[i, k] *= bias_gain
    KS = matmul_into(K, S, np.empty((12, m)))
    dx = np.zeros(12)
    for i in range(12):
        for k in range(m):
            dx[i] += K[i, k] * residual[k]
    P_new = np.empty((12, 12))
    finite = True
    for i in range(12):
        finite &= abs(dx[i]) < np.inf
        for j in range(12):
            v = P[i, j]
            for k in range(m):
                v += -K[i, k] * PHt[j, k] - PHt[i, k] * K[j, k] + KS[i, k] * K[j, k]
            P_new[i, j] = v
            finite &= abs(v) < np.inf
    if not finite:
        s.nonfinite_updates += 1
        return
    inject_and_reset(x, dx, P_new, p)


def inject_and_reset(x, dx, P_new, p):
    """After an update with error estimate `dx` (12,) and covariance `P_new` (12, 12): `dx` injected
    into the nominal state (the rate only with `p.estimates_rate`, the Manhattan frame once known) and
    the low-pass stages, and `P` set to the reset `G P_new G^T`, symmetrised, all in place."""
    s = x[0]
    R_wc, R_wm, b_c, P, _, _, lp, lp_J, _, omega_c = state_views(x)
    with_manhattan = p.manhattan_initialised > 0
    G = reset_jacobian(dx, with_manhattan)
    if with_manhattan:
        R_wm[:, :] = matmul3_into(R_wm, exp3_into(dx[6], dx[7], dx[8], np.empty((3, 3))), np.empty((3, 3)))
    R_wc[:, :] = matmul3_into(R_wc, exp3_into(dx[0], dx[1], dx[2], np.empty((3, 3))), np.empty((3, 3)))
    s.products += 1
    if s.products >= p.orthonormalise_every:
        R_wc[:, :] = orthonormal(R_wc)
        R_wm[:, :] = orthonormal(R_wm)
        s.products = 0
    for i in range(3):
        b_c[i] += dx[3 + i]
    if p.estimates_rate > 0:
        for i in range(3):
            omega_c[i] += dx[9 + i]
    if s.lp_valid > 0:
        for st in range(2):
            for i in range(3):
                lp[st, i] += lp_J[st, i, 0] * dx[3] + lp_J[st, i, 1] * dx[4] + lp_J[st, i, 2] * dx[5]
    # G is the identity but on the rotation blocks (`state.reset_jacobian`), the Manhattan one only
    # `with_manhattan`.
    GP = P_new.copy()  # G P_new: only the rotation blocks' rows change
    n_blocks = 2 if with_manhattan else 1
    for block in range(n_blocks):
        o = ROTATION_BLOCKS[block]
        for a in range(3):
            for j in range(12):
                GP[o + a, j] = (G[o + a, o] * P_new[o, j] + G[o + a, o + 1] * P_new[o + 1, j]
                                + G[o + a, o + 2] * P_new[o + 2, j])
    GPG = GP.copy()  # (G P_new) G^T: only their columns change
    for block in range(n_blocks):
        o = ROTATION_BLOCKS[block]
        for i in range(12):
            for b in range(3):
                GPG[i, o + b] = GP[i, o] * G[o + b, o] + GP[i, o + 1] * G[o + b, o + 1] + GP[i, o + 2] * G[o + b, o + 2]
    for i in range(12):
        for j in range(12):
            P[i, j] = 0.5 * (GPG[i, j] + GPG[j, i])


def accel_rows(x, p, update):
    """The end of an accelerometer period: the zero-rate update when at rest, applied in place, then
    the (low-passed) accelerometer direction's measurement, with `update` > 0 its update too (else
    the caller stacks it into its own; a float, as numba compiles one specialisation per literal
    bool). Consumes the period. Returns `(Measurement, downweighted)`, the
    measurement not `ok` near free fall.
    The compile time of the kernels grows with each function that calls into the Kalman update (each
    is optimised with all it calls): this one updates itself rather than through a wrapper."""
    s = x[0]
    R_wc, _, b_c, _, _, accel_sum, lp, lp_J, rest_sums, _ = state_views(x)
    T = s.accel_time_s
    accel_c = accel_sum / T if T > 0 else accel_sum.copy()
    accel_sum[:] = 0.0
    s.accel_time_s = 0.0
    s.accel_elapsed_s = 0.0
    if p.rest_gyro_max_rad_s > 0:
        n = s.rest_n
        if n >= 2 and T > 0:
            rest = zero_rate_model(rest_sums, n, T, b_c, p.q_gyro, p.rest_gyro_max_rad_s, p.rest_accel_max_m_s2,
                                   p.rest_rate_std_rad_s)
            if not rest.ok:
                s.rest_since_s = np.nan
            else:
                if math.isnan(s.rest_since_s):
                    s.rest_since_s = s.t_state_s - T
                if s.t_state_s - s.rest_since_s >= p.rest_min_duration_s:
                    kalman_update(x, rest.residual, rest.covariance, rest.jacobian, p, 1.0)
                    s.rest_updates += 1
        rest_sums[:] = 0.0
        s.rest_n = 0
    tau = p.lowpass_tau_s
    if tau > 0 and T > 0:
        if s.lp_valid == 0:
            lp[0], lp[1] = accel_c, accel_c
            lp_J[:] = 0.0
            s.lp_valid = 1
        else:
            alpha = 1.0 - math.exp(-T / tau)
            lp[0] += alpha * (accel_c - lp[0])
            lp[1] += alpha * (lp[0] - lp[1])
            lp_J[0] *= 1.0 - alpha
            lp_J[1] += alpha * (lp_J[0] - lp_J[1])
        accel_c = lp[1].copy()
    gravity, downweighted = gravity_model(accel_c, T, R_wc, lp_J[1], tau > 0, p.gravity_m_s2, p.accel_tilt_noise,
                                          p.accel_norm_scale, p.accel_innovation_scale_rad,
                                          p.accel_downweight_flag_ratio)
    if not gravity.ok:
        s.accel_skipped += 1
        return gravity, False
    note_accel_information(s, gravity.covariance[0, 0], T)
    if downweighted:
        s.accel_downweighted += 1
    s.accel_updates += 1
    if update > 0:
        kalman_update(x, gravity.residual, gravity.covariance, gravity.jacobian, p, 1.0)
    return gravity, downweighted


def accel_update_in_place(x, params):
    """The update at the end of an accelerometer period (`accel_rows`) on the state buffer `x`, in
    place: the `DOWNWEIGHTED` | `NONFINITE` bits of what happened."""
    p = params[0]
    nonfinite_before = x[0].nonfinite_updates
    downweighted = accel_rows(x, p, 1.0)[1]
    return (DOWNWEIGHTED if downweighted else 0) + (NONFINITE if x[0].nonfinite_updates > nonfinite_before else 0)


def update_in_place(x, residual, R, H, params):
    """`kalman_update` of one measurement (`residual` (m,), `R` (m, m), `H` (m, 12)) on the state
    buffer `x`, for the rows the filter builds in Python (the gravity of an accelerometer without
    gyro): the `NONFINITE` bit when its result was dropped."""
    nonfinite_before = x[0].nonfinite_updates
    kalman_update(x, residual, R, H, params[0], 1.0)
    return NONFINITE if x[0].nonfinite_updates > nonfinite_before else 0
