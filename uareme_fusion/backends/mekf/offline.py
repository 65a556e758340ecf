"""Offline (recorded IMU file) attitude: the EKF run forward and backward in time, tilts fused.

A two-filter smoother over the same models as `Mekf`: the backward filter runs on the time-reversed
log (gyro negated), so at each sample the two estimates use disjoint halves of the data apart from
the sample itself; their up vectors are averaged with the inverse of each filter's tilt variance.
Only the tilt is fused: each filter's world yaw is its own gauge, so the result keeps the forward
filter's heading. Returns the camera attitude `R_wc` (camera to a z-up world) per IMU sample.

`OfflineImu` serves these as a backend, so that `run`/`eval --offline` on a recorded IMU-only file
(`pipeline.session.build_pipeline`) write them through the usual sinks.
"""

from __future__ import annotations

import numpy as np

from ...errors import InputError
from ...rotations import WORLD_UP, exp_so3
from ...types import Estimate, Estimates, Status, VisualRotation
from ..base import Backend
from ..imu_stream import check_imu_arrays
from .config import GyroSampling, MekfConfig, MekfMode
from .filter import Mekf


def _recorded(config: MekfConfig, t_s, gyro, accel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (N,), R_wc (N, 3, 3), cov (N, 3, 3)) after every sample of one IMU-only run."""
    filt = Mekf(config.model_copy(update={"mode": MekfMode.IMU_ONLY, "record_imu_estimates": True}))
    filt.process_imu(t_s, gyro, accel)
    filt.flush()
    t, R = filt.imu_trajectory()
    return t, R, filt.imu_trajectory_cov()


def _on_grid(t_grid, t, values) -> np.ndarray:
    """`values` (M, ...) placed at their times in `t_grid` (N,), NaN where a time has no value."""
    out = np.full((t_grid.size, *values.shape[1:]), np.nan)
    idx = np.clip(np.searchsorted(t_grid, t), 0, max(t_grid.size - 1, 0))
    hit = t_grid[idx] == t
    out[idx[hit]] = values[hit]
    return out


def _tilt_variance(up_c: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Mean variance (rad^2) of the two tilt directions: that of `cov` across `up_c`, per sample."""
    along = np.einsum("ni,nij,nj->n", up_c, cov, up_c)
    return np.maximum(0.5 * (np.trace(cov, axis1=1, axis2=2) - along), 1e-12)


def forward_backward_imu(config: MekfConfig, t_s, gyro_rad_s, accel_m_s2,
                         with_cov: bool = False) -> tuple[np.ndarray, ...]:
    """Offline attitude of a recorded IMU log (IMU frame; times on the filter's clock, cleaned as
    the filter cleans them): `(t_s (N,), R_wc (N, 3, 3))`, camera to a z-up world whose yaw is the
    forward filter's; samples only the forward filter estimated keep its estimate. With `with_cov`
    also `cov (N, 3, 3)` (rad^2, right perturbation): the forward filter's, scaled by the ratio of
    the fused to the forward tilt variance."""
    t, gyro, accel = check_imu_arrays(t_s, gyro_rad_s, accel_m_s2)
    t_f, R_f, P_f = _recorded(config, t, gyro, accel)
    # Time-reversed log: a gyro sample stamped t_k measures the rate over (t_{k-1}, t_k] when
    # `interval`-sampled, which reversed is the interval ending at -t_{k-1}: shift by one sample.
    gyro_rev = -gyro[::-1]
    if config.gyro_sampling == GyroSampling.INTERVAL and gyro.shape[0] > 1:
        gyro_rev = np.concatenate([gyro_rev[:1], gyro_rev[:-1]])
    t_b, R_b, P_b = _recorded(config, -t[::-1], gyro_rev, accel[::-1])
    grid = np.unique(t_f)
    R_fg = _on_grid(grid, t_f, R_f)
    P_fg = _on_grid(grid, t_f, P_f)
    R_bg = _on_grid(grid, -t_b, R_b)
    P_bg = _on_grid(grid, -t_b, P_b)
    up_f = np.swapaxes(R_fg, 1, 2) @ WORLD_UP
    up_b = np.swapaxes(R_bg, 1, 2) @ WORLD_UP
    w_f = 1.0 / _tilt_variance(up_f, P_fg)
    w_b = 1.0 / _tilt_variance(up_b, P_bg)
    w_b = np.where(np.isfinite(w_b), w_b, 0.0)
    up = w_f[:, None] * up_f + w_b[:, None] * np.nan_to_num(up_b)
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    # R = R_f Exp(phi) with Exp(-phi) up_f = up: phi = -(angle from up_f to up about their normal).
    axis = np.cross(up_f, up)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, np.einsum("ni,ni->n", up_f, up))
    phi = -np.where(s[:, None] > 0, axis / np.where(s > 0, s, 1.0)[:, None], 0.0) * angle[:, None]
    R = R_fg @ exp_so3(phi)
    if not with_cov:
        return grid, R
    return grid, R, P_fg * (w_f / (w_f + w_b))[:, None, None]


class OfflineImu(Backend):
    """Estimates of a whole recorded IMU log smoothed up front (`forward_backward_imu`), returned at
    the times the pipeline asks for (the last sample at or before each)."""

    name = "mekf-offline"

    def __init__(self, config: MekfConfig, t_s, gyro_rad_s, accel_m_s2):
        t = np.asarray(t_s, float) + config.imu_time_offset_s
        self.t_s, self.R_wc, self.cov = forward_backward_imu(
            config.model_copy(update={"imu_time_offset_s": 0.0}), t, gyro_rad_s, accel_m_s2, with_cov=True)

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        return self._at(np.array([float(t_s)]))[0]

    def process_imu_segments(self, t_s, gyro_rad_s, accel_m_s2, ends) -> Estimates:
        """The estimates at the segments' last samples, all at once (`Backend.process_imu_segments`)."""
        return self._at(np.asarray(t_s, float)[np.asarray(ends, int) - 1])

    def _at(self, t_s: np.ndarray) -> Estimates:
        """The smoothed estimates at times `t_s` (M,) s: identity, NOT_INITIALISED before the first sample."""
        k = np.searchsorted(self.t_s, t_s, side="right") - 1
        before = k < 0
        k = np.maximum(k, 0)
        R_wc, cov = self.R_wc[k], 0.5 * (self.cov[k] + np.swapaxes(self.cov[k], 1, 2))
        R_wc[before] = cov[before] = np.eye(3)
        status = np.where(before, int(Status.NOT_INITIALISED), 0).astype(np.int64)
        return Estimates(t_s.copy(), R_wc, cov, status)

    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        return None


def offline_backend(config: MekfConfig, source) -> OfflineImu:
    """`OfflineImu` over every IMU sample of a recorded IMU-only `source` (read once here; the
    pipeline then replays the source for the estimate times)."""
    if source.info.has_frames:
        raise InputError(f"{source.info.name}: --offline smooths a recorded IMU-only file; this source has frames")
    batches = [e for e in source.events() if len(e)]
    if not batches:
        raise InputError(f"{source.info.name}: no IMU samples to smooth")
    return OfflineImu(config, np.concatenate([b.t_s for b in batches]),
                      np.concatenate([b.gyro_rad_s for b in batches]),
                      np.concatenate([b.accel_m_s2 for b in batches]))
