"""How far `Mekf` trusts the camera's vertical, learned from its innovations (DESIGN.md "Never worse
than the best input"), and each source's share of the tilt information.

A visual rotation says where up is in the camera: `u_vis = R_cm_pred Exp(r) e_z`, m's z axis as this
frame sees it (`r` the visual residual, `R_cm_pred = R_wc^T R_wm`). A quiet accelerometer says it too:
`u_acc`, the direction of the current period's specific force carried in the camera frame by the gyro
(no sample while its last update was inflated: a turning or accelerating platform). Their difference
`e_k = u_vis - u_acc` (rad) has per tilt axis the variance `v_k = (R_vis_xx + R_vis_yy) / 2 + accel
variance + vertical_std^2` were the frame's error independent. A camera whose vertical errs the same
way frame after frame (learned normals on a real scene: EuRoC V1_01, a static drone, 8.8 deg off in
every frame while its covariance says 5) is otherwise fused as if each frame were new, and the vertical
pseudo-measurement, re-applied every frame to a constant R_wm, moves that error into the camera tilt.
So over the frames where the camera is still (`update_visual_trust`):

    m = EMA(e_k), v = EMA(v_k), n_eff the EMA's effective count
    b_j = mean of e_k over block j (`BLOCK_FRAMES` still frames), spread_b = EMA(|b_j|^2) - |EMA(b_j)|^2
    varying = BLOCK_FRAMES spread_b / 2                 per tilt axis and frame, as fused frames average it
    share = clip(varying / v, min_share, 1)             the independent share of the tilt covariance, fused
    persistent = max(|m|^2 / 2 - varying / n_eff, 0)    rad^2 per tilt axis

The share scales the frame's covariance on the two tilt axes only (`share_tilt_covariance`): it is
learned from the tilt, and says nothing of the yaw about up. And the vertical pseudo-measurement's
variance grows by the persistent variance beyond `PERSISTENT_MARGIN` times its own, times the horizon
(`vertical_variance`): R_wm's tilt then takes the camera's persistent error and the camera's tilt stays
the accelerometer's. The accelerometer's own trust is its inflation by |a| against gravity and by its
innovation against the gyro-propagated up (`measurements.gravity_model`).

Shares (reported per estimate): information per second on tilt of each source, the accelerometer's
`1 / (noise_density^2 * inflation)` and the camera's `1 / ((share v_vis + vertical variance) dt)`
(v_vis the visual tilt variance of one frame, dt the time between visual updates);
`share_visual = I_vis / (I_vis + I_acc)`. Visual only beside an accelerometer without gyro (`gravity_only.py`)
the same, with the gravity update's variance per update interval and, in place of the vertical variance, what
the Manhattan frame's lean may be (`GravityOnly.note_visual_information`).

Functions on the filter's state record `s` (`state_buffer.py`: scalar fields by name): the compiled
kernels call the very same ones.
"""

from __future__ import annotations

import math

import numpy as np


STILL_RATE_RAD_S = 0.15
"""Below this gyro rate (rad/s, about 9 deg/s: above an uncalibrated MEMS gyro's bias, EuRoC's 0.08)
the camera counts as still (`update_visual_trust`)."""
PERSISTENT_MARGIN = 4.0
"""A persistent error of the camera's vertical loosens the vertical pseudo-measurement only beyond this
many times its variance (twice its std: the running estimate's own scatter stays below it on the
simulated bus, whose vertical is right)."""
MIN_SAMPLES = 3
"""Frames compared with the accelerometer before the trust says anything (the vertical pseudo-measurement
waits for them), and blocks (`BLOCK_FRAMES`) before the share leaves 1."""
BLOCK_FRAMES = 10
"""Still frames per block of the share (`update_visual_trust`): longer than the correlation of a
network's frame errors on a real static scene (EuRoC V1_01: 0.57 one frame apart, 0.19 ten apart),
so that the blocks' means are nearly independent."""


def visual_vertical_innovation(R_wc, R_wm, r, R_vis, accel_sum, accel_time_s, accel_var_rate, quiet_var_rate,
                               vertical_var):
    """`(e (3,) rad, v rad^2)`: this frame's up in the camera (m's z through the visual residual `r`
    (3,), right perturbation of the predicted `R_cm = R_wc^T R_wm`) minus the accelerometer's (the
    direction of the current period's specific force `accel_sum` (3,), carried in the camera frame by the
    gyro, over `accel_time_s` s), and the variance per tilt axis of that difference were the frame's error
    independent (module docstring): the visual covariance `R_vis` (3, 3, m frame) on m's x and y axes,
    the accelerometer's `accel_var_rate / accel_time_s` (its noise density squared times its inflation, the
    last update's) and `vertical_var` rad^2. `v` is 0 (no sample) without accelerometer samples or
    when the accelerometer is not quiet: its last update inflated past `quiet_var_rate` (by |a| off
    gravity or by its disagreement with the gyro-propagated up: a turning vehicle)."""
    e = np.zeros(3)
    norm = math.sqrt(accel_sum[0] ** 2 + accel_sum[1] ** 2 + accel_sum[2] ** 2)
    if not (accel_time_s > 0 and norm > 0 and 0 < accel_var_rate <= quiet_var_rate):
        return e, 0.0
    # Exp(r) e_z by Rodrigues: e_z + a (r x e_z) + b r x (r x e_z) (the helpers of `matrix3` are not
    # called here: the kernels compile this function alone)
    theta2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    if theta2 < 1e-8:
        a, b = 1.0 - theta2 / 6.0, 0.5 - theta2 / 24.0
    else:
        theta = math.sqrt(theta2)
        a, b = math.sin(theta) / theta, (1.0 - math.cos(theta)) / theta2
    z0, z1, z2 = a * r[1] + b * r[0] * r[2], -a * r[0] + b * r[1] * r[2], 1.0 + b * (r[2] * r[2] - theta2)
    for i in range(3):  # (R_wc^T R_wm) Exp(r) e_z - acc / |acc|
        acc = 0.0
        for j in range(3):
            R_pred_ij = R_wc[0, i] * R_wm[0, j] + R_wc[1, i] * R_wm[1, j] + R_wc[2, i] * R_wm[2, j]
            acc += R_pred_ij * (z0 if j == 0 else z1 if j == 1 else z2)
        e[i] = acc - accel_sum[i] / norm
    v = 0.5 * (R_vis[0, 0] + R_vis[1, 1]) + accel_var_rate / accel_time_s + vertical_var
    return e, v


def update_visual_trust(s, e, v, frames, min_share, rate_rad_s2):
    """Take one frame's vertical innovation `e` (3,) and variance `v` (`visual_vertical_innovation`)
    into the running moments in `s`; return `(share, persistent_var)`: the independent share of the
    frame's visual covariance and the variance per tilt axis of the persistent part (half the squared
    running mean less what the varying errors leave in it, >= 0), rad^2. `frames` is the averaging
    horizon (0: off: (1, 0)). A non-finite frame is left out.

    The share is the variance of the means of `BLOCK_FRAMES` consecutive still frames (averaged over
    `frames` blocks), times `BLOCK_FRAMES`, against `2 v` (clipped to [`min_share`, 1]; 1 until
    `MIN_SAMPLES` blocks are seen): the low-frequency power of the varying error, which is what a
    filter fusing every frame averages down. A frame-to-frame spread misses errors correlated over a
    few frames (real EuRoC V1_01, learned normals: the camera's up wanders by about 0.6 deg per axis,
    correlated 0.56 from one frame to the next and 0.19 ten frames apart; the frame spread had the
    share at its floor from the fourth frame on: `eval` NEES 25.9 -> 7.1 with the blocks, tilt 1.39 ->
    1.20 deg). The share is below 1 only while the camera is still (`rate_rad_s2`, its squared
    bias-corrected gyro rate, below `STILL_RATE_RAD_S`^2): then the innovations' spread is the
    camera's own noise, whereas in motion the view, and with it the persistent error, changes from
    frame to frame (a simulated handheld walk: tilt p95 0.56 -> 2.26 deg with the share applied in
    motion); a block is cut short by motion."""
    if not frames > 0:
        return 1.0, 0.0
    s.trust_frames += 1.0
    if not (abs(e[0]) + abs(e[1]) + abs(e[2]) < np.inf and 0.0 < v < np.inf):  # also: no sample
        return s.visual_scale, s.trust_persistent
    if not rate_rad_s2 < STILL_RATE_RAD_S**2:  # in motion: the frame says nothing of the camera's trust
        s.block_n = 0.0
        for i in range(3):
            s.block_sum[i] = 0.0
        return 1.0, s.trust_persistent
    a = min(1.0 / frames, 1.0)
    w = (1.0 - a) * s.trust_weight + a
    s.trust_weight = w
    e2 = 0.0
    for i in range(3):
        s.trust_mean[i] = (1.0 - a) * s.trust_mean[i] + a * e[i]
        s.block_sum[i] += e[i]
        e2 += e[i] * e[i]
    s.trust_square = (1.0 - a) * s.trust_square + a * e2
    s.trust_var = (1.0 - a) * s.trust_var + a * v
    s.trust_count += 1.0
    s.block_n += 1.0
    if s.block_n >= BLOCK_FRAMES:  # a block of still frames closed: its mean into the block moments
        a_b = min(1.0 / frames, 1.0)
        w_b = (1.0 - a_b) * s.block_weight + a_b
        s.block_weight = w_b
        b2 = 0.0
        for i in range(3):
            b = s.block_sum[i] / BLOCK_FRAMES
            s.block_mean[i] = (1.0 - a_b) * s.block_mean[i] + a_b * b
            b2 += b * b
            s.block_sum[i] = 0.0
        s.block_square = (1.0 - a_b) * s.block_square + a_b * b2
        s.block_n = 0.0
        s.block_count += 1.0
    m0, m1, m2 = s.trust_mean[0] / w, s.trust_mean[1] / w, s.trust_mean[2] / w
    mean2 = m0 * m0 + m1 * m1 + m2 * m2
    v_mean = s.trust_var / w
    n_eff = min(s.trust_count, (2.0 - a) / a)
    # The varying error's variance per tilt axis and frame, as fused frames average it: from the blocks
    # once there are enough of them (the camera fully trusted until then), else from the frames.
    share = 1.0
    varying = 0.0
    if s.block_count >= MIN_SAMPLES:
        w_b = s.block_weight
        a_b = min(1.0 / frames, 1.0)
        n_b = min(s.block_count, (2.0 - a_b) / a_b)
        c0, c1, c2 = s.block_mean[0] / w_b, s.block_mean[1] / w_b, s.block_mean[2] / w_b
        spread_b = max(s.block_square / w_b - (c0 * c0 + c1 * c1 + c2 * c2), 0.0) * n_b / (n_b - 1.0)
        varying = 0.5 * BLOCK_FRAMES * spread_b
        share = min(max(varying / v_mean, min_share), 1.0)
    elif s.trust_count >= MIN_SAMPLES:
        varying = 0.5 * max(s.trust_square / w - mean2, 0.0) * n_eff / (n_eff - 1.0)
    persistent = max(0.5 * mean2 - min(varying, v_mean) / n_eff, 0.0)
    s.visual_scale = share
    s.trust_persistent = persistent
    return share, persistent


def share_tilt_covariance(R_vis, share, R_wm):
    """Scale the visual covariance `R_vis` (3, 3, rad^2, m frame; in place) by the independent `share`
    on the camera's tilt only: `S R_vis S^T` with `S = sqrt(share) (I - u u^T) + u u^T`, `u = R_wm^T e_z`
    world up in the m frame. The share is learned from the tilt (the camera's up against the
    accelerometer's, `update_visual_trust`): it says nothing of the yaw about up, whose frame errors
    wander together on a real scene (EuRoC V1_01 micro, learned normals, the share on all three axes:
    the gyro bias learned from the yaw's wander, mekf yaw rms 0.95 deg against single's 0.37, ARE
    0.89 against 0.65; on the tilt only 0.63 deg)."""
    if share == 1.0:
        return
    g = math.sqrt(share)
    u = R_wm[2]
    S = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            S[i, j] = (1.0 - g) * u[i] * u[j] + (g if i == j else 0.0)
    T = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            T[i, j] = S[i, 0] * R_vis[0, j] + S[i, 1] * R_vis[1, j] + S[i, 2] * R_vis[2, j]
    for i in range(3):
        for j in range(3):
            R_vis[i, j] = T[i, 0] * S[j, 0] + T[i, 1] * S[j, 1] + T[i, 2] * S[j, 2]


def note_visual_information(s, R_vis, share, vertical_var, dt_s):
    """Keep the camera's information per second on the camera's tilt for the shares: one frame per
    `dt_s` s, its tilt variance from `R_vis` (3, 3) times `share` in series with the vertical
    pseudo-measurement's `vertical_var` (rad^2; the camera's up reaches the world only through it)."""
    v = 0.5 * (R_vis[0, 0] + R_vis[1, 1]) * share + vertical_var
    s.visual_info_rate = 1.0 / (v * dt_s) if 0 < v < np.inf and dt_s > 0 else 0.0


def note_accel_information(s, var_rad2, T_s):
    """Keep the accelerometer's tilt information per second (one update of variance `var_rad2` per `T_s`
    s), and its variance rate `var_rad2 * T_s`."""
    s.accel_var_rate = var_rad2 * T_s
    s.accel_info_rate = 1.0 / (var_rad2 * T_s) if var_rad2 > 0 and T_s > 0 else 0.0


def tilt_shares(i_a, i_v):
    """`(share_accel, share_visual)` of the tilt information per second `i_a` of the accelerometer and
    `i_v` of the camera (`s.accel_info_rate`, `s.visual_info_rate`; module docstring); NaN for a
    source not seen yet."""
    total = i_a + i_v
    if not total > 0 or not math.isfinite(total):
        return math.nan, math.nan
    return i_a / total, i_v / total


def vertical_variance(s, vertical_var, frames):
    """The vertical pseudo-measurement's variance, rad^2, from the trust kept in `s`: the configured
    `vertical_var`, plus, for a persistent error of the camera's vertical beyond `PERSISTENT_MARGIN`
    times it, that excess times the `frames` over which the same error is applied again (a prior
    re-applied each frame counts once per horizon); continuous in the persistent variance. `inf`
    (skip it) for the first `MIN_SAMPLES` frames unless compared with a quiet accelerometer. With the trust
    off (`frames` 0), `vertical_var`."""
    if not frames > 0:
        return vertical_var
    if s.trust_frames < MIN_SAMPLES and s.trust_count < MIN_SAMPLES:
        return math.inf
    return vertical_var + max(s.trust_persistent - PERSISTENT_MARGIN * vertical_var, 0.0) * frames


def squared_rate(gyro_c, b_c):
    """`|gyro_c - b_c|^2` (rad/s)^2: the squared bias-corrected rate of the last gyro reading (camera frame)."""
    return (gyro_c[0] - b_c[0]) ** 2 + (gyro_c[1] - b_c[1]) ** 2 + (gyro_c[2] - b_c[2]) ** 2
