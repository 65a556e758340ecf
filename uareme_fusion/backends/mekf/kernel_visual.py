"""The EKF's frame-time kernels on the state buffer: the visual measurement and update (with an IMU,
and visual only), the disagreement test before it, and the visual-only constant-rate prediction
(numba-compiled by `kernels`, plain Python without numba).

Visual model (docs/design.md "Backends"): the solver's `R_cm` measures `R_cm = R_wc^T R_wm`, residual
`Log(R_cm_pred^T R_cm)`, `H = [-R_cm_pred^T, 0, I, 0]`. Constant-rate model (visual only): `R_wc <-
R_wc Exp(omega_c dt)`, `omega_c` a random walk.
"""

from __future__ import annotations

import math

import numpy as np

from ... import rotations
from . import status_bits
from .kernel_update import DOWNWEIGHTED, NONFINITE, accel_rows, kalman_update, matmul_into, state_views
from .matrix3 import exp3_into, inv3, log3_into, matmul3_into
from .measurements import Measurement, correlated_noise_scale, vertical_model
from .source_trust import (note_visual_information, share_tilt_covariance, squared_rate, update_visual_trust,
                           vertical_variance, visual_vertical_innovation)
from .state import orthonormal

VISUAL_REJECTED = status_bits.VISUAL_REJECTED
"""`visual_update`: the frame's rotation failed the gate (a `Status` bit)."""
SYMMETRIES = rotations.manhattan_symmetries()
"""The 24 rotations that relabel a Manhattan frame (`rotations.manhattan_symmetries`, in its order):
a constant of the compiled code."""


def visual_model(R_wc, R_wm, R_cm, cov, relabel):
    """The solver's `R_cm` (3, 3) with covariance `cov` (3, 3) rad^2 (right perturbation) measures
    `R_cm = R_wc^T R_wm`; with `relabel`, relabelled first by the symmetry that brings it nearest the
    prediction (the first of `SYMMETRIES` with the largest trace, as `rotations.nearest_symmetric`),
    else as labelled (`backends.labelling_track`): residual `Log(R_cm_pred^T R_cm)`, covariance
    `G^T cov G` (symmetrised) for the relabelling `G`, `H = [-R_cm_pred^T, 0, I, 0]`. Always `ok`."""
    R_pred = np.empty((3, 3))  # R_wc^T R_wm
    for i in range(3):
        for j in range(3):
            R_pred[i, j] = R_wc[0, i] * R_wm[0, j] + R_wc[1, i] * R_wm[1, j] + R_wc[2, i] * R_wm[2, j]
    A = np.empty((3, 3))  # R_pred^T R_cm
    for i in range(3):
        for j in range(3):
            A[i, j] = R_pred[0, i] * R_cm[0, j] + R_pred[1, i] * R_cm[1, j] + R_pred[2, i] * R_cm[2, j]
    best, best_trace = 0, -np.inf  # SYMMETRIES[0] is the identity
    for g in range(SYMMETRIES.shape[0] if relabel else 0):
        trace = 0.0
        for i in range(3):
            for j in range(3):
                trace += A[i, j] * SYMMETRIES[g, j, i]
        if trace > best_trace:
            best, best_trace = g, trace
    G = SYMMETRIES[best]
    r = log3_into(matmul3_into(A, G, np.empty((3, 3))), np.empty(3))
    C = np.empty((3, 3))  # G^T (cov + cov^T)/2 G
    for i in range(3):
        for j in range(3):
            C[i, j] = 0.5 * (cov[i, j] + cov[j, i])
    R_vis, H = np.empty((3, 3)), np.zeros((3, 12))
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += G[k, i] * (C[k, 0] * G[0, j] + C[k, 1] * G[1, j] + C[k, 2] * G[2, j])
            R_vis[i, j] = acc
            H[i, j] = -R_pred[j, i]
        H[i, 6 + i] = 1.0
    return Measurement(True, r, R_vis, H)


def visual_rows(R_wc, R_wm, R_cm, cov, relabel, r, R_vis, H):
    """`visual_model` into the first three rows of a stacked update's `r` (m,), `R_vis`
    (m, m) and `H` (m, 12) (zeros elsewhere, which it leaves)."""
    visual = visual_model(R_wc, R_wm, R_cm, cov, relabel)
    r[0:3] = visual.residual
    R_vis[0:3, 0:3] = visual.covariance
    H[0:3] = visual.jacobian


def visual_update(x, params, R_cm, cov, share_scale, extra_r, extra_R, extra_H, estimate):
    """A frame's rotation `R_cm` (3, 3) with covariance `cov` (3, 3) rad^2, fused into the state
    buffer `x` in place: gated on its Mahalanobis distance (`p.visual_gate_chi2`; past it the other
    rows alone, the frame counted in `s.rejections` and `s.visual_rejected`), its covariance
    scaled for correlated errors (`p.visual_correlation_s`; with an IMU the gyro bias's gain too,
    `p.bias_visual_correlation_s`), by the Huber weight (`p.visual_huber_k`)
    and by the independent share (`share_scale` given, visual only: `VisualNoiseShare`), stacked into
    one update with:
    - with an IMU (`p.uses_imu`): the camera-vertical trust (`source_trust.py`, its share of the
      covariance too), the vertical pseudo-measurement, and a due accelerometer update's rows (its
      zero-rate update applied first);
    - the `extra_*` rows (k rows, k = 0 or 3: the gravity of an accelerometer without gyro, visual only).
    The estimate after it goes to `estimate` (4, 3, 3): `R_wc`, its covariance (the attitude block of
    `P`, symmetrised), `R_wm`, and `b_c` in the first row. Returns the `VISUAL_REJECTED` |
    `DOWNWEIGHTED` | `NONFINITE` bits of what happened; the re-initialisation after many rejections is
    left to the caller."""
    p = params[0]
    s = x[0]
    R_wc, R_wm, b_c, P, last_gyro, accel_sum = state_views(x)[:6]
    with_imu = p.uses_imu > 0
    nonfinite_before = s.nonfinite_updates
    code = 0
    r, R_all, H = np.zeros(9), np.zeros((9, 9)), np.zeros((9, 12))
    visual_rows(R_wc, R_wm, R_cm, cov, with_imu, r, R_all, H)
    share, var_v = 1.0, math.inf
    t_prev = s.t_visual_s
    s.t_visual_s = s.t_state_s
    with_accel, downweighted = False, False
    if with_imu:
        # How far the camera is trusted (`source_trust.py`), from the frame before the accelerometer
        # rows consume the period's specific force.
        var_v = p.vertical_std_rad ** 2
        quiet = (p.accel_downweight_flag_ratio * p.accel_tilt_noise) ** 2
        e, v = visual_vertical_innovation(R_wc, R_wm, r, R_all, accel_sum, s.accel_time_s, s.accel_var_rate,
                                          quiet, var_v)
        share, _ = update_visual_trust(s, e, v, p.visual_trust_frames, p.visual_trust_min_share,
                                       squared_rate(last_gyro, b_c))
        var_v = vertical_variance(s, var_v, p.visual_trust_frames)
        note_visual_information(s, R_all, share, var_v, s.t_state_s - t_prev if t_prev == t_prev else 0.0)
        if s.accel_due > 0:  # left to the frame at the end of its batch (`p.defer`)
            s.accel_due = 0
            rest_before = s.rest_updates
            gravity, downweighted = accel_rows(x, p, 0.0)  # stacked below
            with_accel = gravity.ok
            if s.rest_updates > rest_before:  # the zero-rate update moved the state: the residual again
                r[:], R_all[:, :], H[:, :] = 0.0, 0.0, 0.0
                visual_rows(R_wc, R_wm, R_cm, cov, with_imu, r, R_all, H)
    if t_prev == t_prev:  # not NaN: a previous visual update
        R_all[0:3, 0:3] *= correlated_noise_scale(s.t_state_s - t_prev, p.visual_correlation_s)
    PHt = matmul_into(P, H[0:3].T, np.empty((12, 3)))  # the gate and Huber weigh the frame's full error
    S = matmul_into(H[0:3], PHt, np.empty((3, 3)))
    S += R_all[0:3, 0:3]
    S_inv = inv3(S)
    d2 = 0.0
    for i in range(3):
        d2 += r[i] * (S_inv[i, 0] * r[0] + S_inv[i, 1] * r[1] + S_inv[i, 2] * r[2])
    k = extra_r.shape[0]
    if not -np.inf < d2 <= p.visual_gate_chi2:  # NaN and a singular innovation covariance too
        code |= VISUAL_REJECTED
        s.visual_rejected += 1
        s.rejections += 1
        s.visual_info_rate = 0.0  # no share while the camera is gated out
        if with_accel:
            kalman_update(x, gravity.residual, gravity.covariance, gravity.jacobian, p, 1.0)
        if k:
            kalman_update(x, extra_r, extra_R, extra_H, p, 1.0)
    else:
        s.rejections = 0
        if share_scale != 1.0:  # the independent share, as estimated over the previous frames (visual only)
            R_all[0:3, 0:3] *= share_scale
        d = math.sqrt(d2)
        if d > p.visual_huber_k:  # Huber weight w = k / d  ->  covariance / w
            R_all[0:3, 0:3] *= d / p.visual_huber_k
        if share != 1.0:  # the independent share of the frame's tilt error (gated on the full one)
            share_tilt_covariance(R_all[0:3, 0:3], share, R_wm)
        m = 3
        if with_imu:  # "m's z is up" only where the world is not the Manhattan frame itself
            vertical = vertical_model(R_wm, p.vertical_std_rad, p.vertical_max_rad)
            if vertical.ok and var_v < np.inf:  # its variance from the trust (`source_trust.vertical_variance`)
                r[3:6] = vertical.residual
                H[3:6] = vertical.jacobian
                for i in range(3):
                    R_all[3 + i, 3 + i] = var_v
                m = 6
        if with_accel:
            r[m:m + 3] = gravity.residual
            H[m:m + 3] = gravity.jacobian
            R_all[m:m + 3, m:m + 3] = gravity.covariance
            m += 3
        if k:
            r[m:m + k] = extra_r
            H[m:m + k] = extra_H
            R_all[m:m + k, m:m + k] = extra_R
            m += k
        bias_gain = 1.0  # the frames' persistent error, as the bias sees it (1 after no previous frame: dt NaN)
        if with_imu:
            bias_gain = 1.0 / correlated_noise_scale(s.t_state_s - t_prev, p.bias_visual_correlation_s)
        kalman_update(x, r[:m], R_all, H[:m], p, bias_gain)  # R_all's leading m x m block
        s.visual_updates += 1
    for i in range(3):
        for j in range(3):
            estimate[0, i, j] = R_wc[i, j]
            estimate[1, i, j] = 0.5 * (P[i, j] + P[j, i])
            estimate[2, i, j] = R_wm[i, j]
        estimate[3, 0, i] = b_c[i]
    return code | (DOWNWEIGHTED if downweighted else 0) | (NONFINITE if s.nonfinite_updates > nonfinite_before else 0)


def visual_distance(x, P, R_cm, cov, relabel):
    """`(angle rad, d2)` of a frame's rotation against the prediction of the state buffer `x`: the norm
    of its residual (`visual_model`, relabelled nearest the prediction with `relabel`) and its
    squared Mahalanobis distance under the error covariance `P` (12, 12) and its own (inf for a
    singular innovation covariance)."""
    R_wc, R_wm = state_views(x)[:2]
    r, R_vis, H = visual_model(R_wc, R_wm, R_cm, cov, relabel)[1:]
    PHt = matmul_into(P, H.T, np.empty((12, 3)))
    S = matmul_into(H, PHt, np.empty((3, 3)))
    S += R_vis
    S_inv = inv3(S)
    d2 = 0.0
    for i in range(3):
        d2 += r[i] * (S_inv[i, 0] * r[0] + S_inv[i, 1] * r[1] + S_inv[i, 2] * r[2])
    angle = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    return angle, (d2 if -np.inf < d2 < np.inf else np.inf)


def constant_rate_predict(x, t_s, q_rate):
    """Visual only: the state buffer `x` predicted to `t_s` (s) with the constant-rate model, rate
    random walk `q_rate` ((rad/s^2)^2/Hz): `R_wc <- R_wc Exp(omega_c dt)` (re-orthonormalised), `P <-
    F P F^T + Q` with `F = I` but `F[TH, TH] = M^T`, `F[TH, RATE] = dt I`, and `Q` the integrated
    random walk (`dt^3/3`, `dt^2/2`, `dt` blocks)."""
    s = x[0]
    R_wc, _, _, P, _, _, _, _, _, omega_c = state_views(x)
    dt = t_s - s.t_state_s
    M = exp3_into(omega_c[0] * dt, omega_c[1] * dt, omega_c[2] * dt, np.empty((3, 3)))
    R_wc[:, :] = orthonormal(matmul3_into(R_wc, M, np.empty((3, 3))))
    F = np.eye(12)
    for i in range(3):
        for j in range(3):
            F[i, j] = M[j, i]
        F[i, 9 + i] = dt
    P_new = matmul_into(matmul_into(F, P, np.empty((12, 12))), F.T, np.empty((12, 12)))
    for i in range(3):
        P_new[i, i] += q_rate * dt**3 / 3.0
        P_new[i, 9 + i] += q_rate * dt**2 / 2.0
        P_new[9 + i, i] += q_rate * dt**2 / 2.0
        P_new[9 + i, 9 + i] += q_rate * dt
    P[:, :] = P_new
    s.t_state_s = t_s


