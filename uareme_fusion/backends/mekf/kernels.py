"""Compiled IMU propagation, accelerometer/zero-rate updates and visual update of `Mekf` (issue 17).

The maths are those of the reference path (`filter.Mekf`, `imu_path`, in numpy/filterpy), written as
small pure functions on plain arrays so that numba compiles them; the measurement models and the
error reset are the very functions of `measurements` and `state`:
- `propagate_chunk`: gyro integration over a chunk of samples and the error-state covariance
  prediction (closed-form transition and process noise, as in the reference);
- `accel_measurement` / `zero_rate_measurement`: residual, variance (isotropic) and H of the
  accelerometer-direction and at-rest bias measurements;
- `visual_measurement`: `measurements.visual_model` (its symmetry, residual and noise);
- `kalman_update`: Joseph-form update of the zero-mean error state (m stacked rows), injection and reset.
`integrate_batch` runs them over a released batch, chunk by chunk, with the updates falling due.
It covers batches without gaps or saturated samples; `Mekf` keeps those on the reference path.
`visual_update` fuses a frame's rotation as `Mekf._visual_update` does with an IMU.
The drivers (`integrate_batch`, `integrate_staged`, `integrate_segments`, `accel_update_in_place`,
`visual_update`) take the filter's state buffer `x` (`state_buffer.py`) and update it in place: one
array crosses each call.

Conventions as in `mekf`: right perturbations, error state `[dtheta_c, db_c, dtheta_m, domega_c]`,
`R_wc` camera to world (z up), rates in rad/s in the camera frame, times in s.
Every function here also runs as plain Python (slowly); `KERNEL` is the compiled driver or None.
Compiling them takes about 20 s on a small machine, so their machine code is cached on disk
(numba `cache=True`): only the first process after an install or an edit pays it.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from ... import jit, rotations
from . import state_buffer, status_bits
from .accel import chunk_bounds
from .matrix3 import exp3_into, inv3, log3_into, matmul3_into
from .measurements import correlated_noise_scale, gravity_model, vertical_measurement, zero_rate_model
from .source_trust import (note_accel_information, note_visual_information, squared_rate, update_visual_trust,
                           vertical_variance, visual_vertical_innovation)
from ..imu_stream import rows_if_clean
from .state import ROTATION_BLOCKS, orthonormal, reset_jacobian
from .state_buffer import (S_ACCEL_DOWNWEIGHTED, S_ACCEL_DUE, S_ACCEL_SKIPPED, S_ACCEL_UPDATES, S_ACCEL_VAR_RATE,
                           S_ACCEL_ELAPSED, S_ACCEL_TIME, S_IMU_T, S_LP_VALID, S_NONFINITE, S_PRODUCTS, S_REJECTIONS,
                           S_REST_N, S_REST_SINCE, S_REST_UPDATES, S_T_STATE, S_T_VISUAL, S_VISUAL_INFO_RATE,
                           S_VISUAL_REJECTED, S_VISUAL_UPDATES, X_ACCEL_SUM, X_B_C, X_LAST_GYRO, X_LP, X_LP_J, X_P,
                           X_REST_SUMS, X_R_WC, X_R_WM, X_S, X_SIZE)

# The kernels' results: bits of the code `integrate_batch`, `accel_update_in_place`, `visual_update` return.
DOWNWEIGHTED, NONFINITE = status_bits.ACCEL_DOWNWEIGHTED, status_bits.UPDATE_NONFINITE
"""An accelerometer update was down-weighted; an update's result was not finite (and dropped): the
bits of the `Status` flags that say so, so that a result is or-ed into the filter's flags as it is."""
VISUAL_REJECTED = status_bits.VISUAL_REJECTED
"""`visual_update`: the frame's rotation failed the gate (a `Status` bit)."""
SYMMETRIES = rotations.manhattan_symmetries()
"""The 24 rotations that relabel a Manhattan frame (`rotations.manhattan_symmetries`, in its order):
a constant of the compiled code."""

# Layout of the float64 parameter vector `p`.
(P_Q_GYRO, P_Q_BIAS, P_Q_RATE, P_TRAPEZOID, P_PERIOD, P_DUE, P_DEFER, P_LP_TAU, P_INV_G, P_GRAVITY,
 P_ACCEL_NOISE, P_NORM_SCALE, P_INNOV_SCALE, P_FLAG_RATIO, P_REST_GYRO, P_REST_ACCEL, P_REST_MIN_S,
 P_REST_STD, P_MF_INIT, P_MF_YAW_RW, P_MF_TILT_RW, P_ORTHO_EVERY, P_RECORD, P_GAP_LIMIT, P_GATE_CHI2, P_HUBER,
 P_VERTICAL_STD, P_VERTICAL_MAX, P_VISUAL_CORRELATION, P_TRUST_FRAMES, P_TRUST_MIN_SHARE) = range(31)
P_SIZE = 31


def propagate_chunk(R_wc, b_c, P, last_gyro, t_state, t, gyro, extra_s, trapezoid, q_gyro, q_bias, q_rate,
                    C_out):
    """Integrate samples k = 0..n-1 (camera frame, no gaps) over (t_state, t[-1]] and then hold the
    last rate `extra_s` longer. Writes the cumulative rotations C_k (n, 3, 3) into `C_out` and
    returns (C_N, A_bias, T, P_predicted): `R_wc <- R_wc C_N`, `dtheta_N = C_N^T dtheta_0 - A_bias db`,
    T the time covered, P the covariance predicted with the closed-form transition and noise."""
    n = t.shape[0]
    C = np.eye(3)
    C_prev = np.empty((3, 3))
    M = np.empty((3, 3))
    S = np.zeros((3, 3))  # sum_k dt_k C_k
    T = 0.0
    rate_var = 0.0
    t_prev = t_state
    h0, h1, h2 = last_gyro[0], last_gyro[1], last_gyro[2]  # the previous reading
    b0, b1, b2 = b_c[0], b_c[1], b_c[2]
    m = n + 1 if extra_s > 0.0 else n
    for k in range(m):  # scalar code: no array is allocated per sample
        if k < n:
            dt, g0, g1, g2 = t[k] - t_prev, gyro[k, 0], gyro[k, 1], gyro[k, 2]
            t_prev = t[k]
        else:
            dt, g0, g1, g2 = extra_s, gyro[n - 1, 0], gyro[n - 1, 1], gyro[n - 1, 2]
        if trapezoid:
            r0, r1, r2 = 0.5 * (g0 + h0) - b0, 0.5 * (g1 + h1) - b1, 0.5 * (g2 + h2) - b2
        else:
            r0, r1, r2 = g0 - b0, g1 - b1, g2 - b2
        h0, h1, h2 = g0, g1, g2
        C_prev[:, :] = C
        matmul3_into(C_prev, exp3_into(r0 * dt, r1 * dt, r2 * dt, M), C)
        if k < n:
            C_out[k] = C
        for i in range(3):
            for j in range(3):
                S[i, j] += dt * C[i, j]
        T += dt
        rate_var += (r0 * r0 + r1 * r1 + r2 * r2) * dt
    A_bias = np.empty((3, 3))  # C^T S, written out (a BLAS call costs more than these 27 products)
    for i in range(3):
        for j in range(3):
            A_bias[i, j] = C[0, i] * S[0, j] + C[1, i] * S[1, j] + C[2, i] * S[2, j]
    P_pred = P.copy()
    gyro_predict_in_place(P_pred, C, A_bias)
    q_th = q_gyro * T + q_bias * T**3 / 3.0 + q_rate * rate_var
    for i in range(3):
        P_pred[i, i] += q_th
        P_pred[i, 3 + i] += -q_bias * T**2 / 2.0
        P_pred[3 + i, i] += -q_bias * T**2 / 2.0
        P_pred[3 + i, 3 + i] += q_bias * T
    return C, A_bias, T, P_pred


def gyro_predict_in_place(P, C, A_bias):
    """`P <- F P F^T` for the gyro transition `F` (identity but `F[TH, TH] = C^T`, `F[TH, BG] =
    -A_bias`, as `propagation.gyro_transition`), in place: only the attitude rows and columns change."""
    rows = np.empty((3, 12))  # (F P)[TH, :]
    for i in range(3):
        for j in range(12):
            rows[i, j] = (C[0, i] * P[0, j] + C[1, i] * P[1, j] + C[2, i] * P[2, j]
                          - A_bias[i, 0] * P[3, j] - A_bias[i, 1] * P[4, j] - A_bias[i, 2] * P[5, j])
    P[0:3, :] = rows
    cols = np.empty((12, 3))  # (F P F^T)[:, TH]
    for i in range(12):
        for j in range(3):
            cols[i, j] = (P[i, 0] * C[0, j] + P[i, 1] * C[1, j] + P[i, 2] * C[2, j]
                          - P[i, 3] * A_bias[j, 0] - P[i, 4] * A_bias[j, 1] - P[i, 5] * A_bias[j, 2])
    P[:, 0:3] = cols


def accel_measurement(accel_c, T, R_wc, lp_J1, use_lp_J, p):
    """`measurements.gravity_model` with the parameters of `p`."""
    return gravity_model(accel_c, T, R_wc, lp_J1, use_lp_J, p[P_GRAVITY], p[P_ACCEL_NOISE], p[P_NORM_SCALE],
                         p[P_INNOV_SCALE], p[P_FLAG_RATIO])


def zero_rate_measurement(rest_sums, rest_n, T, b_c, p):
    """`measurements.zero_rate_model` with the parameters of `p`."""
    return zero_rate_model(rest_sums, rest_n, T, b_c, p[P_Q_GYRO], p[P_REST_GYRO], p[P_REST_ACCEL], p[P_REST_STD])


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


def kalman_update(s, R_wc, R_wm, b_c, P, lp, lp_J, residual, R, H, p):
    """Joseph-form update with the measurement `residual` (m,), noise `R` (m, m) and `H` (m, 12), then
    injection into the nominal state and the reset of the error (as `Mekf._kalman_update`), all in
    place; nothing changes but `s[S_NONFINITE]` when the result is not finite.
    Scalar loops that use the structure (a BLAS call per small product costs more than the product,
    and more still out of the caches, after a solver call): the Joseph form expanded,
    `(I - K H) P (I - K H)^T + K R K^T = P - K (P H^T)^T - (P H^T) K^T + K S K^T` with `S` the
    innovation covariance, and the reset `G P G^T` on the rotation blocks only."""
    m = residual.shape[0]
    PHt = matmul_into(P, H.T, np.empty((12, m)))
    S = matmul_into(H, PHt, np.empty((m, m)))
    for i in range(m):
        for j in range(m):
            S[i, j] += R[i, j]
    K = solve_into(S, PHt.T, np.empty((m, 12))).T  # S symmetric: K^T = S^-1 (P H^T)^T
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
        s[S_NONFINITE] += 1
        return
    inject_and_reset(s, R_wc, R_wm, b_c, P, lp, lp_J, dx, P_new, p)


def isotropic_update(s, R_wc, R_wm, b_c, P, lp, lp_J, residual, var, H, p):
    """`kalman_update` of a 3-row measurement with isotropic noise `var`."""
    kalman_update(s, R_wc, R_wm, b_c, P, lp, lp_J, residual, var * np.eye(3), H, p)


def inject_and_reset(s, R_wc, R_wm, b_c, P, lp, lp_J, dx, P_new, p):
    """After an update with error estimate `dx` (12,) and covariance `P_new` (12, 12): `dx` injected
    into the nominal state and the low-pass stages (as `Mekf._kalman_update`), and `P` set to the
    reset `G P_new G^T`, symmetrised, all in place."""
    with_manhattan = p[P_MF_INIT] > 0
    G = reset_jacobian(dx, with_manhattan)
    if with_manhattan:
        R_wm[:, :] = matmul3_into(R_wm, exp3_into(dx[6], dx[7], dx[8], np.empty((3, 3))), np.empty((3, 3)))
    R_wc[:, :] = matmul3_into(R_wc, exp3_into(dx[0], dx[1], dx[2], np.empty((3, 3))), np.empty((3, 3)))
    s[S_PRODUCTS] += 1
    if s[S_PRODUCTS] >= p[P_ORTHO_EVERY]:
        R_wc[:, :] = orthonormal(R_wc)
        R_wm[:, :] = orthonormal(R_wm)
        s[S_PRODUCTS] = 0
    for i in range(3):
        b_c[i] += dx[3 + i]
    if s[S_LP_VALID] > 0:
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


def accel_rows(s, R_wc, R_wm, b_c, P, accel_sum, lp, lp_J, rest_sums, p):
    """The end of an accelerometer period (as `Mekf._accel_rows`): the zero-rate update when at rest,
    applied in place, then the (low-passed) accelerometer direction's measurement. Consumes the
    period. Returns (ok, residual (3,), variance, H (3, 12), downweighted); `ok` False (no
    measurement) near free fall."""
    T = s[S_ACCEL_TIME]
    accel_c = accel_sum / T if T > 0 else accel_sum.copy()
    accel_sum[:] = 0.0
    s[S_ACCEL_TIME] = 0.0
    s[S_ACCEL_ELAPSED] = 0.0
    if p[P_REST_GYRO] > 0:
        n = s[S_REST_N]
        if n >= 2 and T > 0:
            at_rest, r, var, H = zero_rate_measurement(rest_sums, n, T, b_c, p)
            if not at_rest:
                s[S_REST_SINCE] = np.nan
            else:
                if math.isnan(s[S_REST_SINCE]):
                    s[S_REST_SINCE] = s[S_T_STATE] - T
                if s[S_T_STATE] - s[S_REST_SINCE] >= p[P_REST_MIN_S]:
                    isotropic_update(s, R_wc, R_wm, b_c, P, lp, lp_J, r, var, H, p)
                    s[S_REST_UPDATES] += 1
        rest_sums[:] = 0.0
        s[S_REST_N] = 0
    tau = p[P_LP_TAU]
    if tau > 0 and T > 0:
        if s[S_LP_VALID] == 0:
            lp[0], lp[1] = accel_c, accel_c
            lp_J[:] = 0.0
            s[S_LP_VALID] = 1
        else:
            alpha = 1.0 - math.exp(-T / tau)
            lp[0] += alpha * (accel_c - lp[0])
            lp[1] += alpha * (lp[0] - lp[1])
            lp_J[0] *= 1.0 - alpha
            lp_J[1] += alpha * (lp_J[0] - lp_J[1])
        accel_c = lp[1].copy()
    ok, r, var, H, downweighted = accel_measurement(accel_c, T, R_wc, lp_J[1], tau > 0, p)
    if not ok:
        s[S_ACCEL_SKIPPED] += 1
        return False, r, var, H, False
    note_accel_information(s, var, T)
    if downweighted:
        s[S_ACCEL_DOWNWEIGHTED] += 1
    s[S_ACCEL_UPDATES] += 1
    return True, r, var, H, downweighted


def accel_and_rest_update(s, R_wc, R_wm, b_c, P, accel_sum, lp, lp_J, rest_sums, p):
    """The update at the end of an accelerometer period (as `Mekf.accel_update`), in place:
    `accel_rows`, then its measurement's update. Returns whether it was down-weighted."""
    ok, r, var, H, downweighted = accel_rows(s, R_wc, R_wm, b_c, P, accel_sum, lp, lp_J, rest_sums, p)
    if ok:
        isotropic_update(s, R_wc, R_wm, b_c, P, lp, lp_J, r, var, H, p)
    return downweighted


def state_views(x):
    """The fields of the state buffer `x` (`state_buffer.py`) as views: (s, R_wc, R_wm, b_c, P,
    last_gyro, accel_sum, lp, lp_J, rest_sums)."""
    return (x[X_S:X_R_WC], x[X_R_WC:X_R_WM].reshape((3, 3)), x[X_R_WM:X_B_C].reshape((3, 3)), x[X_B_C:X_P],
            x[X_P:X_LAST_GYRO].reshape((12, 12)), x[X_LAST_GYRO:X_ACCEL_SUM], x[X_ACCEL_SUM:X_LP],
            x[X_LP:X_LP_J].reshape((2, 3)), x[X_LP_J:X_REST_SUMS].reshape((2, 3, 3)), x[X_REST_SUMS:X_SIZE])


def integrate_batch(x, rows, extra_s, p, record_R, record_P):
    """Integrate a released batch `rows` (n, 8) (`types.IMU_COLUMNS`: t s, gyro rad/s, accel m/s^2,
    camera frame; no gaps or saturated samples) into the state buffer `x`, in place, as
    `Mekf._integrate_pending` does: chunk by chunk (`accel.chunk_bounds`), with the accelerometer
    updates that fall due, except one due at the end of a batch propagated to a frame (`P_DEFER`):
    that one is left to the frame (`s[S_ACCEL_DUE]` = 1). The last chunk is extrapolated by `extra_s`.
    With `P_RECORD`, `record_R` (n, 3, 3) receives R_wc after each sample and `record_P` the attitude
    covariance predicted to the end of its chunk. Returns the `DOWNWEIGHTED` | `NONFINITE` bits of
    what happened, or -1, changing nothing, when a step (from `s[S_T_STATE]` on) exceeds
    `P_GAP_LIMIT` (an IMU gap). The batch's last stamp goes to `s[S_IMU_T]`."""
    s, R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums = state_views(x)
    t, gyro, accel = rows[:, 0], rows[:, 1:4], rows[:, 4:7]
    if has_gap(t, s[S_T_STATE], p[P_GAP_LIMIT]):
        return -1
    nonfinite_before = s[S_NONFINITE]
    bounds = chunk_bounds(t, s[S_T_STATE], s[S_ACCEL_ELAPSED], p[P_PERIOD])
    code = integrate_chunks(s, R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums, t, gyro, accel, bounds,
                            extra_s, p, record_R, record_P)
    code |= NONFINITE if s[S_NONFINITE] > nonfinite_before else 0
    s[S_IMU_T] = t[t.shape[0] - 1]
    return code


def visual_measurement(R_wc, R_wm, R_cm, cov, r, R_vis, H):
    """`measurements.visual_model` on plain arrays, into the first three rows of `r` (m,), `R_vis`
    (m, m) and `H` (m, 12) (zeros elsewhere, which it leaves): the solver's `R_cm` (3, 3) with
    covariance `cov` (3, 3) rad^2 measures `R_cm = R_wc^T R_wm`, relabelled by the symmetry that
    brings it nearest the prediction (the first of `SYMMETRIES` with the largest trace, as
    `rotations.nearest_symmetric`); residual `Log(R_cm_pred^T R_cm)`."""
    R_pred = np.empty((3, 3))  # R_wc^T R_wm
    for i in range(3):
        for j in range(3):
            R_pred[i, j] = R_wc[0, i] * R_wm[0, j] + R_wc[1, i] * R_wm[1, j] + R_wc[2, i] * R_wm[2, j]
    A = np.empty((3, 3))  # R_pred^T R_cm
    for i in range(3):
        for j in range(3):
            A[i, j] = R_pred[0, i] * R_cm[0, j] + R_pred[1, i] * R_cm[1, j] + R_pred[2, i] * R_cm[2, j]
    best, best_trace = 0, -np.inf
    for g in range(SYMMETRIES.shape[0]):
        trace = 0.0
        for i in range(3):
            for j in range(3):
                trace += A[i, j] * SYMMETRIES[g, j, i]
        if trace > best_trace:
            best, best_trace = g, trace
    G = SYMMETRIES[best]
    log3_into(matmul3_into(A, G, np.empty((3, 3))), r)
    C = np.empty((3, 3))  # G^T (cov + cov^T)/2 G
    for i in range(3):
        for j in range(3):
            C[i, j] = 0.5 * (cov[i, j] + cov[j, i])
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += G[k, i] * (C[k, 0] * G[0, j] + C[k, 1] * G[1, j] + C[k, 2] * G[2, j])
            R_vis[i, j] = acc
            H[i, j] = -R_pred[j, i]
        H[i, 6 + i] = 1.0


def visual_update(x, p, R_cm, cov, estimate):
    """A frame's rotation `R_cm` (3, 3) with covariance `cov` (3, 3) rad^2, fused into the state
    buffer `x` in place as `Mekf._visual_update` fuses it with an IMU (a due accelerometer update's
    rows taken first, as `Mekf._take_accel_rows`): gated on its Mahalanobis distance
    (`P_GATE_CHI2`; past it the accelerometer rows alone, the frame counted in `s[S_REJECTIONS]` and
    `s[S_VISUAL_REJECTED]`), its covariance scaled for correlated errors (`P_VISUAL_CORRELATION`) and
    by the Huber weight (`P_HUBER`), stacked with the vertical pseudo-measurement and the accelerometer
    rows into one update. The estimate after it goes to `estimate` (4, 3, 3): `R_wc`, its covariance
    (the attitude block of `P`, symmetrised), `R_wm`, and `b_c` in the first row. Returns the
    `VISUAL_REJECTED` | `DOWNWEIGHTED` | `NONFINITE` bits of what happened; the re-initialisation after
    many rejections is left to the caller."""
    s, R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums = state_views(x)
    nonfinite_before = s[S_NONFINITE]
    code = 0
    r, R_all, H = np.zeros(9), np.zeros((9, 9)), np.zeros((9, 12))
    visual_measurement(R_wc, R_wm, R_cm, cov, r, R_all, H)
    # How far the camera is trusted (`source_trust.py`), from the frame before the accelerometer rows
    # consume the period's specific force.
    var_v = p[P_VERTICAL_STD] ** 2
    quiet = (p[P_FLAG_RATIO] * p[P_ACCEL_NOISE]) ** 2
    e, v = visual_vertical_innovation(R_wc, R_wm, r, R_all, accel_sum, s[S_ACCEL_TIME], s[S_ACCEL_VAR_RATE], quiet, var_v)
    share, _ = update_visual_trust(s, e, v, p[P_TRUST_FRAMES], p[P_TRUST_MIN_SHARE], squared_rate(last_gyro, b_c))
    var_v = vertical_variance(s, var_v, p[P_TRUST_FRAMES])
    t_prev = s[S_T_VISUAL]
    s[S_T_VISUAL] = s[S_T_STATE]
    note_visual_information(s, R_all, share, var_v, s[S_T_STATE] - t_prev if t_prev == t_prev else 0.0)
    with_accel, downweighted = False, False
    if s[S_ACCEL_DUE] > 0:  # left to the frame at the end of its batch (`P_DEFER`)
        s[S_ACCEL_DUE] = 0
        rest_before = s[S_REST_UPDATES]
        with_accel, r_a, var_a, H_a, downweighted = accel_rows(s, R_wc, R_wm, b_c, P, accel_sum, lp, lp_J, rest_sums, p)
        if s[S_REST_UPDATES] > rest_before:  # the zero-rate update moved the state: the residual again
            r[:], R_all[:, :], H[:, :] = 0.0, 0.0, 0.0
            visual_measurement(R_wc, R_wm, R_cm, cov, r, R_all, H)
    if t_prev == t_prev:  # not NaN: a previous visual update
        R_all[0:3, 0:3] *= correlated_noise_scale(s[S_T_STATE] - t_prev, p[P_VISUAL_CORRELATION])
    PHt = matmul_into(P, H[0:3].T, np.empty((12, 3)))  # the gate and Huber weigh the frame's full error
    S = matmul_into(H[0:3], PHt, np.empty((3, 3)))
    S += R_all[0:3, 0:3]
    S_inv = inv3(S)
    d2 = 0.0
    for i in range(3):
        d2 += r[i] * (S_inv[i, 0] * r[0] + S_inv[i, 1] * r[1] + S_inv[i, 2] * r[2])
    if not -np.inf < d2 <= p[P_GATE_CHI2]:  # NaN and a singular innovation covariance too
        code |= VISUAL_REJECTED
        s[S_VISUAL_REJECTED] += 1
        s[S_REJECTIONS] += 1
        s[S_VISUAL_INFO_RATE] = 0.0  # no share while the camera is gated out
        if with_accel:
            isotropic_update(s, R_wc, R_wm, b_c, P, lp, lp_J, r_a, var_a, H_a, p)
    else:
        s[S_REJECTIONS] = 0
        d = math.sqrt(d2)
        if d > p[P_HUBER]:  # Huber weight w = k / d  ->  covariance / w
            R_all[0:3, 0:3] *= d / p[P_HUBER]
        if share != 1.0:  # the independent share of the frame's error (gated on the full one)
            R_all[0:3, 0:3] *= share
        m = 3
        ok, r_v, _, H_v = vertical_measurement(R_wm, p[P_VERTICAL_STD], p[P_VERTICAL_MAX])
        if ok and var_v < np.inf:
            r[3:6] = r_v
            H[3:6] = H_v
            for i in range(3):
                R_all[3 + i, 3 + i] = var_v
            m = 6
        if with_accel:
            r[m:m + 3] = r_a
            H[m:m + 3] = H_a
            for i in range(3):
                R_all[m + i, m + i] = var_a
            m += 3
        kalman_update(s, R_wc, R_wm, b_c, P, lp, lp_J, r[:m], R_all[:m, :m], H[:m], p)
        s[S_VISUAL_UPDATES] += 1
    for i in range(3):
        for j in range(3):
            estimate[0, i, j] = R_wc[i, j]
            estimate[1, i, j] = 0.5 * (P[i, j] + P[j, i])
            estimate[2, i, j] = R_wm[i, j]
        estimate[3, 0, i] = b_c[i]
    return code | (DOWNWEIGHTED if downweighted else 0) | (NONFINITE if s[S_NONFINITE] > nonfinite_before else 0)


def stage_batch(stage, t, gyro, accel, newest_s, gyro_range_rad_s, max_span_s):
    """A frame's IMU samples (`t` (n,) s, `gyro` (n, 3) rad/s, `accel` (n, 3) m/s^2, camera frame;
    shapes checked), checked as `ImuStream.add` checks them (`imu_stream.rows_if_clean` against
    `newest_s` and `gyro_range_rad_s`) and copied into the rows of `stage` (`types.IMU_COLUMNS`),
    where they wait for the frame (`integrate_staged`). Returns n, or 0 (the samples are left to the
    reorder buffer) when there are none, more than `stage` holds, a span of `max_span_s` or more, or
    a sample that is not clean."""
    n = t.shape[0]
    if n == 0 or n > stage.shape[0] or not t[n - 1] - t[0] < max_span_s:
        return 0
    return n if rows_if_clean(t, gyro, accel, newest_s, gyro_range_rad_s, stage[:n]) else 0


def integrate_staged(x, stage, n, t_frame_s, p, record_R, record_P):
    """`integrate_batch` for the `n` rows of `stage` (`stage_batch`), propagated to a frame at
    `t_frame_s` s: -2, changing nothing, unless they are all at or before the frame, the frame no
    further than `P_GAP_LIMIT` past the last one, and no accelerometer update waits (`s[S_ACCEL_DUE]`)."""
    rows = stage[:n]
    t_last = rows[n - 1, 0]
    if not t_last <= t_frame_s or not t_frame_s - t_last <= p[P_GAP_LIMIT] or x[X_S + S_ACCEL_DUE] > 0:
        return -2
    return integrate_batch(x, rows, t_frame_s - t_last, p, record_R, record_P)


def has_gap(t, t_state, gap_limit_s):
    """Whether a step between samples `t` (from `t_state` on) exceeds `gap_limit_s` (an IMU gap)."""
    t_prev = t_state
    for k in range(t.shape[0]):
        if t[k] - t_prev > gap_limit_s:
            return True
        t_prev = t[k]
    return False


def integrate_chunks(s, R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums, t, gyro, accel, bounds,
                     extra_s, p, record_R, record_P):
    """`integrate_batch` on a batch known to hold no gap: `DOWNWEIGHTED` when an update was, else 0."""
    n_chunks = bounds.shape[0] - 1
    downweighted_any = False
    C_buf = np.empty((t.shape[0], 3, 3))
    for c in range(n_chunks):
        a, b = bounds[c], bounds[c + 1]
        last = c == n_chunks - 1
        extra = extra_s if last else 0.0
        C_k = C_buf[a:b]
        C_N, A_bias, T, P_pred = propagate_chunk(R_wc, b_c, P, last_gyro, s[S_T_STATE], t[a:b], gyro[a:b],
                                                 extra, p[P_TRAPEZOID] > 0, p[P_Q_GYRO], p[P_Q_BIAS],
                                                 p[P_Q_RATE], C_k)
        if p[P_MF_INIT] > 0 and (p[P_MF_YAW_RW] > 0 or p[P_MF_TILT_RW] > 0) and T > 0:
            u = R_wm[2].copy()
            uu = np.outer(u, u)
            P_pred[6:9, 6:9] += T * (p[P_MF_YAW_RW] ** 2 * uu + p[P_MF_TILT_RW] ** 2 * (np.eye(3) - uu))
        P[:, :] = P_pred
        if p[P_RECORD] > 0:
            for k in range(b - a):
                matmul3_into(R_wc, C_k[k], record_R[a + k])
                record_P[a + k] = P_pred[0:3, 0:3]
        R_wc[:, :] = matmul3_into(R_wc, C_N, np.empty((3, 3)))
        s[S_PRODUCTS] += 1
        if s[S_PRODUCTS] >= p[P_ORTHO_EVERY]:
            R_wc[:, :] = orthonormal(R_wc)
            R_wm[:, :] = orthonormal(R_wm)
            s[S_PRODUCTS] = 0
        last_gyro[:] = gyro[b - 1]
        # Specific force, time-weighted, in the chunk's end frame.
        acc = accel_sum.copy()
        t_prev = s[S_T_STATE]
        for k in range(b - a):
            dt = t[a + k] - t_prev
            f0, f1, f2 = accel[a + k, 0], accel[a + k, 1], accel[a + k, 2]
            for i in range(3):
                acc[i] += dt * (C_k[k, i, 0] * f0 + C_k[k, i, 1] * f1 + C_k[k, i, 2] * f2)
            t_prev = t[a + k]
        for i in range(3):
            accel_sum[i] = C_N[0, i] * acc[0] + C_N[1, i] * acc[1] + C_N[2, i] * acc[2]
        s[S_ACCEL_TIME] += T - extra
        s[S_ACCEL_ELAPSED] += T
        if s[S_LP_VALID] > 0:
            carry_lowpass_in_place(lp, lp_J, C_N, A_bias)
        if p[P_REST_GYRO] > 0:
            for k in range(a, b):
                g0, g1, g2, f0, f1, f2 = gyro[k, 0], gyro[k, 1], gyro[k, 2], accel[k, 0], accel[k, 1], accel[k, 2]
                rest_sums[0] += g0
                rest_sums[1] += g1
                rest_sums[2] += g2
                rest_sums[3] += g0 * g0 + g1 * g1 + g2 * g2
                rest_sums[4] += f0
                rest_sums[5] += f1
                rest_sums[6] += f2
                rest_sums[7] += f0 * f0 + f1 * f1 + f2 * f2
            s[S_REST_N] += b - a
        s[S_T_STATE] = t[b - 1] + extra
        if not last or s[S_ACCEL_ELAPSED] >= p[P_DUE]:
            if last and p[P_DEFER] > 0:
                s[S_ACCEL_DUE] = 1
            else:
                downweighted_any |= accel_and_rest_update(s, R_wc, R_wm, b_c, P, accel_sum, lp, lp_J, rest_sums, p)
    return DOWNWEIGHTED if downweighted_any else 0


def carry_lowpass_in_place(lp, lp_J, C_N, A_bias):
    """`accel.AccelPeriod.carry_lowpass` on the kernels' arrays, without allocating per stage:
    `lp[s] <- C_N^T lp[s]`, `lp_J[s] <- C_N^T lp_J[s] - skew(lp[s]) A_bias` (the new lp[s])."""
    v = np.empty(3)
    J = np.empty((3, 3))
    for st in range(2):
        for i in range(3):
            v[i] = C_N[0, i] * lp[st, 0] + C_N[1, i] * lp[st, 1] + C_N[2, i] * lp[st, 2]
            for j in range(3):
                J[i, j] = C_N[0, i] * lp_J[st, 0, j] + C_N[1, i] * lp_J[st, 1, j] + C_N[2, i] * lp_J[st, 2, j]
        for j in range(3):  # skew(v) @ A_bias, column j
            a0, a1, a2 = A_bias[0, j], A_bias[1, j], A_bias[2, j]
            J[0, j] -= v[1] * a2 - v[2] * a1
            J[1, j] -= v[2] * a0 - v[0] * a2
            J[2, j] -= v[0] * a1 - v[1] * a0
        lp[st, :] = v
        lp_J[st, :, :] = J


def integrate_segments(x, t, gyro, accel, ends, p, record_R, record_P, out_R, out_cov, out_b, out_flags):
    """An IMU-only stream (camera frame, no gaps or saturated samples) in segments, segment i being
    samples ends[i-1]:ends[i] (from 0): each is integrated into the state buffer `x` as
    `integrate_batch` integrates one released batch (chunks cut by `accel.chunk_bounds`, updates
    falling due applied, none deferred), and the estimate after it written out: `out_R[i]` R_wc,
    `out_cov[i]` the attitude covariance (symmetrised), `out_b[i]` b_c, `out_flags[i]` the
    `DOWNWEIGHTED` | `NONFINITE` bits of what happened. Returns -1, changing nothing, when a step
    exceeds `P_GAP_LIMIT`, else 0."""
    s, R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums = state_views(x)
    if has_gap(t, s[S_T_STATE], p[P_GAP_LIMIT]):
        return -1
    start = 0
    for i in range(ends.shape[0]):
        end = ends[i]
        seg_t = t[start:end]
        bounds = chunk_bounds(seg_t, s[S_T_STATE], s[S_ACCEL_ELAPSED], p[P_PERIOD])
        nonfinite_before = s[S_NONFINITE]
        downweighted = integrate_chunks(s, R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums, seg_t,
                                        gyro[start:end], accel[start:end], bounds, 0.0, p, record_R[start:end],
                                        record_P[start:end])
        out_R[i] = R_wc
        out_cov[i] = 0.5 * (P[0:3, 0:3] + P[0:3, 0:3].T)
        out_b[i] = b_c
        out_flags[i] = downweighted + (NONFINITE if s[S_NONFINITE] > nonfinite_before else 0)
        start = end
    s[S_IMU_T] = t[t.shape[0] - 1]
    return 0


def accel_update_in_place(x, p):
    """`accel_and_rest_update` on the state buffer `x`, in place: the `DOWNWEIGHTED` | `NONFINITE`
    bits of what happened."""
    s, R_wc, R_wm, b_c, P, _, accel_sum, lp, lp_J, rest_sums = state_views(x)
    nonfinite_before = s[S_NONFINITE]
    downweighted = accel_and_rest_update(s, R_wc, R_wm, b_c, P, accel_sum, lp, lp_J, rest_sums, p)
    return (DOWNWEIGHTED if downweighted else 0) + (NONFINITE if s[S_NONFINITE] > nonfinite_before else 0)


KERNEL = None
"""`integrate_batch` compiled, with the functions it calls, or None (numba missing or broken)."""
ACCEL_UPDATE = None
"""`accel_update_in_place` compiled, or None."""
SEGMENTS = None
"""`integrate_segments` compiled, or None."""
STAGE = None
"""`stage_batch` compiled, or None."""
INTEGRATE_STAGED = None
"""`integrate_staged` compiled, or None."""
VISUAL_UPDATE = None
"""`visual_update` compiled, or None."""


def disable_all() -> None:
    """No compiled kernels from now on (numba failed here or at a first call: `compiled.fall_back`)."""
    global KERNEL, ACCEL_UPDATE, SEGMENTS, STAGE, INTEGRATE_STAGED, VISUAL_UPDATE
    KERNEL = ACCEL_UPDATE = SEGMENTS = STAGE = INTEGRATE_STAGED = VISUAL_UPDATE = None


if jit.available():
    try:
        _pure = (reset_jacobian, gravity_model, zero_rate_model, orthonormal, inv3, exp3_into,
                 matmul3_into, gyro_predict_in_place, carry_lowpass_in_place, propagate_chunk, accel_measurement,
                 zero_rate_measurement, matmul_into, solve_into, inject_and_reset, kalman_update, isotropic_update,
                 accel_rows, accel_and_rest_update, has_gap, chunk_bounds, integrate_chunks, state_views, rows_if_clean,
                 integrate_batch, correlated_noise_scale, log3_into, vertical_measurement, visual_measurement,
                 note_accel_information, note_visual_information, update_visual_trust, vertical_variance,
                 visual_vertical_innovation, squared_rate)
        # The modules whose functions the kernels inline or whose constants they freeze.
        jit.drop_stale_caches({__file__, rotations.__file__, state_buffer.__file__, status_bits.__file__}
                              | {sys.modules[f.__module__].__file__ for f in _pure})
        for _f in _pure:
            globals()[_f.__name__] = jit.compiled(_f, cache=True, error_model="numpy")
        KERNEL = integrate_batch
        STAGE = jit.compiled(stage_batch, cache=True, nogil=False)  # per frame, a few microseconds each
        INTEGRATE_STAGED = jit.compiled(integrate_staged, cache=True, error_model="numpy", nogil=False)
        ACCEL_UPDATE = jit.compiled(accel_update_in_place, cache=True, error_model="numpy")
        SEGMENTS = jit.compiled(integrate_segments, cache=True, error_model="numpy")
        VISUAL_UPDATE = jit.compiled(visual_update, cache=True, error_model="numpy", nogil=False)
    except Exception as exc:  # noqa: BLE001 -- fall back to the reference path
        jit.disable(exc)
        disable_all()
