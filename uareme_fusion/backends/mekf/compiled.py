"""`Mekf`'s calls into its kernels (`kernels.py`: IMU propagation, accelerometer, visual and other
updates, the constant-rate prediction) on the filter's state buffer (`state_buffer.py`), which they
update in place, and their result bits turned into status flags.

numba compiles a kernel (or loads it from its disk cache) at its first call. Should that fail, the
call changed nothing (compilation comes before execution): `_failed` warns once and puts the plain
Python functions in place (`kernels.use_python`), and the call runs again as Python; this filter and
every later one then run the same functions uncompiled.
"""

from __future__ import annotations

import numpy as np

from ... import jit
from . import kernels
from .state_buffer import python_state


def _state(filt) -> np.ndarray:
    """The filter's state buffer as the kernels take it: `x` itself when they are compiled, else its
    `np.recarray` view (`state_buffer.python_state`: fields by attribute, as numba reads them)."""
    return filt.x if kernels.compiled_now() else python_state(filt.x)


def _failed(exc: BaseException) -> None:
    """A compiled kernel failed to compile or load: one warning, the plain functions from now on.
    Re-raises when the kernels already ran as Python (a failure of the function itself)."""
    if not kernels.compiled_now():
        raise exc
    jit.disable(exc)
    kernels.use_python()


def _parameters(filt, defer: bool) -> np.ndarray:
    """The kernels' parameter record of `filt` (`parameters.py`), as plain Python reads it when the
    kernels run uncompiled."""
    params = filt.kernel_parameters
    if not kernels.compiled_now() and not params.python:
        params.as_python()
    return params.get(filt.manhattan_initialised, defer)


_COUNTERS = ("accel_updates", "accel_skipped", "accel_downweighted", "rest_updates", "nonfinite_updates",
             "visual_updates", "visual_rejected", "imu_gaps")
"""The update counts the kernels keep in the state record: fields named as the filter's counters."""
_FLOAT64 = np.dtype(np.float64)
_NO_RECORD = np.empty((0, 3, 3))  # record buffers when nothing is recorded (writable: the kernels' type)
_NO_ROWS = (np.zeros(0), np.zeros((0, 0)), np.zeros((0, 12)))  # no extra rows in a visual update


def harvest_kernel_counters(x: np.ndarray, counters: dict[str, int]) -> None:
    """Move the update counts the kernels keep in the state buffer `x` into `counters` (by name)."""
    for name in _COUNTERS:
        count = x[name][0]
        if count:
            counters[name] += int(count)
            x[name] = 0.0


def _record_buffers(filt, n: int) -> tuple[np.ndarray, np.ndarray]:
    if not filt.config.record_imu_estimates:
        return _NO_RECORD, _NO_RECORD
    return np.empty((n, 3, 3)), np.empty((n, 3, 3))


def _kept(filt, code: int, rows: np.ndarray, n: int, record_R: np.ndarray, record_P: np.ndarray) -> None:
    """After a kernel integrated the first `n` of `rows` (`types.IMU_COLUMNS`) with result `code`:
    the estimates it recorded kept and its result bits (`Status` bits) raised in `filt.flags`."""
    if record_R.shape[0] and n:
        filt.record_t.append(rows[:n, 0].copy())
        filt.record_R.append(record_R)
        filt.record_P.append(record_P)
    filt.flags |= code


def integrate(filt, rows: np.ndarray, extra_s: float, defer: bool) -> None:
    """Integrate a batch `rows` (n, 8) (`types.IMU_COLUMNS`, camera frame; n may be 0 with `extra_s`
    > 0) and then hold the last rate `extra_s` s longer, updating the filter's state buffer in place
    (`kernel_imu.integrate_batch`); `defer`: an update due at the end waits for the frame."""
    record_R, record_P = _record_buffers(filt, rows.shape[0])
    args = (_state(filt), rows, extra_s, _parameters(filt, defer), record_R, record_P)
    try:
        code = kernels.INTEGRATE(*args)
    except Exception as exc:  # noqa: BLE001 -- compilation failed: the plain function takes the batch
        _failed(exc)
        code = kernels.INTEGRATE(_state(filt), rows, extra_s, _parameters(filt, defer), record_R, record_P)
    _kept(filt, code, rows, rows.shape[0], record_R, record_P)


STAGE_ROWS = 512
"""Rows of a filter's stage (`Mekf._stage`, `stage`): a frame's samples up to 15 kHz at 30 fps."""


def stage(filt, t, gyro_c, accel_c) -> int:
    """A frame's batch from `process_imu` (`t` (n,) s, `gyro_c` (n, 3) rad/s, `accel_c` (n, 3) m/s^2,
    camera frame, shapes checked), nothing else held in the filter's reorder buffer: checked as
    `ImuStream.add` checks it and copied into the filter's stage (the caller may reuse its arrays),
    where it waits for the frame (`integrate_staged`), in one kernel call (`kernel_imu.stage_batch`).
    Returns n, or 0 (nothing staged) unless every sample is clean (finite, in order, later than the
    stream's watermark, below the gyro range) and the batch spans less than an accelerometer period
    and the reorder window (a batch that long may release samples)."""
    stream = filt._stream
    args = (filt._stage, t, gyro_c, accel_c, stream.watermark_s, stream.gyro_range_rad_s, filt.stage_span_s)
    try:
        return kernels.STAGE(*args)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        return kernels.STAGE(*args)


def integrate_staged(filt, n: int, t_frame_s: float) -> bool:
    """The `n` samples staged by `stage`, integrated to the frame at `t_frame_s` (s) in one kernel
    call (`kernel_imu.integrate_staged`); an update falling due at their end is left to the frame (its
    visual update stacks it). False, changing nothing, when a sample lies past the frame or an
    accelerometer update waits. A frame's path: the fewest Python steps around the one call."""
    record_R, record_P = _record_buffers(filt, n)
    try:
        code = kernels.INTEGRATE_STAGED(_state(filt), filt._stage, n, t_frame_s, _parameters(filt, True), record_R, record_P)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        code = kernels.INTEGRATE_STAGED(_state(filt), filt._stage, n, t_frame_s, _parameters(filt, True), record_R, record_P)
    if code < 0:
        return False
    _kept(filt, code, filt._stage, n, record_R, record_P)
    filt._stream.released_elsewhere(t_frame_s)
    return True


def integrate_segments(filt, t, gyro_c, accel_c, ends: np.ndarray):
    """An IMU-only stream (camera frame, clean: see `kernel_imu.integrate_segments`) integrated with an
    estimate after each segment `ends` (M,) (exclusive sample ends), in the filter's state buffer;
    returns `(R_wc (M, 3, 3), attitude cov (M, 3, 3), b_c (M, 3), flags (M,) Status bits)`. `filt.flags`
    is left to the caller: the per-estimate flags already say what happened."""
    m = ends.shape[0]
    record_R, record_P = _record_buffers(filt, t.size)
    out = np.empty((m, 3, 3)), np.empty((m, 3, 3)), np.empty((m, 3)), np.empty(m, np.int64)
    arrays = (np.ascontiguousarray(t, float), np.ascontiguousarray(gyro_c, float), np.ascontiguousarray(accel_c, float))
    try:
        kernels.SEGMENTS(_state(filt), *arrays, ends, _parameters(filt, False), record_R, record_P, *out)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        kernels.SEGMENTS(_state(filt), *arrays, ends, _parameters(filt, False), record_R, record_P, *out)
    if record_R.shape[0]:
        filt.record_t.append(np.array(t, float))
        filt.record_R.append(record_R)
        filt.record_P.append(record_P)
    return out  # the kernels' result bits are `Status` bits


def accel_update(filt) -> None:
    """The accelerometer (and at-rest) update of the period just completed, in the filter's state
    buffer (`kernel_update.accel_update_in_place`); no longer due."""
    try:
        code = kernels.ACCEL_UPDATE(_state(filt), _parameters(filt, False))
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        code = kernels.ACCEL_UPDATE(_state(filt), _parameters(filt, False))
    filt.flags |= code
    filt.accel.due = False


def update(filt, residual: np.ndarray, R: np.ndarray, H: np.ndarray) -> None:
    """One measurement `(residual (m,), R (m, m), H (m, 12))` built in Python, fused into the filter's
    state buffer (`kernel_update.update_in_place`); a non-finite result changes nothing and is flagged."""
    rows = (np.ascontiguousarray(residual, float), np.ascontiguousarray(R, float), np.ascontiguousarray(H, float))
    try:
        code = kernels.UPDATE(_state(filt), *rows, _parameters(filt, False))
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        code = kernels.UPDATE(_state(filt), *rows, _parameters(filt, False))
    filt.flags |= code


def _as_float(visual):
    R_cm, cov = visual.R_cm, visual.cov
    if not (type(R_cm) is type(cov) is np.ndarray and R_cm.dtype is cov.dtype is _FLOAT64):
        R_cm, cov = np.asarray(R_cm, float), np.asarray(cov, float)  # lists, other dtypes: one specialisation
    return R_cm, cov


def visual_update(filt, visual, share_scale: float = 1.0, rows=None) -> int:
    """A frame's visual rotation fused into the filter's state buffer in one call
    (`kernel_visual.visual_update`): with an IMU, a due accelerometer update stacked in; visual only,
    its covariance times `share_scale` and the gravity `rows` `(residual, R, H)` (or None) stacked in.
    Its result bits raised in `filt.flags` and the estimate after it in `filt.estimate_out`. Returns
    non-zero when the frame was gated out."""
    R_cm, cov = _as_float(visual)
    extra = _NO_ROWS if rows is None else tuple(np.ascontiguousarray(a, float) for a in rows)
    try:
        code = kernels.VISUAL_UPDATE(_state(filt), _parameters(filt, False), R_cm, cov, share_scale, *extra, filt.estimate_out)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        code = kernels.VISUAL_UPDATE(_state(filt), _parameters(filt, False), R_cm, cov, share_scale, *extra, filt.estimate_out)
    filt.flags |= code
    return code & kernels.kernel_visual.VISUAL_REJECTED


def visual_distance(filt, visual, P: np.ndarray, relabel: bool) -> tuple[float, float]:
    """`(angle rad, d2)` of a frame's rotation against the filter's prediction, under the error
    covariance `P` (`kernel_visual.visual_distance`)."""
    R_cm, cov = _as_float(visual)
    try:
        return kernels.VISUAL_DISTANCE(_state(filt), P, R_cm, cov, relabel)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        return kernels.VISUAL_DISTANCE(_state(filt), P, R_cm, cov, relabel)


def constant_rate_predict(filt, t_s: float, q_rate: float) -> None:
    """Visual only: the state predicted to `t_s` (s) with the constant-rate model
    (`kernel_visual.constant_rate_predict`)."""
    try:
        kernels.CONSTANT_RATE(_state(filt), t_s, q_rate)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        kernels.CONSTANT_RATE(_state(filt), t_s, q_rate)


def image_rotation_predict(filt, t_s: float, R_cp: np.ndarray, var_rad2: float, q_rate: float) -> None:
    """Visual only: the state predicted to `t_s` (s) by the image rotation `R_cp` (3, 3) of variance
    `var_rad2` (rad^2 per axis) (`kernel_image_rotation.image_rotation_predict`)."""
    R_cp = np.ascontiguousarray(R_cp, float)
    try:
        kernels.IMAGE_ROTATION(_state(filt), t_s, R_cp, var_rad2, q_rate)
    except Exception as exc:  # noqa: BLE001
        _failed(exc)
        kernels.IMAGE_ROTATION(_state(filt), t_s, R_cp, var_rad2, q_rate)
