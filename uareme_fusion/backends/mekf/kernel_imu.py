"""The EKF's IMU propagation: gyro integration, covariance prediction and the accelerometer period,
over released batches of samples, gaps and saturated samples included (numba-compiled by `kernels`,
plain Python without numba).

Gyro model (docs/design.md "Backends"): `R_wc <- R_wc C_N` with `C_N` the product of `Exp(rate_k dt_k)`
over a chunk of samples; per sample `dtheta_{k+1} = M_k^T dtheta_k - dt_k db`, composed:
`dtheta_N = C_N^T dtheta_0 - A_bias db` with `A_bias = C_N^T sum_k dt_k C_k`. Sample k covers
`(t_{k-1}, t_k]` with the mean of its rate and the previous one (trapezoid) or its own (interval).
A step longer than `gap_limit_s` (an IMU gap), a saturated sample, the first step after frames bridged
a gap, and an extrapolation of a stale stream are unknown rotations: they are not integrated, and the
attitude variance grows by `unknown_rate_std_rad_s` over them instead.

The drivers (`integrate_batch`, `integrate_staged`, `integrate_segments`) take the filter's state
buffer `x` (`state_buffer.py`) and update it in place.
"""

from __future__ import annotations

import numpy as np

from . import status_bits
from .accel import chunk_bounds
from .kernel_update import accel_rows, state_views
from .matrix3 import exp3_into, matmul3_into
from .state import orthonormal
from ..imu_stream import rows_if_clean

DOWNWEIGHTED, NONFINITE = status_bits.ACCEL_DOWNWEIGHTED, status_bits.UPDATE_NONFINITE
IMU_GAP, GYRO_SATURATED = status_bits.IMU_GAP, status_bits.GYRO_SATURATED


def chunk_steps(s, t, gyro, saturated, extra_s, last_gyro, gap_limit_s, unknown_std_rad_s, g, dt):
    """The steps of a chunk of n samples `t` (n,), `gyro` (n, 3), `saturated` (n,) (nonzero: at the
    gyro's range), continuing from the state time `s.t_state_s` and extrapolated by `extra_s` (m = n
    + 1 steps then, else n): the readings into `g` (m + 1, 3) (the previous one `last_gyro` first,
    each saturated one replaced by the last reading before it, the last held over the extrapolation)
    and the step lengths into `dt` (m,), zero over gaps. Updates the gap bookkeeping in `s`
    (`s.imu_t_s`, `s.in_gap`, `s.imu_gaps`, the low-pass lost at a gap). Returns `(T_elapsed s, unknown
    variance rad^2, result bits)`."""
    n, m = t.shape[0], dt.shape[0]
    resumed = n > 0 and s.in_gap > 0
    any_saturated = False
    T_elapsed, longest = 0.0, 0.0
    g[0] = last_gyro
    t_prev = s.t_state_s
    for k in range(n):  # one pass: readings, steps, their sum and the longest
        if saturated[k] > 0:
            any_saturated = True
            g[k + 1] = g[k]  # the last reading below the range
        else:
            g[k + 1, 0], g[k + 1, 1], g[k + 1, 2] = gyro[k, 0], gyro[k, 1], gyro[k, 2]
        h = t[k] - t_prev
        t_prev = t[k]
        dt[k] = h
        T_elapsed += h
        if h > longest:
            longest = h
    if n:
        s.imu_t_s = t[n - 1]
        s.in_gap = 0.0
    stale = False
    if m > n:
        g[m] = g[n]
        dt[m - 1] = extra_s
        T_elapsed += extra_s
        longest = max(longest, extra_s)
        stale = abs(s.imu_t_s) < np.inf and s.t_state_s + extra_s - s.imu_t_s > gap_limit_s
    if resumed:  # the reading before the gap is stale: the step to the first new one is unknown
        g[0] = g[1]
    if not (stale or resumed or longest > gap_limit_s or any_saturated):
        return T_elapsed, 0.0, 0
    unknown_var, gaps, any_gap = 0.0, 0, False
    for k in range(m):
        gap = dt[k] > gap_limit_s or (stale and k == m - 1)
        if gap or (k < n and saturated[k] > 0) or (k == 0 and resumed):
            unknown_var += (unknown_std_rad_s * dt[k]) ** 2
        if gap:
            any_gap = True
            gaps += 1 if k < n else 0
            dt[k] = 0.0
    code = GYRO_SATURATED if any_saturated else 0
    if any_gap:
        code |= IMU_GAP
        s.imu_gaps += gaps + (1 if stale and not s.in_gap > 0 else 0)
        if stale:
            s.in_gap = 1.0
    s.lp_valid = 0.0  # the frame carried along by the gyro is lost
    return T_elapsed, unknown_var, code


def propagate_chunk(b_c, P, g, dt, trapezoid, q_gyro, q_bias, q_rate, T_s, unknown_var, C_out):
    """Integrate the chunk's steps (`chunk_steps`: readings `g` (m + 1, 3), steps `dt` (m,)) with the
    bias `b_c`: writes the cumulative rotations C_k of its first n = `C_out.shape[0]` samples into
    `C_out` and returns `(C_N, A_bias, P_predicted)`, P predicted with the closed-form transition and
    the process noise of `T_s` s (white gyro noise, bias random walk, rate-proportional error and the
    `unknown_var` rad^2 of unknown rotations)."""
    m, n = dt.shape[0], C_out.shape[0]
    C = np.eye(3)
    C_prev = np.empty((3, 3))
    M = np.empty((3, 3))
    S = np.zeros((3, 3))  # sum_k dt_k C_k
    rate_var = 0.0
    b0, b1, b2 = b_c[0], b_c[1], b_c[2]
    for k in range(m):  # scalar code: no array is allocated per sample
        if trapezoid:
            r0 = 0.5 * (g[k + 1, 0] + g[k, 0]) - b0
            r1 = 0.5 * (g[k + 1, 1] + g[k, 1]) - b1
            r2 = 0.5 * (g[k + 1, 2] + g[k, 2]) - b2
        else:
            r0, r1, r2 = g[k + 1, 0] - b0, g[k + 1, 1] - b1, g[k + 1, 2] - b2
        h = dt[k]
        C_prev[:, :] = C
        matmul3_into(C_prev, exp3_into(r0 * h, r1 * h, r2 * h, M), C)
        if k < n:
            C_out[k] = C
        for i in range(3):
            for j in range(3):
                S[i, j] += h * C[i, j]
        rate_var += (r0 * r0 + r1 * r1 + r2 * r2) * h
    A_bias = np.empty((3, 3))  # C^T S, written out (a BLAS call costs more than these 27 products)
    for i in range(3):
        for j in range(3):
            A_bias[i, j] = C[0, i] * S[0, j] + C[1, i] * S[1, j] + C[2, i] * S[2, j]
    P_pred = P.copy()
    gyro_predict_in_place(P_pred, C, A_bias)
    T = T_s
    q_th = q_gyro * T + q_bias * T**3 / 3.0 + unknown_var + q_rate * rate_var
    for i in range(3):
        P_pred[i, i] += q_th
        P_pred[i, 3 + i] += -q_bias * T**2 / 2.0
        P_pred[3 + i, i] += -q_bias * T**2 / 2.0
        P_pred[3 + i, 3 + i] += q_bias * T
    return C, A_bias, P_pred


def gyro_predict_in_place(P, C, A_bias):
    """`P <- F P F^T` for the gyro transition `F` (identity but `F[TH, TH] = C^T`, `F[TH, BG] =
    -A_bias`), in place: only the attitude rows and columns change."""
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


def scratch(n):
    """Work arrays for `integrate_chunks` of up to n samples: rotations (n, 3, 3), readings (n + 2, 3),
    steps (n + 1,)."""
    return np.empty((n, 3, 3)), np.empty((n + 2, 3)), np.empty(n + 1)


def integrate_chunks(x, t, gyro, accel, saturated, bounds, extra_s, p, record_R, record_P, C_buf, g_buf, dt_buf):
    """Integrate a batch chunk by chunk (`bounds`, `accel.chunk_bounds`), the last chunk extrapolated
    by `extra_s`, with the accelerometer updates falling due (one due at the end left to a frame with
    `p.defer`); see `integrate_batch`. `C_buf`, `g_buf`, `dt_buf`: work arrays (`scratch`). Returns the
    `DOWNWEIGHTED` | `IMU_GAP` | `GYRO_SATURATED` bits."""
    s = x[0]
    R_wc, R_wm, b_c, P, last_gyro, accel_sum, lp, lp_J, rest_sums, _ = state_views(x)
    n_chunks = bounds.shape[0] - 1
    code = 0
    for c in range(n_chunks):
        a, b = bounds[c], bounds[c + 1]
        n = b - a
        last = c == n_chunks - 1
        extra = extra_s if last and extra_s > 0.0 else 0.0
        m = n + 1 if extra > 0.0 else n
        g, dt, C_k = g_buf[:m + 1], dt_buf[:m], C_buf[a:b]
        T_elapsed, unknown_var, bits = chunk_steps(s, t[a:b], gyro[a:b], saturated[a:b], extra, last_gyro,
                                                   p.gap_limit_s, p.unknown_rate_std_rad_s, g, dt)
        code |= bits
        T = T_elapsed
        if unknown_var != 0.0:
            T = 0.0
            for k in range(m):
                T += dt[k]
        C_N, A_bias, P_pred = propagate_chunk(b_c, P, g, dt, p.trapezoid > 0, p.q_gyro, p.q_bias, p.q_rate, T,
                                              unknown_var, C_k)
        if p.manhattan_initialised > 0 and (p.manhattan_yaw_rw > 0 or p.manhattan_tilt_rw > 0) and T_elapsed > 0:
            u = R_wm[2].copy()
            uu = np.outer(u, u)
            P_pred[6:9, 6:9] += T_elapsed * (p.manhattan_yaw_rw ** 2 * uu + p.manhattan_tilt_rw ** 2 * (np.eye(3) - uu))
        P[:, :] = P_pred
        if p.record > 0:
            for k in range(n):
                matmul3_into(R_wc, C_k[k], record_R[a + k])
                record_P[a + k] = P_pred[0:3, 0:3]
        R_wc[:, :] = matmul3_into(R_wc, C_N, np.empty((3, 3)))
        s.products += 1
        if s.products >= p.orthonormalise_every:
            R_wc[:, :] = orthonormal(R_wc)
            R_wm[:, :] = orthonormal(R_wm)
            s.products = 0
        last_gyro[:] = g[n]
        # Specific force, time-weighted (not over gaps), in the chunk's end frame.
        acc = accel_sum.copy()
        covered = 0.0
        for k in range(n):
            f0, f1, f2 = accel[a + k, 0], accel[a + k, 1], accel[a + k, 2]
            h = dt[k]
            covered += h
            for i in range(3):
                acc[i] += h * (C_k[k, i, 0] * f0 + C_k[k, i, 1] * f1 + C_k[k, i, 2] * f2)
        for i in range(3):
            accel_sum[i] = C_N[0, i] * acc[0] + C_N[1, i] * acc[1] + C_N[2, i] * acc[2]
        if n:
            s.accel_time_s += T_elapsed - extra if unknown_var == 0.0 else covered
        s.accel_elapsed_s += T_elapsed
        if s.lp_valid > 0:
            carry_lowpass_in_place(lp, lp_J, C_N, A_bias)
        if p.rest_gyro_max_rad_s > 0:
            for k in range(n):
                g0, g1, g2 = g[k + 1, 0], g[k + 1, 1], g[k + 1, 2]
                f0, f1, f2 = accel[a + k, 0], accel[a + k, 1], accel[a + k, 2]
                rest_sums[0] += g0
                rest_sums[1] += g1
                rest_sums[2] += g2
                rest_sums[3] += g0 * g0 + g1 * g1 + g2 * g2
                rest_sums[4] += f0
                rest_sums[5] += f1
                rest_sums[6] += f2
                rest_sums[7] += f0 * f0 + f1 * f1 + f2 * f2
            s.rest_n += n
        s.t_state_s = (t[b - 1] if n else s.t_state_s) + extra
        if not last or s.accel_elapsed_s >= p.due_s:
            if last and p.defer > 0:
                s.accel_due = 1
            elif accel_rows(x, p, 1.0)[1]:  # updated, down-weighted
                code |= DOWNWEIGHTED
    return code


def carry_lowpass_in_place(lp, lp_J, C_N, A_bias):
    """Carry the low-pass stages through a chunk turning by `C_N` whose bias transition is `A_bias`:
    with the true bias the chunk turns by `C_N Exp(-A_bias db)`, so a carried vector v reads
    `C_N^T v - skew(C_N^T v) A_bias db`: `lp[s] <- C_N^T lp[s]`, `lp_J[s] <- C_N^T lp_J[s] - skew(lp[s]) A_bias`."""
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


def integrate_batch(x, rows, extra_s, params, record_R, record_P):
    """Integrate a released batch `rows` (n, 8) (`types.IMU_COLUMNS`: t s, gyro rad/s, accel m/s^2,
    camera frame, saturated flag) into the state buffer `x`, in place: chunk by chunk
    (`accel.chunk_bounds`), with the accelerometer updates that fall due, except one due at the end of
    a batch propagated to a frame (`p.defer`): that one is left to the frame (`s.accel_due` = 1).
    The last chunk is extrapolated by `extra_s` s (n may be 0 then). With `p.record`, `record_R` (n, 3,
    3) receives R_wc after each sample and `record_P` the attitude covariance predicted to the end of
    its chunk. Returns the `Status` bits of what happened (`DOWNWEIGHTED`, `NONFINITE`, `IMU_GAP`,
    `GYRO_SATURATED`)."""
    p = params[0]
    s = x[0]
    t = rows[:, 0]
    nonfinite_before = s.nonfinite_updates
    bounds = chunk_bounds(t, s.t_state_s, s.accel_elapsed_s, p.period_s)
    C_buf, g_buf, dt_buf = scratch(t.shape[0])
    code = integrate_chunks(x, t, rows[:, 1:4], rows[:, 4:7], rows[:, 7], bounds, extra_s, p, record_R, record_P,
                            C_buf, g_buf, dt_buf)
    return code | (NONFINITE if s.nonfinite_updates > nonfinite_before else 0)


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


def integrate_staged(x, stage, n, t_frame_s, params, record_R, record_P):
    """`integrate_batch` for the `n` rows of `stage` (`stage_batch`), propagated to a frame at
    `t_frame_s` s: -2, changing nothing, unless they are all at or before the frame and no
    accelerometer update waits (`s.accel_due`)."""
    rows = stage[:n]
    t_last = rows[n - 1, 0]
    if not t_last <= t_frame_s or x[0].accel_due > 0:
        return -2
    return integrate_batch(x, rows, t_frame_s - t_last, params, record_R, record_P)


def integrate_segments(x, t, gyro, accel, ends, params, record_R, record_P, out_R, out_cov, out_b, out_flags):
    """An IMU-only stream (camera frame, no saturated samples) in segments, segment i being samples
    ends[i-1]:ends[i] (from 0): each is integrated into the state buffer `x` as `integrate_batch`
    integrates one released batch (chunks cut by `accel.chunk_bounds`, updates falling due applied,
    none deferred), and the estimate after it written out: `out_R[i]` R_wc, `out_cov[i]` the attitude
    covariance (symmetrised), `out_b[i]` b_c, `out_flags[i]` the `Status` bits of what happened."""
    p = params[0]
    s = x[0]
    R_wc, _, b_c, P = state_views(x)[:4]
    # Strided views ('A' layout in numba, as a batch's columns in `integrate_batch`): `integrate_chunks`
    # and what it calls compile once for both drivers.
    t, gyro, accel = t[::1], gyro[::1], accel[::1]
    not_saturated = np.zeros(t.shape[0])[::1]
    C_buf, g_buf, dt_buf = scratch(t.shape[0])
    start = 0
    for i in range(ends.shape[0]):
        end = ends[i]
        seg_t = t[start:end]
        bounds = chunk_bounds(seg_t, s.t_state_s, s.accel_elapsed_s, p.period_s)
        nonfinite_before = s.nonfinite_updates
        bits = integrate_chunks(x, seg_t, gyro[start:end], accel[start:end], not_saturated[start:end], bounds, 0.0,
                                p, record_R[start:end], record_P[start:end], C_buf, g_buf, dt_buf)
        out_R[i] = R_wc
        out_cov[i] = 0.5 * (P[0:3, 0:3] + P[0:3, 0:3].T)
        out_b[i] = b_c
        out_flags[i] = bits | (NONFINITE if s.nonfinite_updates > nonfinite_before else 0)
        start = end
    return 0

