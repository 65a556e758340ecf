"""Timing between an IMU and its optical reference, measured from the data alone (no filter).

BROAD compares each IMU sample with the optical sample of the same index. Integrated gyro rotations
match the optical rotations best with the reference read about 0.65 samples (2.3 ms at 286 Hz)
earlier on every trial of `broad_subset`: the IMU's samples are late by that much. Every IMU-only
filter inherits this delay, identically, so it does not favour one filter; but at fast rotation it
is much of the error (vqf on trial 07: 1.02 deg with the index pairing, 0.54 deg against the
re-timed reference), which pushes every ratio between filters towards 1. `bench mekf` prints the
ratios both ways: the published pairing (the goal) and against the re-timed reference.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

WINDOW_SAMPLES = 4
"""Rotation increments are compared over this many samples (short: the increments stay small-angle)."""


def _slerp_of_valid(t_s: np.ndarray, R_ref: np.ndarray) -> tuple[Slerp, np.ndarray]:
    """Slerp over the finite rows of `R_ref` (N, 3, 3) at `t_s` (N,) s, and the mask of those rows."""
    valid = np.all(np.isfinite(R_ref), axis=(1, 2))
    return Slerp(t_s[valid], Rotation.from_matrix(R_ref[valid])), valid


def _increments_mismatch(t_s, gyro_rad_s, slerp, valid, keep, shift_s, dt_s) -> float:
    """Mean squared difference (rad^2) between the gyro's rotation increments over `WINDOW_SAMPLES`
    and the reference's, read `shift_s` later."""
    L = WINDOW_SAMPLES
    t_read = np.clip(t_s + shift_s, slerp.times[0], slerp.times[-1])
    R = slerp(t_read)
    inc_ref = (R[:-L].inv() * R[L:]).as_rotvec()
    # Interval samples: reading k + 1 is the mean rate over (t_k, t_k+1].
    summed = np.cumsum(np.vstack([np.zeros(3), gyro_rad_s]), axis=0) * dt_s
    inc_gyro = summed[L + 1:] - summed[1:-L]
    use = valid[:-L] & valid[L:] & keep[:-L]
    if not use.any():
        return np.inf  # nothing moved with a reference on both ends: this shift says nothing
    return float(np.mean(np.sum((inc_ref[use] - inc_gyro[use]) ** 2, axis=1)))


def imu_delay_s(t_s: np.ndarray, gyro_rad_s: np.ndarray, R_ref: np.ndarray, keep: np.ndarray,
                max_samples: float = 2.0) -> float:
    """How late the IMU's samples are against the optical reference, s: the reference `R_ref` (N, 3, 3,
    IMU to world; NaN rows where missing) at `t - delay` matches the gyro `gyro_rad_s` (N, 3) rad/s
    (interval samples) at `t`. Searched within `max_samples` sample steps on the samples `keep` (N,)
    (the moving ones), to a twentieth of a sample."""
    t_s = np.asarray(t_s, float)
    slerp, valid = _slerp_of_valid(t_s, R_ref)
    dt_s = float(np.median(np.diff(t_s)))
    keep = np.asarray(keep, bool)
    best = 0.0
    for step, half_width in ((0.25, max_samples), (0.05, 0.25)):  # coarse, then fine around the coarse best
        shifts = best + np.arange(-half_width, half_width + 1e-9, step) * dt_s
        cost = [_increments_mismatch(t_s, gyro_rad_s, slerp, valid, keep, s, dt_s) for s in shifts]
        if not np.isfinite(cost).any():
            return 0.0  # no moving samples to time against: no delay measured
        best = float(shifts[int(np.argmin(cost))])
    return -best


def retimed_reference(t_s: np.ndarray, R_ref: np.ndarray, delay_s: float) -> np.ndarray:
    """`R_ref` (N, 3, 3) read `delay_s` earlier (slerp between valid samples), NaN where it was NaN."""
    t_s = np.asarray(t_s, float)
    slerp, valid = _slerp_of_valid(t_s, R_ref)
    R = slerp(np.clip(t_s - delay_s, t_s[valid][0], t_s[valid][-1])).as_matrix()
    R[~valid] = np.nan
    return R
