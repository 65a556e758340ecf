"""`Mekf`'s compiled path: calls the kernels (IMU propagation, accelerometer and visual updates) on the
filter's state buffer (`state_buffer.py`), which they update in place, and turns their result bits
into status flags.

Used for released batches without gaps, saturated samples or a resumed stream (those keep the
reference path in `motion.GyroMotion`, which handles them); tests check both paths agree.

numba compiles a kernel (or loads it from its disk cache) at its first call. Should that fail, the
call changes nothing (compilation comes before execution): `fall_back` warns once, and this filter
and every later one take the reference path; each caller then does the step that way.
"""

from __future__ import annotations

import numpy as np

from ... import jit
from . import kernels
from .accel import PERIOD_TOLERANCE_S
from .state import ORTHONORMALISE_EVERY
from .state_buffer import (S_ACCEL_DOWNWEIGHTED, S_ACCEL_SKIPPED, S_ACCEL_UPDATES, S_NONFINITE, S_REST_UPDATES,
                           S_VISUAL_REJECTED, S_VISUAL_UPDATES)


def kernels_available() -> bool:
    """Whether the compiled kernels are there (numba imported, none failed)."""
    return kernels.KERNEL is not None


def fall_back(filt, exc: BaseException) -> None:
    """A kernel failed to compile or load: one warning line, no kernels from now on, and `filt`
    switched to the reference path (see the module docstring)."""
    jit.disable(exc)
    kernels.disable_all()
    to_reference_path(filt)


def to_reference_path(filt) -> None:
    """`filt` on the reference path from now on: not compiled, its motion's paths chosen again."""
    filt.compiled = False
    filt.set_motion(filt.motion)


def compiled_path_applies(filt, t: np.ndarray, saturated: np.ndarray, extra_s: float) -> bool:
    """Whether a batch (camera clock) can take the compiled path: samples present, not just after an
    IMU gap, no saturated sample, no extrapolation past `imu_gap_limit_s` (the kernel itself refuses
    a batch with a longer step between samples)."""
    if not t.size or filt.in_imu_gap or extra_s > filt.config.imu_gap_limit_s:
        return False
    return not (filt.stream.counts.saturated and saturated.any())


def _parameters(filt, defer: bool) -> np.ndarray:
    """The kernels' parameter vector (cached per filter: only two entries change over a run)."""
    cache = filt.__dict__.get("_kernel_parameters")
    if cache is None:  # all four at once, so that the cache never grows later in a run
        cache = filt._kernel_parameters = {}
        for manhattan in (False, True):
            for deferred in (False, True):
                p = parameter_vector(filt, deferred)
                p[kernels.P_MF_INIT] = float(manhattan)
                cache[manhattan, deferred] = p
    return cache[filt.manhattan_initialised, defer]


def parameter_vector(filt, defer: bool) -> np.ndarray:
    """The kernels' parameter vector (`kernels.P_SIZE`,) for filter `filt`, from its configuration; `defer`:
    an update due at the end of a batch waits for the frame."""
    cfg = filt.config
    p = np.empty(kernels.P_SIZE)
    p[kernels.P_Q_GYRO], p[kernels.P_Q_BIAS], p[kernels.P_Q_RATE] = filt.q_gyro, filt.q_bias, filt.q_rate
    p[kernels.P_TRAPEZOID] = float(filt.trapezoid)
    p[kernels.P_PERIOD] = cfg.accel_update_period_s
    p[kernels.P_DUE] = cfg.accel_update_period_s - PERIOD_TOLERANCE_S
    p[kernels.P_DEFER] = float(defer)
    p[kernels.P_LP_TAU] = cfg.accel_lowpass_tau_s
    p[kernels.P_INV_G], p[kernels.P_GRAVITY] = 1.0 / cfg.gravity_m_s2, cfg.gravity_m_s2
    p[kernels.P_ACCEL_NOISE] = cfg.accel_tilt_noise_rad_sqrt_s
    p[kernels.P_NORM_SCALE], p[kernels.P_INNOV_SCALE] = cfg.accel_norm_scale, cfg.accel_innovation_scale_rad
    p[kernels.P_FLAG_RATIO] = cfg.accel_downweight_flag_ratio
    p[kernels.P_REST_GYRO], p[kernels.P_REST_ACCEL] = cfg.rest_gyro_max_rad_s, cfg.rest_accel_max_m_s2
    p[kernels.P_REST_MIN_S], p[kernels.P_REST_STD] = cfg.rest_min_duration_s, cfg.rest_rate_std_rad_s
    p[kernels.P_MF_INIT] = float(filt.manhattan_initialised)
    walks = filt.manhattan_walks
    p[kernels.P_MF_YAW_RW] = cfg.manhattan_yaw_rw_rad_per_sqrt_s if walks else 0.0
    p[kernels.P_MF_TILT_RW] = cfg.manhattan_tilt_rw_rad_per_sqrt_s if walks else 0.0
    p[kernels.P_ORTHO_EVERY] = ORTHONORMALISE_EVERY
    p[kernels.P_RECORD] = float(cfg.record_imu_estimates)
    p[kernels.P_GAP_LIMIT] = cfg.imu_gap_limit_s
    p[kernels.P_GATE_CHI2], p[kernels.P_HUBER] = cfg.visual_gate_chi2, cfg.visual_huber_k
    p[kernels.P_VERTICAL_STD], p[kernels.P_VERTICAL_MAX] = cfg.manhattan_vertical_std_rad, cfg.manhattan_vertical_max_rad
    p[kernels.P_VISUAL_CORRELATION] = cfg.visual_error_correlation_s
    p[kernels.P_TRUST_FRAMES], p[kernels.P_TRUST_MIN_SHARE] = cfg.visual_trust_frames, cfg.visual_trust_min_share
    return p


_COUNTERS = ((S_ACCEL_UPDATES, "accel_updates"), (S_ACCEL_SKIPPED, "accel_skipped"),
             (S_ACCEL_DOWNWEIGHTED, "accel_downweighted"), (S_REST_UPDATES, "rest_updates"),
             (S_NONFINITE, "nonfinite_updates"), (S_VISUAL_UPDATES, "visual_updates"),
             (S_VISUAL_REJECTED, "visual_rejected"))
_FLOAT64 = np.dtype(np.float64)
_NO_RECORD = np.empty((0, 3, 3))  # record buffers when nothing is recorded (writable: the kernels' type)


def harvest_kernel_counters(x: np.ndarray, counters: dict[str, int]) -> None:
    """Move the update counts the kernels keep in the state buffer `x` into `counters` (by name)."""
    for index, name in _COUNTERS:
        count = x[index]
        if count:
            counters[name] += int(count)
            x[index] = 0.0


def _record_buffers(filt, n: int) -> tuple[np.ndarray, np.ndarray]:
    if not filt.config.record_imu_estimates:
        return _NO_RECORD, _NO_RECORD
    return np.empty((n, 3, 3)), np.empty((n, 3, 3))


def integrate_compiled(filt, rows: np.ndarray, extra_s: float, defer: bool) -> bool:
    """Integrate a batch `rows` (n, 8) (`types.IMU_COLUMNS`, camera frame) with the kernel, which
    updates the filter's state buffer in place; False (nothing changed) when the batch holds an IMU
    gap, which the reference path then handles."""
    record_R, record_P = _record_buffers(filt, rows.shape[0])
    try:
        code = kernels.KERNEL(filt.x, rows, extra_s, _parameters(filt, defer), record_R, record_P)
    except Exception as exc:  # noqa: BLE001 -- the reference path takes the batch
        fall_back(filt, exc)
        return False
    return _took_batch(filt, code, rows, rows.shape[0], record_R, record_P)


def _took_batch(filt, code: int, rows: np.ndarray, n: int, record_R: np.ndarray, record_P: np.ndarray) -> bool:
    """After a kernel integrated the first `n` of `rows` (`types.IMU_COLUMNS`) with result `code`: False
    when it refused them (code < 0, nothing changed); else True, with the estimates it recorded kept
    and its result bits (`Status` bits) raised in `filt.flags`."""
    if code < 0:
        return False
    if record_R.shape[0]:
        filt.record_t.append(rows[:n, 0].copy())
        filt.record_R.append(record_R)
        filt.record_P.append(record_P)
    filt.flags |= code
    return True


STAGE_ROWS = 512
"""Rows of a filter's stage (`Mekf._stage`, `stage_compiled`): a frame's samples up to 15 kHz at 30 fps."""


def stage_compiled(filt, t, gyro_c, accel_c) -> int:
    """A frame's batch from `process_imu` (`t` (n,) s, `gyro_c` (n, 3) rad/s, `accel_c` (n, 3) m/s^2,
    camera frame, shapes checked), nothing else held in the filter's reorder buffer: checked as
    `ImuStream.add` checks it and copied into the filter's stage (the caller may reuse its arrays),
    where it waits for the frame (`integrate_staged_compiled`), in one kernel call
    (`kernels.stage_batch`). Returns n, or 0 (nothing staged) unless every sample is clean (finite,
    in order, later than the stream's watermark, below the gyro range) and the batch spans less than
    an accelerometer period and the reorder window (a batch that long may release samples)."""
    stream = filt._stream
    try:
        return kernels.STAGE(filt._stage, t, gyro_c, accel_c, stream.watermark_s, stream.gyro_range_rad_s,
                       filt.stage_span_s)
    except Exception as exc:  # noqa: BLE001 -- nothing staged: the reorder buffer takes the batch
        fall_back(filt, exc)
        return 0


def integrate_staged_compiled(filt, n: int, t_frame_s: float) -> bool:
    """The `n` samples staged by `stage_compiled`, integrated to the frame at `t_frame_s` (s) in one
    kernel call (`kernels.integrate_staged`); an update falling due at their end is left to the frame
    (its visual update stacks it). False, changing nothing, when a sample lies past the frame, the
    frame lies past the gap limit, a step is an IMU gap, or an accelerometer update waits. A frame's
    path: the fewest Python steps around the one call."""
    record_R, record_P = _record_buffers(filt, n)
    try:
        code = kernels.INTEGRATE_STAGED(filt.x, filt._stage, n, t_frame_s, _parameters(filt, True), record_R, record_P)
    except Exception as exc:  # noqa: BLE001 -- the reference path takes the staged batch
        fall_back(filt, exc)
        return False
    if not _took_batch(filt, code, filt._stage, n, record_R, record_P):
        return False
    filt._stream.released_elsewhere(t_frame_s)
    return True


def integrate_segments_compiled(filt, t, gyro_c, accel_c, ends: np.ndarray):
    """An IMU-only stream (camera frame, clean: see `kernels.integrate_segments`) integrated with an
    estimate after each segment `ends` (M,) (exclusive sample ends), in the filter's state buffer;
    returns `(R_wc (M, 3, 3), attitude cov (M, 3, 3), b_c (M, 3), flags (M,) Status bits)`, or None
    (nothing changed) when the stream holds an IMU gap. `filt.flags` is left to the caller: the
    per-estimate flags already say what happened."""
    m = ends.shape[0]
    record_R, record_P = _record_buffers(filt, t.size)
    out_R, out_cov, out_b, out_flags = np.empty((m, 3, 3)), np.empty((m, 3, 3)), np.empty((m, 3)), np.empty(m, np.int64)
    try:
        done = kernels.SEGMENTS(filt.x, np.ascontiguousarray(t, float), np.ascontiguousarray(gyro_c, float),
                          np.ascontiguousarray(accel_c, float), ends, _parameters(filt, False), record_R, record_P,
                          out_R, out_cov, out_b, out_flags)
    except Exception as exc:  # noqa: BLE001 -- the reference path takes the segments
        fall_back(filt, exc)
        return None
    if done < 0:
        return None
    if record_R.shape[0]:
        filt.record_t.append(np.array(t, float))
        filt.record_R.append(record_R)
        filt.record_P.append(record_P)
    return out_R, out_cov, out_b, out_flags  # the kernels' result bits are `Status` bits


def accel_update_compiled(filt) -> bool:
    """The accelerometer (and at-rest) update of the period just completed, compiled, in the filter's
    state buffer: as `Mekf.accel_update` (no longer due). False, changing nothing, after `fall_back`."""
    try:
        filt.flags |= kernels.ACCEL_UPDATE(filt.x, _parameters(filt, False))
    except Exception as exc:  # noqa: BLE001 -- the reference path applies the update
        fall_back(filt, exc)
        return False
    filt.accel.due = False
    return True


def visual_update_compiled(filt, visual) -> int | None:
    """A frame's visual rotation fused into the filter's state buffer in one compiled call
    (`kernels.visual_update`), as `Mekf._visual_update` fuses it with an IMU, a due accelerometer
    update stacked in; its result bits raised in `filt.flags` and the estimate after it in
    `filt.estimate_out` (see the kernel). Returns non-zero when the frame was gated out; None,
    changing nothing, after `fall_back`."""
    R_cm, cov = visual.R_cm, visual.cov
    if not (type(R_cm) is type(cov) is np.ndarray and R_cm.dtype is cov.dtype is _FLOAT64):
        R_cm, cov = np.asarray(R_cm, float), np.asarray(cov, float)  # lists, other dtypes: one specialisation
    try:
        code = kernels.VISUAL_UPDATE(filt.x, _parameters(filt, False), R_cm, cov, filt.estimate_out)
    except Exception as exc:  # noqa: BLE001 -- the reference path fuses the frame
        fall_back(filt, exc)
        return None
    filt.flags |= code
    return code & kernels.VISUAL_REJECTED
