"""The mistakes people make with IMU logs, found from the data itself: fixed where the evidence is
unambiguous (each fix is returned as a warning for the run summary), refused in one line otherwise.

    imu, fixes = check_imu_log(read_euroc_imu(path))

Checks, in this order (each sees the previous ones' fixes):
1. Timestamp unit. The median step of the ns column implies a sample rate; IMUs sample at
   `IMU_RATE_RANGE_HZ` (20 Hz .. 4 kHz). Read as ns, us, ms or s, exactly one unit can land in that
   range (the units are 1000x apart and the range is 200x wide): that unit is taken and the stamps
   converted to ns (FIX). No unit lands in it: refused, naming the column and the implied rate.
   Timestamps written as seconds with decimals (`EurocImu.t_from_float_s`) are taken as seconds when
   that gives an IMU rate (FIX), else refused: decimals in ms or us are not told apart by guessing.
2. A log that runs backwards. Rows stamped no later than an earlier row that repeat earlier rows
   exactly (a log concatenated with itself) are dropped (FIX). A jump back of more than
   `BACKWARD_JUMP_S` that is not such a repeat (two recordings in one file) is refused, naming the
   line. Small steps back are left to the backends' IMU stream, which reorders, drops and counts them.
3. Columns 2-4 vs 5-7. The accelerometer's norm sits near 1 g with little spread (`_accel_like`); when
   columns 2-4 look like that and columns 5-7 do not, the two triples were written in the wrong order
   and are swapped (FIX).
4. Accelerometer unit. A median |accel| within 25 % of 1 (not of 9.81), with little spread, means g:
   scaled by 9.80665 (FIX).
5. Gyro unit. With the device rotating, the direction of the (low-passed) accelerometer turns as
   `du/dt = u x omega`; the least-squares scale s between the two says rad/s (s ~ 1) or deg/s
   (s ~ pi/180, converted: FIX), when they correlate (`GYRO_EVIDENCE_CORRELATION`). Without enough
   rotation to tell, a gyro reading beyond `GYRO_RAD_S_LIMIT` (2000 deg/s in rad/s) is refused as
   likely deg/s; otherwise the log is taken as it is.
Logs shorter than `MIN_SAMPLES_FOR_STATISTICS` only get checks 1 and 2.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy.ndimage import uniform_filter1d

from uareme_fusion.errors import InputError

from ..formats.euroc import EurocImu

G_M_S2 = 9.80665
IMU_RATE_RANGE_HZ = (20.0, 4000.0)
"""Sample rates of real IMUs; the timestamp unit is the one that puts the log's rate in here."""
TIME_UNITS_NS = {"ns": 1, "us": 1_000, "ms": 1_000_000, "s": 1_000_000_000}
BACKWARD_JUMP_S = 1.0
"""A step back in time larger than this is two recordings in one file, not jitter."""
ACCEL_NORM_TOLERANCE = 0.25
"""The median |accel| is within this fraction of 1 g (in m/s^2 or in g) for an accelerometer."""
ACCEL_NORM_SPREAD = 0.3
"""An accelerometer's |a| has an interquartile range below this fraction of its median."""
GYRO_RAD_S_LIMIT = 34.9
"""2000 deg/s, the largest full scale of common MEMS gyros, in rad/s."""
GYRO_EVIDENCE_CORRELATION = 0.3
"""Correlation between du/dt and u x omega above which the gyro scale fit is trusted."""
GYRO_SCALE_TOLERANCE = 2.0
"""A fitted scale within this factor of 1 (or of pi/180) is rad/s (or deg/s)."""
MIN_SAMPLES_FOR_STATISTICS = 200
SMOOTHING_S = 0.05
"""Moving-average window for the gyro-scale fit, s (removes accelerometer noise before differencing)."""

COLUMNS_GYRO = "columns 2-4 (w_x, w_y, w_z)"
COLUMNS_ACCEL = "columns 5-7 (a_x, a_y, a_z)"


def check_imu_log(imu: EurocImu) -> tuple[EurocImu, list[str]]:
    """`imu` with the fixes of the module docstring applied, and one warning per fix;
    `InputError` naming the file, the column and the likely cause for what cannot be fixed."""
    fixes: list[str] = []
    imu = _timestamp_unit(imu, fixes)
    imu = _backward_time(imu, fixes)
    if len(imu.t_ns) >= MIN_SAMPLES_FOR_STATISTICS:
        imu = _column_order(imu, fixes)
        imu = _accel_unit(imu, fixes)
        imu = _gyro_unit(imu, fixes)
    return imu, fixes


def _with(imu: EurocImu, t_ns=None, gyro=None, accel=None, keep=None) -> EurocImu:
    t_ns = imu.t_ns if t_ns is None else t_ns
    gyro = imu.gyro_rad_s if gyro is None else gyro
    accel = imu.accel_m_s2 if accel is None else accel
    if keep is not None:
        t_ns, gyro, accel = t_ns[keep], gyro[keep], accel[keep]
    return dataclasses.replace(imu, t_ns=t_ns, t_s=t_ns * 1e-9, gyro_rad_s=gyro, accel_m_s2=accel)


def _median_step_ns(t_ns: np.ndarray) -> float | None:
    steps = np.diff(t_ns)
    steps = steps[steps > 0]
    return float(np.median(steps)) if len(steps) else None


def _float_seconds(imu: EurocImu, fixes: list[str]) -> EurocImu:
    step = _median_step_ns(imu.t_ns)
    lo, hi = IMU_RATE_RANGE_HZ
    if step is None or not lo <= 1e9 / step <= hi:
        implied = "no rate (fewer than two distinct stamps)" if step is None else f"{1e9 / step:.3g} Hz"
        raise InputError(f"{imu.path}: column 1 (timestamp [ns]): holds numbers with decimals; read as seconds they "
                         f"imply {implied}, not an IMU rate of {lo:g}-{hi:g} Hz: write integer nanoseconds")
    fixes.append(f"{imu.path}: column 1 holds timestamps in seconds with decimals, not integer ns (as seconds, "
                 f"{1e9 / step:.4g} Hz): converted to ns")
    return dataclasses.replace(imu, t_from_float_s=False)


def _timestamp_unit(imu: EurocImu, fixes: list[str]) -> EurocImu:
    if imu.t_from_float_s:
        return _float_seconds(imu, fixes)
    step = _median_step_ns(imu.t_ns)
    if step is None:
        return imu
    lo, hi = IMU_RATE_RANGE_HZ
    fits = [unit for unit, ns in TIME_UNITS_NS.items() if lo <= 1e9 / (step * ns) <= hi]
    if fits == ["ns"]:
        return imu
    rate_hz = 1e9 / step
    if len(fits) != 1:
        raise InputError(f"{imu.path}: column 1 (timestamp [ns]): the median step of {step:g} ns implies "
                         f"{rate_hz:.3g} Hz, and no time unit (ns, us, ms, s) gives an IMU rate of {lo:g}-{hi:g} Hz; "
                         "check the timestamp column")
    unit = fits[0]
    scale = TIME_UNITS_NS[unit]
    if np.abs(imu.t_ns).max() > np.iinfo(np.int64).max // scale:
        raise InputError(f"{imu.path}: column 1 (timestamp [ns]): the stamps look like {unit} but are too large "
                         "to convert to ns")
    fixes.append(f"{imu.path}: column 1 holds timestamps in {unit}, not ns (read as ns they imply "
                 f"{rate_hz:.3g} Hz; as {unit}, {rate_hz / scale:.4g} Hz): converted to ns")
    return _with(imu, t_ns=imu.t_ns * scale)


def _backward_time(imu: EurocImu, fixes: list[str]) -> EurocImu:
    t = imu.t_ns
    newest_before = np.maximum.accumulate(np.r_[np.iinfo(np.int64).min, t[:-1]])
    behind = t <= newest_before
    if not behind.any():
        return imu
    first = int(np.flatnonzero(behind)[0])
    rows = np.column_stack([t, imu.gyro_rad_s, imu.accel_m_s2])
    seen = {row.tobytes() for row in rows[~behind]}
    repeats = np.array([row.tobytes() in seen for row in rows[behind]])
    jump_s = (newest_before[first] - t[first]) * 1e-9
    if repeats.all():
        fixes.append(f"{imu.path}: {int(behind.sum())} rows from row {first + 1} repeat earlier rows exactly "
                     "(the log concatenated with itself?): dropped")
        return _with(imu, keep=~behind)
    if jump_s > BACKWARD_JUMP_S:
        raise InputError(f"{imu.path}: column 1 (timestamp): time goes back by {jump_s:.3g} s at data row {first + 1} "
                         f"and {int(behind.sum())} rows are earlier than rows before them: two recordings (or one "
                         "log concatenated with itself) in one file? Keep one of them")
    return imu


def _norm_stats(values: np.ndarray) -> tuple[float, float]:
    norm = np.linalg.norm(values, axis=1)
    median = float(np.median(norm))
    q25, q75 = np.percentile(norm, [25, 75])
    return median, float(q75 - q25) / median if median > 0 else np.inf


def _accel_like(values: np.ndarray) -> str | None:
    """'m/s^2' or 'g' when the triple's norm sits near 1 g with little spread, else None."""
    median, spread = _norm_stats(values)
    if spread > ACCEL_NORM_SPREAD:
        return None
    for unit, one_g in (("m/s^2", G_M_S2), ("g", 1.0)):
        if abs(median / one_g - 1.0) <= ACCEL_NORM_TOLERANCE:
            return unit
    return None


def _column_order(imu: EurocImu, fixes: list[str]) -> EurocImu:
    if _accel_like(imu.gyro_rad_s) and not _accel_like(imu.accel_m_s2):
        fixes.append(f"{imu.path}: {COLUMNS_GYRO} read like an accelerometer (|a| near 1 g) and {COLUMNS_ACCEL} do "
                     "not: accelerometer columns were written before the gyro's; swapped")
        return _with(imu, gyro=imu.accel_m_s2, accel=imu.gyro_rad_s)
    return imu


def _accel_unit(imu: EurocImu, fixes: list[str]) -> EurocImu:
    unit = _accel_like(imu.accel_m_s2)
    if unit == "g":
        fixes.append(f"{imu.path}: {COLUMNS_ACCEL}: median |accel| is {_norm_stats(imu.accel_m_s2)[0]:.3g}, so "
                     f"the accelerometer is in g, not m/s^2: multiplied by {G_M_S2}")
        return _with(imu, accel=imu.accel_m_s2 * G_M_S2)
    return imu


def gyro_scale_fit(t_s: np.ndarray, gyro: np.ndarray, accel: np.ndarray) -> tuple[float, float]:
    """(s, correlation) of the least-squares fit `du/dt = s (u x gyro)`, u the low-passed accelerometer
    direction: s is 1 for a gyro in rad/s and pi/180 for one in deg/s."""
    rate_hz = 1.0 / float(np.median(np.diff(t_s)))
    window = max(1, int(round(SMOOTHING_S * rate_hz)))
    accel_s = uniform_filter1d(accel, window, axis=0)
    gyro_s = uniform_filter1d(gyro, window, axis=0)
    u = accel_s / np.linalg.norm(accel_s, axis=1, keepdims=True)
    h = window
    du = (u[2 * h:] - u[:-2 * h]) / (t_s[2 * h:] - t_s[:-2 * h])[:, None]
    predicted = np.cross(u[h:-h], gyro_s[h:-h])
    # Only where the accelerometer measures mostly gravity (|a| within 10 % of its median).
    norm = np.linalg.norm(accel_s[h:-h], axis=1)
    calm = np.abs(norm / np.median(norm) - 1.0) < 0.1
    du, predicted = du[calm], predicted[calm]
    pp = float(np.sum(predicted * predicted))
    dd = float(np.sum(du * du))
    if pp <= 0 or dd <= 0:
        return float("nan"), 0.0
    dp = float(np.sum(du * predicted))
    return dp / pp, dp / np.sqrt(pp * dd)


def _gyro_unit(imu: EurocImu, fixes: list[str]) -> EurocImu:
    t_s = (imu.t_ns - imu.t_ns[0]) * 1e-9
    if np.any(np.diff(t_s) <= 0):
        order = np.argsort(t_s, kind="stable")
        t_s, gyro, accel = t_s[order], imu.gyro_rad_s[order], imu.accel_m_s2[order]
        keep = np.r_[True, np.diff(t_s) > 0]
        t_s, gyro, accel = t_s[keep], gyro[keep], accel[keep]
    else:
        gyro, accel = imu.gyro_rad_s, imu.accel_m_s2
    scale, correlation = gyro_scale_fit(t_s, gyro, accel)
    if correlation >= GYRO_EVIDENCE_CORRELATION:
        deg = np.pi / 180.0
        if abs(np.log(scale / deg)) <= np.log(GYRO_SCALE_TOLERANCE):
            fixes.append(f"{imu.path}: {COLUMNS_GYRO}: the gyro turns the accelerometer's direction {1 / scale:.3g} "
                         "times faster than it moves, as a gyro in deg/s does: converted to rad/s")
            return _with(imu, gyro=imu.gyro_rad_s * deg)
        return imu
    peak = float(np.abs(imu.gyro_rad_s).max())
    if peak > GYRO_RAD_S_LIMIT:
        raise InputError(f"{imu.path}: {COLUMNS_GYRO}: the gyro reaches {peak:.4g}, beyond any gyro's range in rad/s "
                         f"({GYRO_RAD_S_LIMIT} rad/s = 2000 deg/s): is it in deg/s? Convert it to rad/s")
    return imu
