"""Multiplicative (error-state) EKF fusing visual Manhattan rotations with a gyro and accelerometer.

See DESIGN.md "Backends: mekf". Conventions:
- Nominal state: `R_wc` (camera to world, world z up), gyro bias `b_c` (rad/s, held in the camera
  frame, reported in the IMU frame), the Manhattan frame's attitude `R_wm`, and (visual-only mode)
  the camera's angular rate `omega_c` (rad/s, camera frame).
- Error state (12,): `[dtheta_c, db_c, dtheta_m, domega_c]` with RIGHT perturbations,
  `R_wc = R_wc_hat @ Exp(dtheta_c)`, `R_wm = R_wm_hat @ Exp(dtheta_m)`; covariance `P` in rad^2,
  (rad/s)^2. filterpy's `predict`/`update` (Joseph form) do the covariance algebra; the nominal
  rotations live in scipy/numpy and take the correction after each update (error reset with its
  Jacobian `I - skew(dtheta)/2`).
- World yaw is a gauge: it is the camera's heading at initialisation (its yaw variance starts at 0).
  With an IMU, world z is up from the accelerometer; without one, the world is the first Manhattan
  frame labelled with its z the axis nearest image up (`R_wm = I`).
- Visual measurement: `R_cm = R_wc^T R_wm`, covariance from the solver; Manhattan labelling resolved
  against the prediction. The IMU: `omega_c = R_ci (gyro_i - b_i)`, `accel_c = R_ci accel_i`; an
  IMU sample stamped `t` measures the camera time `t - imu_time_offset_s`.
- Updates: gyro samples are integrated in one chunk per frame (or per accelerometer period in a long
  batch); the accelerometer updates once per `accel_update_period_s`, and an update that falls due
  at a frame is stacked into that frame's visual update (one filterpy update, same state time). With
  `accel_lowpass_tau_s` the update measures the low-passed direction, whose sensitivity to the gyro
  bias (it was carried along by the gyro) enters H; with `rest_gyro_max_rad_s` the mean gyro reading
  at rest measures the bias (zero-rate update).
"""

from __future__ import annotations

import enum
import math

import numpy as np
from filterpy.kalman import predict as kf_predict
from filterpy.kalman import update as kf_update
from pydantic import BaseModel, ConfigDict, Field, field_validator
from scipy.spatial.transform import Rotation

from ..config import load_config, preset_names
from ..errors import InputError
from ..rotations import WORLD_UP, exp_so3, nearest_symmetric, skew
from ..solver.manhattan import R_CM_UPRIGHT
from ..types import Estimate, Status, VisualRotation
from .base import Backend
from .imu_stream import COLUMNS, ImuBatch, ImuStream
from .mekf_compiled import KERNEL, accel_update_compiled, compiled_path_applies, integrate_compiled

TH, BG, MF, RATE = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
"""Blocks of the 12-dimensional error state."""
N_STATE = 12
I3 = np.eye(3)
_ZERO_STATE = np.zeros(N_STATE)
_NO_ROWS = np.zeros((0, COLUMNS))
_ORTHONORMALISE_EVERY = 16
"""Products (integration chunks and update corrections) between re-orthonormalisations of R_wc and
R_wm: rounding drift grows by ~1e-16 per product, far below anything that matters in 16."""
_TH_AND_MF = np.array([[0, 1, 2], [6, 7, 8]])
"""Indices that gather the two rotation blocks of the error state as a (2, 3) stack."""
_PERIOD_TOLERANCE_S = 1e-9
"""An accelerometer period counts as complete this close to its length (sums of sample steps round)."""

def _block_pattern(*blocks: tuple[slice, slice]) -> np.ndarray:
    """(12, 12) zeros with I3 in the given blocks: process-noise terms are scalars times these."""
    E = np.zeros((N_STATE, N_STATE))
    for rows, cols in blocks:
        E[rows, cols] = I3
    E.setflags(write=False)
    return E


_E_TH_CROSS_BG = np.stack(
    [_block_pattern((TH, TH)), _block_pattern((TH, BG), (BG, TH)), _block_pattern((BG, BG))]
).reshape(3, -1)
"""Attitude, attitude-bias and bias process-noise patterns, flattened: `Q = (c @ this).reshape(12, 12)`."""


class MekfMode(str, enum.Enum):
    """Which inputs the filter uses. `auto`: visual + IMU when IMU samples arrived before the first
    frame, else visual only."""

    AUTO = "auto"
    VISUAL_IMU = "visual_imu"
    IMU_ONLY = "imu_only"
    VISUAL_ONLY = "visual_only"


class GyroSampling(str, enum.Enum):
    """What a gyro sample stamped t_k measures: the rate at t_k (`instant`, integrated with the
    trapezoid rule) or the mean rate over (t_{k-1}, t_k] (`interval`, as many IMUs output)."""

    INSTANT = "instant"
    INTERVAL = "interval"


class MekfConfig(BaseModel):
    """Noise model and robustness settings of `Mekf`; SI units and radians, unit in every name."""

    model_config = ConfigDict(extra="forbid")

    mode: MekfMode = MekfMode.AUTO
    gyro_noise_rad_s_sqrt_hz: float = Field(2e-3, ge=1e-9, le=1.0)
    """Gyro white-noise density (angle random walk), rad/s/sqrt(Hz)."""
    gyro_bias_rw_rad_s2_sqrt_hz: float = Field(1e-4, ge=0, le=1.0)
    """Gyro bias random-walk density, rad/s^2/sqrt(Hz)."""
    gyro_bias_initial_std_rad_s: float = Field(0.01, ge=0, le=10.0)
    """Prior standard deviation of each gyro bias component, rad/s."""
    gyro_rate_noise_sqrt_s: float = Field(0.0, ge=0, le=1.0)
    """Relative gyro error (scale factor, axis misalignment, timing) as a white-noise density, sqrt(s):
    the attitude variance grows by `(this * |omega|)^2` per second of rotation at `|omega|` (0 = off),
    so the filter leans on the accelerometer more while the camera turns fast."""
    gyro_sampling: GyroSampling = GyroSampling.INSTANT
    gyro_range_rad_s: float = Field(34.9, ge=0.1, le=1000.0)
    """Gyro full scale, rad/s (34.9 = 2000 deg/s); readings at or beyond it are flagged."""
    unknown_rate_std_rad_s: float = Field(2.0, ge=1e-3, le=100.0)
    """Angular-rate uncertainty assumed over IMU gaps and saturated samples, rad/s: the attitude
    variance grows by (this * duration)^2 instead of integrating garbage."""
    imu_gap_limit_s: float = Field(0.1, ge=1e-4, le=60.0)
    """A step between IMU samples (or to a frame) longer than this is a gap, s."""
    reorder_window_s: float = Field(0.02, ge=0, le=10.0)
    """IMU samples arriving out of order by less than this are put back in place, s."""
    accel_tilt_noise_rad_sqrt_s: float = Field(0.02, ge=1e-6, le=10.0)
    """Accelerometer direction noise density, rad*sqrt(s): one update over T seconds of averaged
    samples has std `this / sqrt(T)` per tilt axis before inflation."""
    accel_update_period_s: float = Field(0.04, ge=1e-4, le=10.0)
    """Accelerometer samples are averaged (in a common camera frame) over this long per update, s."""
    accel_lowpass_tau_s: float = Field(0.0, ge=0, le=600.0)
    """Time constant of each of two cascaded first-order low-pass stages (second-order roll-off)
    applied to the accelerometer in an almost-inertial frame (the camera frame carried along by the
    gyro), s; 0 = off (each update uses only its own period's mean). Translational accelerations
    average out over it (velocity stays bounded), so seconds suit handheld IMU-only use; each update
    then measures the filtered direction."""
    accel_norm_scale: float = Field(0.05, ge=1e-4, le=100.0)
    """Relative deviation of |mean a| from gravity (dimensionless) at which the update's variance
    doubles: variance factor `1 + (dev / this)^2`."""
    accel_innovation_scale_rad: float = Field(0.05, ge=1e-4, le=10.0)
    """Angle between measured and predicted up at which the update's variance doubles, rad:
    variance factor `1 + (angle / this)^2` (continuous, no timeouts)."""
    accel_downweight_flag_ratio: float = Field(2.0, gt=1, le=1e6)
    """ACCEL_DOWNWEIGHTED is set when the inflated std exceeds this many times the nominal one."""
    rest_gyro_max_rad_s: float = Field(0.0, ge=0, le=10.0)
    """Rest detection for the zero-rate bias update (0 = off): an accelerometer-update period is at
    rest when its mean gyro reading and the rms deviation of its gyro samples from that mean are both
    below this, rad/s (vqf uses 2 deg/s = 0.035)."""
    rest_accel_max_m_s2: float = Field(0.5, gt=0, le=100.0)
    """...and the rms deviation of its accelerometer samples from their mean is below this, m/s^2."""
    rest_min_duration_s: float = Field(1.5, ge=0, le=3600.0)
    """Rest must have lasted this long before the mean gyro reading measures the bias, s."""
    rest_rate_std_rad_s: float = Field(5e-4, ge=1e-9, le=10.0)
    """Residual angular rate allowed at rest (micro-motion), added to the gyro white noise of the
    period's mean in the zero-rate update's std, rad/s."""
    initial_tilt_std_rad: float = Field(0.03, ge=1e-6, le=10.0)
    """Tilt std after initialisation from the first accelerometer samples, rad."""
    init_accel_window_s: float = Field(0.05, ge=1e-4, le=60.0)
    """Accelerometer samples averaged for the initial tilt, s."""
    manhattan_yaw_rw_rad_sqrt_s: float = Field(0.0, ge=0, le=10.0)
    """Random walk of the Manhattan frame's yaw about world up, rad/sqrt(s) (0 in a building; a
    vehicle's turns need about 0.5)."""
    manhattan_tilt_rw_rad_sqrt_s: float = Field(0.0, ge=0, le=10.0)
    """Random walk of the Manhattan frame's tilt, rad/sqrt(s) (vehicle body sway)."""
    manhattan_vertical_std_rad: float = Field(0.02, ge=1e-6, le=10.0)
    """How far the Manhattan z axis may lean from world up (std, rad): a pseudo-measurement applied
    with each visual update ("walls are vertical"); skipped when m's z is far from up."""
    manhattan_vertical_max_rad: float = Field(0.35, gt=0, le=3.15)
    """The vertical pseudo-measurement is skipped when m's z is farther than this from up, rad."""
    rate_rw_rad_s2_sqrt_hz: float = Field(3.0, ge=1e-6, le=1000.0)
    """Visual-only constant-rate model: angular-rate random walk, rad/s^2/sqrt(Hz)."""
    rate_initial_std_rad_s: float = Field(1.0, ge=1e-6, le=100.0)
    """Visual-only: prior std of the angular rate, rad/s."""
    visual_gate_chi2: float = Field(16.27, gt=0, le=1e6)
    """Mahalanobis gate on the 3-dof visual residual (16.27 = chi-square 99.9 %)."""
    visual_huber_sigma: float = Field(2.0, ge=1e-3, le=1e6)
    """Huber threshold on the Mahalanobis distance: beyond it the visual covariance is scaled by d/k."""
    reinit_after_rejections: int = Field(8, ge=1, le=1000000)
    """Consecutive gated-out frames after which the Manhattan frame is re-initialised."""
    R_ci: list[list[float]] = Field(default_factory=lambda: np.eye(3).tolist())
    """Camera-from-IMU rotation (`v_c = R_ci v_i`), 3x3 row-major."""
    imu_time_offset_s: float = Field(0.0, ge=-3600.0, le=3600.0)
    """The IMU clock runs this far ahead of the camera clock, s."""
    gravity_m_s2: float = Field(9.81, ge=1.0, le=100.0)
    record_imu_estimates: bool = False
    compiled: bool = True
    """Integrate gap-free IMU batches with the compiled kernels (`mekf_kernels`) when numba is
    available; False (or no numba) runs the numpy/filterpy reference path."""
    """Keep `R_wc` after every IMU sample (see `Mekf.imu_trajectory`)."""

    @field_validator("R_ci")
    @classmethod
    def _rotation(cls, value):
        R = np.asarray(value, float)
        if R.shape != (3, 3) or not np.allclose(R.T @ R, I3, atol=1e-6) or np.linalg.det(R) <= 0:
            raise ValueError(f"must be a 3x3 rotation matrix, got {value}")
        return value


def _orthonormal(R: np.ndarray) -> np.ndarray:
    """One Newton step of the polar decomposition, `R (3 I - R^T R) / 2`: removes the rounding drift
    of a product of rotations (quadratic convergence; exact rotations are fixed points)."""
    return 0.5 * R @ (3.0 * I3 - R.T @ R)


def _prefix_products(M: np.ndarray) -> np.ndarray:
    """C_k = M_0 @ M_1 @ ... @ M_k for a stack (N, 3, 3), by a log-depth (Hillis-Steele) scan."""
    C = M.copy()
    shift = 1
    while shift < C.shape[0]:
        C[shift:] = C[:-shift] @ C[shift:]
        shift *= 2
    return C


def _direction_update_jacobian(u: np.ndarray) -> np.ndarray:
    """d/d(dtheta) of `Exp(-dtheta) u` at 0 (a world direction seen in a right-perturbed frame)."""
    return skew(u)


class Mekf(Backend):
    """The multiplicative EKF; see the module docstring for state and conventions."""

    name = "mekf"

    def __init__(self, config: MekfConfig | str | None = None):
        """`config`: a `MekfConfig`, a preset name or YAML path (`Mekf("vehicle")`), or None for the defaults."""
        if isinstance(config, str):
            config = load_config(config, MekfConfig)
        elif config is not None and not isinstance(config, MekfConfig):
            raise TypeError(f"Mekf(config): expected a MekfConfig, a preset name ({', '.join(preset_names())}) or a "
                            f"YAML path, got {type(config).__name__}")
        self.config = cfg = config or MekfConfig()
        self.R_ci = np.asarray(cfg.R_ci, float)
        self._imu_is_camera = bool(np.array_equal(self.R_ci, I3))
        self._q_gyro = cfg.gyro_noise_rad_s_sqrt_hz**2
        self._q_bias = cfg.gyro_bias_rw_rad_s2_sqrt_hz**2
        self._q_rate = cfg.gyro_rate_noise_sqrt_s**2
        self._manhattan_walks = bool(cfg.manhattan_yaw_rw_rad_sqrt_s or cfg.manhattan_tilt_rw_rad_sqrt_s)
        self._inv_g = 1.0 / cfg.gravity_m_s2
        self._trapezoid = cfg.gyro_sampling == GyroSampling.INSTANT
        self._compiled = cfg.compiled and KERNEL is not None
        self.stream = ImuStream(cfg.reorder_window_s, cfg.gyro_range_rad_s)
        self.mode = cfg.mode
        self.R_wc = np.eye(3)
        self.R_wm = np.eye(3)
        self.b_c = np.zeros(3)
        self.omega_c = np.zeros(3)
        self.P = np.zeros((N_STATE, N_STATE))
        self._F = np.eye(N_STATE)  # transition buffer: only its TH rows change between chunks
        self._products_unnormalised = 0
        self.t_state: float | None = None
        self.initialised = False
        self.manhattan_initialised = False
        self.counters = dict(visual_rejected=0, reinitialised=0, accel_downweighted=0, accel_skipped=0,
                             imu_gaps=0, imu_ignored=0, visual_updates=0, accel_updates=0,
                             rest_updates=0)
        self._flags = Status.OK
        self._last_gyro_c: np.ndarray | None = None
        self._imu_t_s = -np.inf  # time of the newest integrated IMU sample (camera clock), s
        self._in_imu_gap = False  # frames are being extrapolated past `imu_gap_limit_s` of no IMU
        self._pending: list[ImuBatch] = []
        self._pending_span_s = 0.0
        self._init_samples: list[ImuBatch] = []
        self._rejections = 0
        self._dropped_reported = 0
        # Accelerometer average since the last update, expressed in the current camera frame.
        self._acc_sum_c = np.zeros(3)
        self._acc_time_s = 0.0  # time covered by accelerometer samples since the last update, s
        self._acc_elapsed_s = 0.0  # time elapsed since the last update (frame extrapolations too), s
        self._accel_due = False  # a completed period's update waits for the frame's visual update
        # Rest detection over the same period: raw gyro and accelerometer sums (camera frame), sums
        # of squared norms, sample count; time rest began (None when moving).
        self._rest_sums = np.zeros(8)
        self._rest_since_s: float | None = None
        self._rest_n = 0
        # Low-pass stages (2, 3) of the specific force (m/s^2), rows in the current camera frame
        # (None until the first update), and their sensitivity (2, 3, 3) to the gyro-bias error:
        # the stages computed with the true bias would read `lp + J @ db` (the frame they were
        # carried in turned with the estimated bias).
        self._acc_lp_c: np.ndarray | None = None
        self._acc_lp_J: np.ndarray | None = None
        self._record_t: list[np.ndarray] = []
        self._record_R: list[np.ndarray] = []
        self._record_P: list[np.ndarray] = []

    # ------------------------------------------------------------------ public API
    def process_imu(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        """Feed IMU samples (IMU frame, IMU clock); see `Backend.process_imu`. Non-finite, duplicate
        and late samples are dropped and counted in `self.stream.counts`."""
        if self.mode == MekfMode.VISUAL_ONLY:
            self.counters["imu_ignored"] += int(np.size(t_s))
            return
        if self.config.imu_time_offset_s:
            t_s = np.asarray(t_s, float) - self.config.imu_time_offset_s
        stream = self.stream
        stream.add(t_s, gyro_rad_s, accel_m_s2)
        # Samples wait in the reorder buffer; a frame's `propagate_to` releases them, or, in an
        # IMU-only stream, this does once an accelerometer period's worth is older than the window.
        if stream.held_span_s + self._pending_span_s >= self.config.accel_update_period_s + stream.reorder_window_s:
            self._queue(stream.release_until(stream.newest_s - stream.reorder_window_s, move_watermark=False))
            if self._pending_span_s >= self.config.accel_update_period_s:
                self._integrate_pending()

    def flush(self) -> None:
        """Release and integrate every buffered IMU sample (end of an IMU-only stream)."""
        self._queue(self.stream.flush())
        self._integrate_pending(force_init=True)
        if self._accel_due:
            self._accel_update()

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        """Propagate to `t_s`, fuse `visual` (None for a dropped frame) and return the estimate.

        `Estimate.R_wc` maps camera to world (z up); `cov` (3, 3, rad^2) is that of the right
        perturbation of `R_wc`; `gyro_bias_rad_s` is in the IMU frame; `R_wm` is None until a
        Manhattan frame was seen.
        """
        t_s = float(t_s)
        if visual is not None and (np.shape(visual.R_cm) != (3, 3) or np.shape(visual.cov) != (3, 3)):
            raise InputError(f"visual rotation at t = {t_s:g} s: expected R_cm and cov of shape (3, 3), got "
                             f"{np.shape(visual.R_cm)} and {np.shape(visual.cov)}")
        if self.mode == MekfMode.AUTO:
            seen_imu = self.initialised or self._pending or self.stream.newest_s > -np.inf or self._init_samples
            self.mode = MekfMode.VISUAL_IMU if seen_imu else MekfMode.VISUAL_ONLY
        self.propagate_to(t_s)
        if visual is not None and self.manhattan_initialised and self.mode != MekfMode.IMU_ONLY:
            self._visual_update(visual)  # stacks a due accelerometer update into its own
            return self._estimate(t_s)
        if self._accel_due:
            self._accel_update()
        if visual is None or self.mode == MekfMode.IMU_ONLY:
            if self.mode != MekfMode.IMU_ONLY:
                self._flags |= Status.VISUAL_MISSING
        elif not self.initialised:
            self._initialise_from_visual(t_s, visual)
        else:
            self._initialise_manhattan(visual)
        return self._estimate(t_s)

    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        """`R_cm = R_wc^T R_wm` predicted at `t_s` (propagates the filter to `t_s`); None before a
        Manhattan frame is known."""
        if not self.manhattan_initialised:
            return None
        self.propagate_to(float(t_s))
        return self.R_wc.T @ self.R_wm

    def propagate_to(self, t_s: float) -> None:
        """Integrate IMU samples up to `t_s` (then hold the last rate), or run the constant-rate
        model in visual-only mode."""
        if t_s == self.t_state and not self._pending:
            return  # already there (a frame's prediction, then its update); later stamps are late
        if self.mode in (MekfMode.VISUAL_IMU, MekfMode.IMU_ONLY, MekfMode.AUTO):
            self._queue(self.stream.release_until(t_s))
            self._integrate_pending(extrapolate_to_s=t_s, force_init=True)
        elif self.initialised and t_s > self.t_state:
            self._propagate_constant_rate(t_s - self.t_state)
            self.t_state = t_s

    def imu_trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """`(t_s (N,), R_wc (N, 3, 3))` after every integrated IMU sample (camera clock), before the
        accelerometer update that may follow it; needs `record_imu_estimates`."""
        if not self._record_t:
            return np.zeros(0), np.zeros((0, 3, 3))
        return np.concatenate(self._record_t), np.concatenate(self._record_R)

    def imu_trajectory_cov(self) -> np.ndarray:
        """(N, 3, 3) covariance (rad^2, right perturbation of `R_wc`) beside each `imu_trajectory`
        rotation: the one predicted to the end of the chunk that sample was integrated in."""
        return np.concatenate(self._record_P) if self._record_P else np.zeros((0, 3, 3))

    def estimate(self, t_s: float | None = None) -> Estimate:
        """Current estimate (at the state time) without consuming status flags."""
        return self._make_estimate(self.t_state if t_s is None else t_s, self._flags)

    # ------------------------------------------------------------------ IMU propagation
    def _queue(self, batch: ImuBatch) -> None:
        rows = batch.rows
        if rows.shape[0]:
            self._pending.append(batch)
            self._pending_span_s = float(rows[-1, 0] - self._pending[0].rows[0, 0]) + 1e-12

    def _integrate_pending(self, extrapolate_to_s: float | None = None, force_init: bool = False) -> None:
        """Integrate the released samples; with `extrapolate_to_s`, then hold the last gyro rate up
        to that time (a synthetic sample that carries no accelerometer weight)."""
        batches, self._pending, self._pending_span_s = self._pending, [], 0.0
        if len(batches) == 1:
            batch = batches[0]
        else:
            batch = ImuBatch(np.concatenate([b.rows for b in batches]) if batches else _NO_ROWS)
        t, gyro_i, accel_i, saturated = batch.t_s, batch.gyro_rad_s, batch.accel_m_s2, batch.saturated
        gyro_c, accel_c = (gyro_i, accel_i) if self._imu_is_camera else (gyro_i @ self.R_ci.T, accel_i @ self.R_ci.T)
        if not self.initialised:
            if t.size == 0:
                return
            t, gyro_c, accel_c, saturated = self._initialise_from_accel(t, gyro_c, accel_c, saturated, force_init)
            if not self.initialised:
                return
        last_t = float(t[-1]) if t.size else self.t_state
        extra_s = extrapolate_to_s - last_t if extrapolate_to_s is not None and extrapolate_to_s > last_t else 0.0
        if t.size == 0 and extra_s == 0.0:
            return
        if self._accel_due:  # a deferred update that no frame took: apply it before moving on
            self._accel_update()
        period = self.config.accel_update_period_s
        due_s = period - _PERIOD_TOLERANCE_S
        # Propagating to a frame: an update due at its end waits for the frame's visual update (IMU-only
        # there is none: the frame would apply it at once, so it is applied here, in the same order).
        defer = extrapolate_to_s is not None and self.mode != MekfMode.IMU_ONLY
        if (self._compiled and compiled_path_applies(self, t, saturated, extra_s)
                and integrate_compiled(self, t, gyro_c, accel_c, extra_s, defer)):
            return
        if t.size < 2 or last_t - self.t_state <= period:
            # Short batch (a frame's worth): one chunk, then the update if the period is complete.
            self._integrate_chunk(t, gyro_c, accel_c, saturated, extra_s)
            if self._acc_elapsed_s >= due_s:
                self._accel_due = True
                if not defer:
                    self._accel_update()
            return
        # Long batch: split at accelerometer-update boundaries. A sample belongs to the chunk in
        # which its interval starts, so a chunk ends on the sample whose interval crosses the
        # boundary: every chunk but the last one crossed it and ends with an update (each update then
        # averages between `period` and `period` + one sample step).
        bounds = self._chunk_bounds(t).tolist()
        for i in range(len(bounds) - 1):
            a, b = bounds[i], bounds[i + 1]
            last = i == len(bounds) - 2
            self._integrate_chunk(t[a:b], gyro_c[a:b], accel_c[a:b], saturated[a:b], extra_s if last else 0.0)
            if not last or self._acc_elapsed_s >= due_s:
                self._accel_due = True
                if not (last and defer):
                    self._accel_update()

    def _chunk_bounds(self, t: np.ndarray) -> np.ndarray:
        """Chunk limits of a batch (chunk k is samples bounds[k]:bounds[k+1]): one chunk for a short
        batch (a frame's worth), else a cut after each sample whose interval crosses an
        accelerometer-update boundary."""
        period = self.config.accel_update_period_s
        if t.size < 2 or float(t[-1]) - self.t_state <= period:
            return np.array([0, t.size])
        elapsed_before = np.empty(t.size)
        elapsed_before[0] = self._acc_elapsed_s
        elapsed_before[1:] = self._acc_elapsed_s + (t[:-1] - self.t_state)
        cuts = np.flatnonzero(np.diff(np.floor(elapsed_before / period))) + 1
        return np.concatenate(([0], cuts, [t.size]))

    def _integrate_chunk(self, t, gyro_c, accel_c, saturated, extra_s: float = 0.0) -> None:
        """Integrate samples (camera frame) over (t_state, t[-1]]: sample k covers (t_{k-1}, t_k]
        with the mean of its rate and the previous one (trapezoid), or its own rate (`interval`);
        then, for `extra_s` > 0, hold the last rate that much longer (to a frame's time; no
        accelerometer reading there). One scipy call integrates the chunk; the transition matrices
        are composed in closed form."""
        cfg = self.config
        n = t.size
        m = n + 1 if extra_s > 0 else n
        resumed = bool(n and self._in_imu_gap)  # first samples after frames bridged an IMU gap
        if n:
            self._imu_t_s = float(t[-1])
            self._in_imu_gap = False
            if self.stream.counts.saturated and saturated.any():
                gyro_c = self._hold_unsaturated(gyro_c, saturated)
        # A frame more than `imu_gap_limit_s` past the newest IMU sample: the IMU stopped, so the
        # extrapolation is an unknown rotation, not the last rate held.
        stale = (m > n and math.isfinite(self._imu_t_s)
                 and self.t_state + extra_s - self._imu_t_s > cfg.imu_gap_limit_s)
        # Sample times from the state time (and to the extrapolated end), and the gyro readings with
        # the previous one in front (and the last one held over the extrapolation).
        t_all = np.empty(m + 1)
        t_all[0], t_all[1:n + 1] = self.t_state, t
        g_all = np.empty((m + 1, 3))
        g_all[0], g_all[1:n + 1] = self._last_gyro_c, gyro_c
        if m > n:
            t_all[m], g_all[m] = t_all[n] + extra_s, g_all[n]
        if resumed:  # the reading before the gap is stale: the step to the first new one is unknown
            g_all[0] = g_all[1]
        dt = t_all[1:] - t_all[:-1]
        if self._trapezoid:
            rate_c = g_all[1:] + g_all[:-1]
            rate_c *= 0.5
            rate_c -= self.b_c
        else:
            rate_c = g_all[1:] - self.b_c
        self._last_gyro_c = g_all[n]
        unknown_var = 0.0
        if stale or resumed or dt.max() > cfg.imu_gap_limit_s or (self.stream.counts.saturated and saturated.any()):
            # Do not integrate garbage: skip gaps (saturated samples hold the last unsaturated
            # reading), and grow the attitude variance by an unknown rate.
            gap = dt > cfg.imu_gap_limit_s
            if stale:
                gap[m - 1] = True
            unknown = gap.copy()
            unknown[:n] |= saturated > 0
            unknown[0] |= resumed
            unknown_var = float(np.sum((cfg.unknown_rate_std_rad_s * dt[unknown]) ** 2))
            if gap.any():
                self._flags |= Status.IMU_GAP
                self.counters["imu_gaps"] += int(gap[:n].sum()) + int(stale and not self._in_imu_gap)
                self._in_imu_gap |= bool(stale)
            if saturated.any():
                self._flags |= Status.GYRO_SATURATED
            T_elapsed = float(dt.sum())
            dt[gap] = 0.0
            self._acc_lp_c = None  # the frame carried along by the gyro is lost
        else:
            T_elapsed = float(dt.sum())
        M = exp_so3(rate_c * dt[:, None])
        C = _prefix_products(M)
        C_N = C[-1]
        if cfg.record_imu_estimates and n:
            self._record_t.append(t.copy())
            self._record_R.append(self.R_wc @ C[:n])
        self.R_wc = self.R_wc @ C_N
        self._products_unnormalised += 1
        if self._products_unnormalised >= _ORTHONORMALISE_EVERY:
            self._reorthonormalise()
        T = T_elapsed if unknown_var == 0.0 else float(dt.sum())
        # Error transition over the chunk (right perturbations), per sample
        # dtheta_{k+1} = M_k^T dtheta_k - dt_k db, composed: dtheta_N = C_N^T dtheta_0 - C_N^T sum_k dt_k C_k db.
        A_bias = C_N.T @ (dt @ C.reshape(m, 9)).reshape(3, 3)
        F = self._F
        F[TH, TH] = C_N.T
        F[TH, BG] = -A_bias
        # White gyro noise is isotropic, so its rotated sum is q_g T I; bias random walk to 2nd order.
        q_g, q_b = self._q_gyro, self._q_bias
        rate_var = self._q_rate * float(np.einsum("ki,ki,k->", rate_c, rate_c, dt)) if self._q_rate else 0.0
        coefficients = np.array([q_g * T + q_b * T**3 / 3.0 + unknown_var + rate_var, -q_b * T**2 / 2.0, q_b * T])
        Q = (coefficients @ _E_TH_CROSS_BG).reshape(N_STATE, N_STATE)
        if self._manhattan_walks and self.manhattan_initialised:
            self._add_manhattan_noise(Q, T_elapsed)
        _, self.P = kf_predict(_ZERO_STATE, self.P, F, Q)
        if cfg.record_imu_estimates and n:
            self._record_P.append(np.repeat(self.P[None, TH, TH], n, axis=0))
        # Accelerometer: time-weighted sum of specific force, rotated into the chunk's end frame.
        if n:
            self._acc_sum_c = C_N.T @ (self._acc_sum_c + np.einsum("kjl,kl,k->j", C[:n], accel_c, dt[:n]))
            self._acc_time_s += T_elapsed - extra_s if unknown_var == 0.0 else float(dt[:n].sum())
        else:
            self._acc_sum_c = C_N.T @ self._acc_sum_c
        self._acc_elapsed_s += T_elapsed
        if self._acc_lp_c is not None:
            lp = self._acc_lp_c = self._acc_lp_c @ C_N  # rows v^T C_N = (C_N^T v)^T
            # With the true bias the chunk turns by C_N Exp(-A_bias db), so a carried vector v reads
            # Exp(A_bias db) C_N^T v = C_N^T v - skew(C_N^T v) A_bias db.
            J = self._acc_lp_J
            J = np.matmul(C_N.T, J, out=J)
            J[0] -= skew(lp[0]) @ A_bias
            J[1] -= skew(lp[1]) @ A_bias
        if cfg.rest_gyro_max_rad_s > 0 and n:
            self._accumulate_rest(gyro_c, accel_c)
        self.t_state = float(t[-1]) + extra_s if n else self.t_state + extra_s

    def _hold_unsaturated(self, gyro_c: np.ndarray, saturated: np.ndarray) -> np.ndarray:
        """Gyro readings (camera frame, rad/s) with each saturated sample replaced by the last
        unsaturated reading before it: beyond the range the true rate is unknown, and a reading
        pinned at full scale (a shock, a stuck sensor) would spin the attitude by its whole range."""
        index = np.where(saturated > 0, -1, np.arange(saturated.size))
        np.maximum.accumulate(index, out=index)
        held = np.where((index >= 0)[:, None], gyro_c[np.maximum(index, 0)], self._last_gyro_c)
        return held

    def _accumulate_rest(self, gyro_c, accel_c) -> None:
        """Add a chunk's raw readings to the rest statistics."""
        sums = self._rest_sums
        sums[0:3] += gyro_c.sum(axis=0)
        sums[3] += float(np.einsum("ki,ki->", gyro_c, gyro_c))
        sums[4:7] += accel_c.sum(axis=0)
        sums[7] += float(np.einsum("ki,ki->", accel_c, accel_c))
        self._rest_n += gyro_c.shape[0]

    def _rest_update(self, T: float) -> None:
        """Zero-rate update: after `rest_min_duration_s` of rest the period's mean gyro reading
        measures the bias (`b_c = mean gyro`, camera frame), with the gyro white noise of a
        T-second mean plus `rest_rate_std_rad_s`."""
        cfg = self.config
        sums, n = self._rest_sums, self._rest_n
        self._rest_sums, self._rest_n = np.zeros(8), 0
        if n < 2 or T <= 0:
            return
        g_mean, a_mean = sums[0:3] / n, sums[4:7] / n
        g_dev2 = max(sums[3] / n - float(g_mean @ g_mean), 0.0)
        a_dev2 = max(sums[7] / n - float(a_mean @ a_mean), 0.0)
        limit2 = cfg.rest_gyro_max_rad_s**2
        if float(g_mean @ g_mean) >= limit2 or g_dev2 >= limit2 or a_dev2 >= cfg.rest_accel_max_m_s2**2:
            self._rest_since_s = None
            return
        if self._rest_since_s is None:
            self._rest_since_s = self.t_state - T
        if self.t_state - self._rest_since_s < cfg.rest_min_duration_s:
            return
        H = np.zeros((3, N_STATE))
        H[:, BG] = I3
        var = self._q_gyro / T + cfg.rest_rate_std_rad_s**2
        self._kalman_update(g_mean - self.b_c, var * I3, H)
        self.counters["rest_updates"] += 1

    def _reorthonormalise(self) -> None:
        """Remove the rounding drift that products of rotations accumulate in R_wc and R_wm."""
        self.R_wc = _orthonormal(self.R_wc)
        self.R_wm = _orthonormal(self.R_wm)
        self._products_unnormalised = 0

    def _add_manhattan_noise(self, Q: np.ndarray, dt: float) -> None:
        """Manhattan-frame random walk: yaw about world up and tilt, in m's right-perturbation."""
        cfg = self.config
        if not self.manhattan_initialised or dt <= 0 or not (cfg.manhattan_yaw_rw_rad_sqrt_s or cfg.manhattan_tilt_rw_rad_sqrt_s):
            return
        u = self.R_wm.T @ WORLD_UP
        uu = np.outer(u, u)
        Q[MF, MF] += dt * (cfg.manhattan_yaw_rw_rad_sqrt_s**2 * uu + cfg.manhattan_tilt_rw_rad_sqrt_s**2 * (I3 - uu))

    def _propagate_constant_rate(self, dt: float) -> None:
        """Visual-only motion model: `R_wc <- R_wc Exp(omega_c dt)`, omega a random walk."""
        M = exp_so3(self.omega_c * dt)
        self.R_wc = _orthonormal(self.R_wc @ M)
        F = np.eye(N_STATE)
        F[TH, TH] = M.T
        F[TH, RATE] = dt * I3
        q = self.config.rate_rw_rad_s2_sqrt_hz**2
        Q = np.zeros((N_STATE, N_STATE))
        Q[TH, TH] = q * dt**3 / 3.0 * I3
        Q[TH, RATE] = Q[RATE, TH] = q * dt**2 / 2.0 * I3
        Q[RATE, RATE] = q * dt * I3
        _, self.P = kf_predict(np.zeros(N_STATE), self.P, F, Q)

    # ------------------------------------------------------------------ updates
    def _accel_update(self) -> None:
        """Apply the accelerometer update of the period just completed (see `_accel_rows`)."""
        self._accel_due = False
        if self._compiled:
            accel_update_compiled(self)
            return
        rows = self._accel_rows()
        if rows is not None:
            self._kalman_update(*rows)

    def _take_due_accel_rows(self):
        """The deferred accelerometer update's rows, to stack into a frame's visual update (one
        filterpy update instead of two at the same state time), or None when none is due."""
        if not self._accel_due:
            return None
        self._accel_due = False
        return self._accel_rows()

    def _accel_rows(self):
        """Tilt from the accelerometer direction (the period's mean, or its low-passed value with
        `accel_lowpass_tau_s`), noise inflated continuously by how far |a| and the innovation are
        from pure gravity: (residual (3,), covariance (3, 3), H (3, 12)), or None (near free fall).
        Consumes the period's sums."""
        cfg = self.config
        T = self._acc_time_s
        acc_c = self._acc_sum_c / T if T > 0 else self._acc_sum_c
        self._acc_sum_c, self._acc_time_s, self._acc_elapsed_s = np.zeros(3), 0.0, 0.0
        if cfg.rest_gyro_max_rad_s > 0:
            self._rest_update(T)
        if cfg.accel_lowpass_tau_s > 0 and T > 0:
            lp = self._acc_lp_c
            if lp is None:
                lp = self._acc_lp_c = np.array([acc_c, acc_c])
                self._acc_lp_J = np.zeros((2, 3, 3))
            else:
                alpha = 1.0 - np.exp(-T / cfg.accel_lowpass_tau_s)
                lp[0] += alpha * (acc_c - lp[0])
                lp[1] += alpha * (lp[0] - lp[1])
                J = self._acc_lp_J  # the period's own mean is taken as bias-free (its age is ~T/2)
                J[0] *= 1.0 - alpha
                J[1] += alpha * (J[0] - J[1])
            acc_c = lp[1]
        norm = math.sqrt(float(acc_c @ acc_c))
        # |mean specific force| against gravity: the mean is taken in a common (rotating) camera
        # frame, so it is the inertial-frame average and translational accelerations cancel in it.
        norm_dev = abs(norm * self._inv_g - 1.0)
        if not (T > 0 and norm > 0.1 * cfg.gravity_m_s2):  # near free fall: no direction
            self.counters["accel_skipped"] += 1
            return None
        z = acc_c / norm
        h = self.R_wc.T @ WORLD_UP
        angle = math.acos(min(1.0, max(-1.0, float(z @ h))))
        var0 = cfg.accel_tilt_noise_rad_sqrt_s**2 / T
        var = var0 * (1.0 + (norm_dev / cfg.accel_norm_scale) ** 2) * (1.0 + (angle / cfg.accel_innovation_scale_rad) ** 2)
        std0 = np.sqrt(var0)
        if var > (cfg.accel_downweight_flag_ratio * std0) ** 2:
            self._flags |= Status.ACCEL_DOWNWEIGHTED
            self.counters["accel_downweighted"] += 1
        H = np.zeros((3, N_STATE))
        H[:, TH] = _direction_update_jacobian(h)
        if self._acc_lp_J is not None and cfg.accel_lowpass_tau_s > 0:
            # z = normalise(lp - J db): the low-passed direction also measures the bias error.
            H[:, BG] = -(I3 - np.outer(z, z)) @ self._acc_lp_J[1] / norm
        self.counters["accel_updates"] += 1
        return z - h, var * I3, H

    def _visual_update(self, visual: VisualRotation) -> None:
        """Paper's per-frame rotation as a measurement of `R_cm = R_wc^T R_wm` (right perturbation)."""
        cfg = self.config
        accel_rows = self._take_due_accel_rows()
        R_cm_pred = self.R_wc.T @ self.R_wm
        R_cm, P_sym = nearest_symmetric(visual.R_cm, R_cm_pred)  # as VisualRotation.symmetric_to
        # Log of a product of rotations: scipy may skip its orthogonalisation (assume_valid).
        r = Rotation.from_matrix(R_cm_pred.T @ R_cm, assume_valid=True).as_rotvec()
        H = np.zeros((3, N_STATE))
        H[:, TH] = -R_cm_pred.T
        H[:, MF] = I3
        R_vis = P_sym.T @ (0.5 * (visual.cov + visual.cov.T)) @ P_sym
        S = H @ self.P @ H.T + R_vis
        d2 = float(r @ np.linalg.solve(S, r))
        if not np.isfinite(d2) or d2 > cfg.visual_gate_chi2:
            self._flags |= Status.VISUAL_REJECTED
            self.counters["visual_rejected"] += 1
            self._rejections += 1
            if accel_rows is not None:
                self._kalman_update(*accel_rows)
            if self._rejections >= cfg.reinit_after_rejections:
                self._reinitialise_manhattan(visual)
            return
        self._rejections = 0
        d = np.sqrt(d2)
        if d > cfg.visual_huber_sigma:  # Huber weight w = k / d  ->  covariance / w
            R_vis = R_vis * (d / cfg.visual_huber_sigma)
        # One stacked update: the visual rotation, "m's z is up" and a due accelerometer update.
        blocks = [(r, R_vis, H), self._manhattan_vertical_rows(), accel_rows]
        blocks = [b for b in blocks if b is not None]
        if len(blocks) > 1:
            R_all = np.zeros((3 * len(blocks), 3 * len(blocks)))
            for i, b in enumerate(blocks):
                R_all[3 * i:3 * i + 3, 3 * i:3 * i + 3] = b[1]
            r, R_vis, H = np.concatenate([b[0] for b in blocks]), R_all, np.vstack([b[2] for b in blocks])
        self._kalman_update(r, R_vis, H)
        self.counters["visual_updates"] += 1

    def _manhattan_vertical_rows(self):
        """Pseudo-measurement "the Manhattan z axis is (nearly) world up" (DESIGN.md "Conventions"):
        (residual, covariance, H) or None in visual-only mode or when m's z is far from up."""
        if self.mode == MekfMode.VISUAL_ONLY:
            return None  # the world is the Manhattan frame there
        h = self.R_wm.T @ WORLD_UP
        if math.acos(min(1.0, max(-1.0, float(h[2])))) > self.config.manhattan_vertical_max_rad:
            return None
        H = np.zeros((3, N_STATE))
        H[:, MF] = _direction_update_jacobian(h)
        return np.array([0.0, 0.0, 1.0]) - h, self.config.manhattan_vertical_std_rad**2 * I3, H

    def _kalman_update(self, residual: np.ndarray, R: np.ndarray, H: np.ndarray) -> None:
        """filterpy update (Joseph form) of the zero-mean error state, then inject and reset."""
        dx, P = kf_update(_ZERO_STATE, self.P, residual, R, H)
        if not (np.isfinite(dx).all() and np.isfinite(P).all()):
            return
        # Reset Jacobian of the right-perturbation error: G = I - skew(dtheta)/2 on rotation blocks.
        G = np.eye(N_STATE)
        if self.manhattan_initialised:
            dtheta = dx[_TH_AND_MF]
            (dR_c, dR_m), (half_c, half_m) = exp_so3(dtheta), 0.5 * skew(dtheta)
            self.R_wm = self.R_wm @ dR_m
            G[MF, MF] -= half_m
        else:
            dR_c, half_c = exp_so3(dx[TH]), 0.5 * skew(dx[TH])
        self.R_wc = self.R_wc @ dR_c
        self._products_unnormalised += 1
        if self._products_unnormalised >= _ORTHONORMALISE_EVERY:
            self._reorthonormalise()
        G[TH, TH] -= half_c
        self.b_c = self.b_c + dx[BG]
        if self._acc_lp_c is not None:  # re-carry the low-passed accelerometer with the new bias
            self._acc_lp_c += self._acc_lp_J @ dx[BG]
        if self.mode == MekfMode.VISUAL_ONLY:
            self.omega_c = self.omega_c + dx[RATE]
        P = G @ P @ G.T
        self.P = 0.5 * (P + P.T)

    # ------------------------------------------------------------------ initialisation
    def _initialise_from_accel(self, t, gyro_c, accel_c, saturated, force: bool = False):
        """Tilt from the mean of the first `init_accel_window_s` of accelerometer samples; yaw is the
        gauge (variance 0). Returns the samples still to integrate."""
        cfg = self.config
        self._init_samples.append(ImuBatch.of(t, gyro_c, accel_c, saturated))
        held = ImuBatch(np.concatenate([b.rows for b in self._init_samples]))
        t_all = held.t_s
        if t_all[-1] - t_all[0] < cfg.init_accel_window_s and not force:
            return t[:0], gyro_c[:0], accel_c[:0], saturated[:0]
        g_all, a_all, s_all = held.gyro_rad_s, held.accel_m_s2, held.saturated
        self._init_samples = []
        window = t_all <= t_all[0] + cfg.init_accel_window_s
        mean_acc = a_all[window].mean(axis=0)
        if not np.linalg.norm(mean_acc) > 0:
            mean_acc = np.array([0.0, -1.0, 0.0])
        up_c = mean_acc / np.linalg.norm(mean_acc)
        rot, _ = Rotation.align_vectors(WORLD_UP[None], up_c[None])
        self.R_wc = rot.as_matrix()
        self.P = np.zeros((N_STATE, N_STATE))
        self.P[TH, TH] = cfg.initial_tilt_std_rad**2 * (I3 - np.outer(up_c, up_c))
        self.P[BG, BG] = cfg.gyro_bias_initial_std_rad_s**2 * I3
        self.t_state = self._imu_t_s = float(t_all[0])
        self._last_gyro_c = g_all[0]
        self.initialised = True
        if self.mode == MekfMode.AUTO:
            self.mode = MekfMode.VISUAL_IMU
        return t_all[1:], g_all[1:], a_all[1:], s_all[1:]

    def _initialise_from_visual(self, t_s: float, visual: VisualRotation) -> None:
        """No IMU: the world is the Manhattan frame labelled with z nearest image up (`R_wm = I`)."""
        if self.mode != MekfMode.VISUAL_ONLY:
            self._flags |= Status.VISUAL_MISSING  # waiting for the accelerometer to give gravity
            return
        visual = visual.symmetric_to(R_CM_UPRIGHT)
        self.R_wm = np.eye(3)
        self.R_wc = visual.R_cm.T
        self.P = np.zeros((N_STATE, N_STATE))
        self.P[TH, TH] = visual.R_cm @ visual.cov @ visual.R_cm.T
        self.P[RATE, RATE] = self.config.rate_initial_std_rad_s**2 * I3
        self.omega_c = np.zeros(3)
        self.t_state = t_s
        self.initialised = self.manhattan_initialised = True

    def _initialise_manhattan(self, visual: VisualRotation, R_wm_ref: np.ndarray | None = None) -> None:
        """`R_wm = R_wc R_cm`, labelled nearest `R_wm_ref` (identity: m's z nearest up), with its
        covariance from the camera's and the measurement's: `dtheta_m = R_cm^T dtheta_c + delta`."""
        R_wm_ref = np.eye(3) if R_wm_ref is None else R_wm_ref
        visual = visual.symmetric_to(self.R_wc.T @ R_wm_ref)
        A = visual.R_cm.T
        self.R_wm = _orthonormal(self.R_wc @ visual.R_cm)
        T = np.eye(N_STATE)
        T[MF, MF] = 0.0
        T[MF, TH] = A
        P = T @ self.P @ T.T
        P[MF, MF] += visual.cov
        self.P = 0.5 * (P + P.T)
        self.manhattan_initialised = True
        self._rejections = 0

    def _reinitialise_manhattan(self, visual: VisualRotation) -> None:
        """Persistent disagreement: the camera sees a differently aligned scene (or lost track)."""
        self._flags |= Status.REINITIALISED
        self.counters["reinitialised"] += 1
        if self.mode == MekfMode.VISUAL_ONLY:
            visual = visual.symmetric_to(self.R_wc.T @ self.R_wm)
            self.R_wc = self.R_wm @ visual.R_cm.T
            self.P = np.zeros((N_STATE, N_STATE))
            self.P[TH, TH] = visual.R_cm @ visual.cov @ visual.R_cm.T
            self.P[RATE, RATE] = self.config.rate_initial_std_rad_s**2 * I3
            self.omega_c = np.zeros(3)
            self._rejections = 0
            return
        self._initialise_manhattan(visual, R_wm_ref=self.R_wm)

    # ------------------------------------------------------------------ output
    def _estimate(self, t_s: float) -> Estimate:
        dropped = self.stream.counts.dropped
        if dropped > self._dropped_reported:
            self._flags |= Status.IMU_DROPPED
            self._dropped_reported = dropped
        est = self._make_estimate(t_s, self._flags)
        self._flags = Status.OK
        return est

    def _make_estimate(self, t_s, flags: Status) -> Estimate:
        if not self.initialised:
            return Estimate(t_s, np.eye(3), np.eye(3), flags | Status.NOT_INITIALISED)
        cov = 0.5 * (self.P[TH, TH] + self.P[TH, TH].T)
        bias_i = None if self.mode == MekfMode.VISUAL_ONLY else self.R_ci.T @ self.b_c
        return Estimate(
            t_s, self.R_wc.copy(), cov, flags,
            R_wm=self.R_wm.copy() if self.manhattan_initialised else None,
            gyro_bias_rad_s=bias_i,
        )
