"""`Mekf.process_imu_segments`: an IMU-only stream in bulk, one kernel call for many estimates.

The result is the one `Backend.process_imu_segments` gives (each segment fed with `process_imu`,
then a frame without visual rotation at its last sample): clean stretches of the stream take the
kernel `kernel_imu.integrate_segments` in one call, with the same chunks and updates as the
segment-by-segment path; the rest (the first samples, before the filter is initialised; a segment
holding a non-finite, repeated, out-of-order or saturated sample, which the reorder buffer handles;
a gap; a segment longer than an update period; a stream with an IMU time offset, whose segments the
filter sees on the camera clock) goes segment by segment through `process_imu` and `process_frame`,
into the same kernels.
"""

from __future__ import annotations

import numpy as np

from ...types import Estimates
from ..base import Backend
from ..imu_stream import check_imu_arrays
from . import status_bits
from .compiled import integrate_segments


def process_imu_segments(filt, t_s, gyro_rad_s, accel_m_s2, ends) -> Estimates:
    """See the module docstring; `filt` is a `Mekf`."""
    t, gyro, accel = check_imu_arrays(t_s, gyro_rad_s, accel_m_s2)
    ends = np.asarray(ends, np.int64)
    parts: list[Estimates] = []
    first = 0  # next segment
    while first < ends.size:
        start = int(ends[first - 1]) if first else 0
        n_clean = _clean_segments(filt, t, gyro, accel, ends, first) if _ready(filt) else 0
        if n_clean:
            parts.append(_segments_in_one_call(filt, t, gyro, accel, ends[first:first + n_clean], start))
            first += n_clean
            continue
        end = int(ends[first])
        parts.append(Backend.process_imu_segments(filt, t[start:end], gyro[start:end], accel[start:end],
                                                  np.array([end - start])))
        first += 1
    if not parts:
        return Estimates.of([])
    return Estimates.concatenate(parts)


def _ready(filt) -> bool:
    """Whether the filter is in the state the segments in one call start from: gyro-driven and
    initialised, nothing buffered, no IMU gap or deferred update pending, no time offset."""
    return bool(filt.motion.uses_imu and filt.initialised and not filt.pending
                and not filt.init_samples and filt.stream.held_count == 0 and not filt.accel.due
                and not filt.in_imu_gap and not filt.manhattan_initialised and not filt.config.imu_time_offset_s)


def _clean_segments(filt, t, gyro, accel, ends, first: int) -> int:
    """How many segments from `first` on hold only samples the one call takes as they are: finite,
    strictly later than every earlier one, gyro below its range, no step over the gap limit."""
    start = int(ends[first - 1]) if first else 0
    t_rest = t[start:]
    steps = np.diff(t_rest, prepend=max(filt.stream.newest_s, filt.t_state))
    cfg = filt.config
    bad = ~((steps > 0) & (steps <= cfg.imu_gap_limit_s))  # NaN times are bad too
    bad |= ~(np.abs(gyro[start:]) < cfg.gyro_range_rad_s).all(axis=1) | ~np.isfinite(accel[start:]).all(axis=1)
    first_bad = int(np.argmax(bad)) if bad.any() else t_rest.size
    # A segment is clean when it ends at or before the first bad sample, and is short enough that
    # `process_imu` alone would integrate none of it (so the chunks are the same).
    n_clean = int(np.searchsorted(ends[first:] - start, first_bad, side="right"))
    seg_ends = ends[first:first + n_clean]
    seg_starts = np.concatenate(([start], seg_ends[:-1]))
    long = t[seg_ends - 1] - t[seg_starts] >= cfg.accel_update_period_s + filt.stream.reorder_window_s
    return int(np.argmax(long)) if long.any() else n_clean


def _segments_in_one_call(filt, t, gyro_i, accel_i, ends, start: int) -> Estimates:
    """The estimates after clean segments `ends` (from sample `start`) by one kernel call."""
    stop = int(ends[-1])
    t, gyro_i, accel_i = t[start:stop], gyro_i[start:stop], accel_i[start:stop]
    R_ci = filt.R_ci
    gyro_c, accel_c = (gyro_i, accel_i) if filt.imu_is_camera else (gyro_i @ R_ci.T, accel_i @ R_ci.T)
    out = integrate_segments(filt, t, gyro_c, accel_c, ends - start)
    carried, filt.flags = filt.flags, status_bits.OK  # flags gathered before: the first estimate's
    R_wc, cov, b_c, status = out
    status[0] |= carried
    if filt.motion.fuses_visual:  # a frame without visual rotation, as `process_frame` flags it
        status |= status_bits.VISUAL_MISSING
    filt.stream.watermark_s = float(t[-1])
    return Estimates(t[ends - start - 1].copy(), R_wc, cov, status, None, b_c @ R_ci)
