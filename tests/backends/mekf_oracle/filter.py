"""The EKF's oracle: the numpy/scipy/filterpy reference of `uareme_fusion.backends.mekf.Mekf`, which
the tests run beside the production filter (its numba kernels) on the same streams.

As the production filter was before its one implementation: `Mekf` here is that filter's reference
path (no kernels), kept only to cross-check the kernels.

See docs/design.md "Backends" and the package docstring for the conventions. The filter holds the
nominal state and its covariance, and schedules: IMU samples and frames propagate through the motion
strategy chosen once for its mode (`motion.py`); a frame's visual rotation, the vertical
pseudo-measurement and a due accelerometer update are fused in one stacked filterpy update
(`measurements.py`); every update is injected and reset through `state.py`.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import update as kf_update

from uareme_fusion.config import load_config, preset_names
from uareme_fusion.errors import InputError
from uareme_fusion.rotations import angle_between
from uareme_fusion.types import Estimate, ImuBatch, VisualRotation
from uareme_fusion.backends.base import Backend
from uareme_fusion.backends.imu_stream import ImuStream
from uareme_fusion.backends.labelling_track import LabellingTrack
from uareme_fusion.backends.visual_noise_share import VisualNoiseShare
from uareme_fusion.backends.mekf import status_bits
from .accel import AccelPeriod
from uareme_fusion.backends.mekf.config import GyroSampling, MekfConfig, MekfMode
from uareme_fusion.backends.mekf.gravity_only import GravityOnly
from .measurements import (correlated_noise_scale, gravity_model, stack, vertical_distance2, vertical_model,
                           visual_model)
from .motion import ConstantRateMotion, GyroMotion
from uareme_fusion.backends.mekf.source_trust import (note_accel_information, note_visual_information, squared_rate, tilt_shares,
                           update_visual_trust, vertical_variance, visual_vertical_innovation)
from uareme_fusion.backends.mekf.status_bits import status_of
from uareme_fusion.backends.mekf.state import (BG, I3, MF, N_STATE, ORTHONORMALISE_EVERY, TH, ZERO_STATE, orthonormal,
                                               reset_jacobian)
from .state import inject
from uareme_fusion.backends.mekf.state_buffer import (BufferArray, BufferScalar, S_ACCEL_VAR_RATE, S_IMU_T, S_PRODUCTS,
                                                      S_REJECTIONS, S_T_STATE, S_T_VISUAL, S_VISUAL_INFO_RATE, X_B_C, X_P,
                                                      X_R_WC, X_R_WM, field_views, new_state_buffer)


_P_TH = X_P + N_STATE * np.arange(N_STATE)[TH, None] + np.arange(N_STATE)[TH]  # where P[TH, TH] lies in `x`
_ESTIMATE_INDEX = np.stack([np.arange(X_R_WC, X_R_WM).reshape(3, 3), np.arange(X_R_WM, X_B_C).reshape(3, 3), _P_TH,
                            _P_TH.T, np.tile(np.arange(X_B_C, X_P), (3, 1))])
"""Where R_wc, R_wm, P[TH, TH], its transpose and b_c (in each row) lie in the state buffer `x` (5, 3, 3):
one `take` copies them."""


_CAMERA_ONLY = (float("nan"), 1.0)
"""`Estimate.tilt_shares` without an IMU: the camera alone."""


def _finite(visual: VisualRotation) -> bool:
    """Whether a frame's rotation and covariance are finite (checked only for a gated-out frame)."""
    return bool(np.isfinite(visual.R_cm).all() and np.isfinite(visual.cov).all())


def _shape(a) -> tuple:
    """`np.shape(a)`, an ndarray's without a numpy call (a frame's checks run between solver calls,
    where each numpy call costs microseconds)."""
    return a.shape if type(a) is np.ndarray else np.shape(a)


def motion_for(mode: MekfMode):
    """The motion strategy of a mode; `auto` starts gyro-driven and is resolved once (`Mekf.resolve_mode`)."""
    return ConstantRateMotion() if mode == MekfMode.VISUAL_ONLY else GyroMotion(mode)


class Mekf(Backend):
    """The multiplicative EKF fusing visual Manhattan rotations with a gyro and accelerometer.

    Feed IMU samples with `process_imu(t_s (N,) s, gyro_rad_s (N, 3), accel_m_s2 (N, 3))` (IMU frame
    and clock) and frames with `process_frame(t_s, VisualRotation or None)`, which returns the
    `Estimate` at `t_s`: `R_wc` (3, 3) camera to a z-up world, `cov` (3, 3) rad^2 of its right
    perturbation, `gyro_bias_rad_s` (3,) in the IMU frame. Counters of what happened are in
    `counters` (e.g. `nonfinite_updates`: updates dropped because their result was not finite,
    flagged `Status.UPDATE_NONFINITE`). The state attributes (`R_wc`, `P`, `b_c`, ...) are live views
    of the filter's one state array (`state_buffer.py`): copy one to keep it; `Estimate`s are copies.

    The mode (`MekfConfig.mode`) fixes the motion strategy: `visual_imu` and `imu_only` integrate
    the gyro, `visual_only` runs a constant-rate model. `auto` resolves once, to `visual_imu` when
    IMU samples arrived before the first frame and to `visual_only` otherwise.

    Example: a camera at rest, upright, seeing a Manhattan frame aligned with the world.

    >>> import numpy as np
    >>> from uareme_fusion.types import VisualRotation
    >>> filt = Mekf(MekfConfig(mode="visual_imu"))
    >>> t = np.arange(1, 201) / 200.0                    # 1 s of IMU at 200 Hz
    >>> filt.process_imu(t, np.zeros((200, 3)), np.tile([0.0, -9.81, 0.0], (200, 1)))
    >>> R_cm = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])   # camera y down = world -z
    >>> visual = VisualRotation(R_cm, 1e-4 * np.eye(3), cost=0.0, iterations=1, n_valid=1000)
    >>> est = filt.process_frame(1.0, visual)
    >>> bool(np.allclose(est.R_wc @ [0, -1, 0], [0, 0, 1], atol=1e-6))   # image up is world up
    True
    >>> est.R_wm is not None, filt.counters["nonfinite_updates"]        # the scene frame is known
    (True, 0)
    """

    name = "mekf"
    # The nominal state, covariance and accelerometer period live in one array, `x`, which the compiled
    # kernels update in place (`state_buffer.py`); these attributes read and write it.
    R_wc = BufferArray("R_wc")
    R_wm = BufferArray("R_wm")
    b_c = BufferArray("b_c")
    P = BufferArray("P")
    last_gyro_c = BufferArray("last_gyro")
    t_state = BufferScalar(S_T_STATE, optional=True)
    imu_t_s = BufferScalar(S_IMU_T)  # time of the newest integrated IMU sample (camera clock), s; -inf before any
    products_unnormalised = BufferScalar(S_PRODUCTS, int)
    t_visual_s = BufferScalar(S_T_VISUAL, optional=True)  # time of the previous visual update (camera clock), s
    rejections = BufferScalar(S_REJECTIONS, int)  # consecutive frames gated out

    def __init__(self, config: MekfConfig | str | None = None):
        """`config`: a `MekfConfig`, a preset name or YAML path (`Mekf("vehicle")`), or None for the defaults."""
        if isinstance(config, str):
            config = load_config(config, MekfConfig)
        elif config is not None and not isinstance(config, MekfConfig):
            raise TypeError(f"Mekf(config): expected a MekfConfig, a preset name ({', '.join(preset_names())}) or a "
                            f"YAML path, got {type(config).__name__}")
        self.config = cfg = config or MekfConfig()
        self.R_ci = np.asarray(cfg.R_ci, float)
        self.imu_is_camera = bool(np.array_equal(self.R_ci, I3))
        self.q_gyro = cfg.gyro_noise_rad_s_sqrt_hz**2
        self.q_bias = cfg.gyro_bias_rw_rad_s2_sqrt_hz**2
        self.q_rate = cfg.gyro_rate_noise_sqrt_s**2
        self.manhattan_walks = bool(cfg.manhattan_yaw_rw_rad_per_sqrt_s or cfg.manhattan_tilt_rw_rad_per_sqrt_s)
        self.trapezoid = cfg.gyro_sampling == GyroSampling.INSTANT
        self._stream = ImuStream(cfg.reorder_window_s, cfg.gyro_range_rad_s)
        self.set_motion(motion_for(cfg.mode))
        self._mode_resolved = cfg.mode != MekfMode.AUTO
        self.x = new_state_buffer()  # R_wc = R_wm = I, b_c = 0, P = 0, t_state None
        self.views = field_views(self.x)
        self.omega_c = np.zeros(3)
        self.F_buffer = np.eye(N_STATE)  # gyro transition: only its TH rows change between chunks
        self.initialised = False
        self.manhattan_initialised = False
        self._counters = dict(visual_rejected=0, visual_nonfinite=0, visual_ignored=0, reinitialised=0,
                              accel_downweighted=0, accel_skipped=0,
                              imu_gaps=0, imu_ignored=0, visual_updates=0, accel_updates=0,
                              rest_updates=0, nonfinite_updates=0)
        self.flags = status_bits.OK  # `Status` bits gathered since the last estimate (`status_bits.py`)
        self.disagree_since_s: float | None = None  # first frame of the current run of ignored visual rotations, s
        self._disagree_R_cm = None  # visual only: the previous frame of that run (labelled)
        self._disagree_P = None  # the error-state covariance at that frame
        self.in_imu_gap = False  # frames are being extrapolated past `imu_gap_limit_s` of no IMU
        self.pending: list[ImuBatch] = []
        self.pending_span_s = 0.0
        self.init_samples: list[ImuBatch] = []
        self.noise_share = VisualNoiseShare(cfg.visual_noise_share_frames)  # visual only (its `persistent_cov`)
        self.labelling = LabellingTrack()  # visual only: each frame labelled nearest a track of the frames
        self._dropped_reported = 0
        self.accel = AccelPeriod(self.x)
        self.gravity_only = GravityOnly(cfg)  # an accelerometer without gyro (visual only: `process_accel`)
        self.accelerometer_lookahead_s = cfg.accel_only_lookahead_s
        self.record_t: list[np.ndarray] = []
        self.record_R: list[np.ndarray] = []
        self.record_P: list[np.ndarray] = []

    @property
    def counters(self) -> dict[str, int]:
        """What happened so far, by name (updates applied, skipped, rejected, ...)."""
        if self.gravity_only.active:
            self._counters.update(self.gravity_only.counts)
        return self._counters

    @property
    def mode(self) -> MekfMode:
        """The filter's mode (`auto` until resolved)."""
        return self.motion.mode

    def resolve_mode(self, mode: MekfMode) -> None:
        """Fix an `auto` filter's mode (once: later calls and explicit modes are left alone)."""
        if not self._mode_resolved:
            self._mode_resolved = True
            self.set_motion(motion_for(mode))

    def set_motion(self, motion) -> None:
        """Use `motion` (a strategy of `motion.py`)."""
        self.motion = motion

    # ------------------------------------------------------------------ public API
    def process_imu(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        """Feed IMU samples: `t_s` (N,) s on the IMU clock, `gyro_rad_s` (N, 3) rad/s and
        `accel_m_s2` (N, 3) m/s^2 in the IMU frame; see `Backend.process_imu`. Non-finite, duplicate
        and late samples are dropped and counted in `self.stream.counts`."""
        if not self.motion.uses_imu:
            self.counters["imu_ignored"] += int(np.size(t_s))
            return
        if self.config.imu_time_offset_s:
            t_s = np.asarray(t_s, float) + self.config.imu_time_offset_s
        self._add(t_s, gyro_rad_s, accel_m_s2)

    @property
    def uses_image_motion(self) -> bool:
        """Visual only (or not yet known): the labelling track takes the image rotation."""
        return not self._mode_resolved or not self.motion.uses_imu

    def process_accel(self, t_s, accel_m_s2) -> None:
        """Feed accelerometer samples of a sensor without gyro: `t_s` (N,) s on the IMU clock,
        `accel_m_s2` (N, 3) m/s^2 in the IMU frame (`R_ci`). The visual-only model uses them as a
        gravity measurement at each frame (`gravity_only.py`); a gyro-driven mode ignores them."""
        if self._mode_resolved and self.motion.uses_imu:
            self.counters["imu_ignored"] += int(np.size(t_s))
            return
        self.gravity_only.add(t_s, accel_m_s2)

    def _gravity_rows(self):
        """Visual only, with an accelerometer without gyro: its gravity rows `(residual, R, H)` at the
        state time, or None (`gravity_only.py`: the first makes the world gravity-aligned)."""
        if self.motion.uses_imu or not self.initialised or not self.gravity_only.active:
            return None
        rows, bits = self.gravity_only.update_rows(self)
        self.flags |= bits
        return rows

    def _gravity_update(self) -> None:
        """`_gravity_rows` alone, for a frame without a visual update."""
        rows = self._gravity_rows()
        if rows is not None:
            self._kalman_update(*rows)

    def _add(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        """`process_imu`'s samples into the reorder buffer, released once they span an update period."""
        stream = self._stream
        stream.add(t_s, gyro_rad_s, accel_m_s2)
        dropped = stream.counts.dropped  # only `add` drops samples: flagged here, not per estimate
        if dropped > self._dropped_reported:
            self.flags |= status_bits.IMU_DROPPED
            self._dropped_reported = dropped
        self._release_if_period_held()

    def _release_if_period_held(self) -> None:
        """After samples were added: samples wait in the reorder buffer; a frame's `propagate_to` releases
        them, or, in an IMU-only stream, this does once an accelerometer period's worth is older than the
        window (and integrates them)."""
        stream = self._stream
        if stream.held_span_s + self.pending_span_s >= self.config.accel_update_period_s + stream.reorder_window_s:
            self.queue(stream.release_until(stream.newest_s - stream.reorder_window_s, move_watermark=False))
            if self.pending_span_s >= self.config.accel_update_period_s:
                self.motion.integrate_pending(self)

    @property
    def stream(self) -> ImuStream:
        """The IMU reorder buffer."""
        return self._stream

    def flush(self) -> None:
        """Release and integrate every buffered IMU sample (end of an IMU-only stream)."""
        if not self.motion.uses_imu:
            return
        self.queue(self.stream.flush())
        self.motion.integrate_pending(self, force_init=True)
        if self.accel.due:
            self.accel_update()

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        """Propagate to `t_s` (s, camera clock), fuse `visual` (None for a dropped frame) and return
        the estimate. `Estimate.R_wc` maps camera to world (z up); `cov` (3, 3, rad^2) is that of
        the right perturbation of `R_wc`; `gyro_bias_rad_s` is in the IMU frame; `R_wm` is None
        until a Manhattan frame was seen."""
        t_s = float(t_s)
        if visual is not None and not (_shape(visual.R_cm) == _shape(visual.cov) == (3, 3)):
            raise InputError(f"visual rotation at t = {t_s:g} s: expected R_cm and cov of shape (3, 3), got "
                             f"{np.shape(visual.R_cm)} and {np.shape(visual.cov)}")
        if not self._mode_resolved:
            seen_imu = self.initialised or self.pending or self.stream.newest_s > -np.inf or self.init_samples
            self.resolve_mode(MekfMode.VISUAL_IMU if seen_imu else MekfMode.VISUAL_ONLY)
        self.propagate_to(t_s)
        if visual is not None and self.initialised and not self.motion.uses_imu:
            visual = self.labelling.label(t_s, visual)  # `labelling_track.py`: not nearest a prediction that may drift
        fuses_visual = self.motion.fuses_visual
        if visual is not None and self.manhattan_initialised and fuses_visual:
            ignored = self._ignored_too_long(t_s, visual)
            if ignored is None:
                self._visual_update(visual)
                return self._estimate(t_s)
            if ignored:  # else skipped (visual only): the filter coasts
                if not self.motion.uses_imu:
                    self.labelling.start(t_s, visual)
                self._reinitialise(visual)
                self.t_visual_s = t_s
            if self.accel.due:
                self.accel_update()
            self._gravity_update()
            return self._estimate(t_s)
        if self.accel.due:
            self.accel_update()
        self._gravity_update()
        if visual is None or not fuses_visual:
            if fuses_visual:
                self.flags |= status_bits.VISUAL_MISSING
                self.x[S_VISUAL_INFO_RATE] = 0.0  # no share while the camera gives nothing
        elif not _finite(visual):  # never a start
            self.flags |= status_bits.VISUAL_REJECTED
            self.counters["visual_rejected"] += 1
            self.counters["visual_nonfinite"] += 1
        elif not self.initialised:
            self.motion.start_from_visual(self, t_s, visual)
            self._gravity_update()  # (visual only) the first frame's world is gravity's
        elif not self.initialise_manhattan(visual):
            self._count_rejection()
        return self._estimate(t_s)

    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        """`R_cm = R_wc^T R_wm` (3, 3) predicted at `t_s` (s; propagates the filter there); None
        before a Manhattan frame is known."""
        if not self.manhattan_initialised:
            return None
        self.propagate_to(float(t_s))
        return self.R_wc.T @ self.R_wm

    def propagate_to(self, t_s: float) -> None:
        """Propagate the state to `t_s` (s, camera clock) with the mode's motion strategy."""
        if not self.pending and t_s == self.t_state:
            return  # already there (a frame's prediction, then its update); later stamps are late
        self.motion.propagate_to(self, t_s)

    def imu_trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """`(t_s (N,), R_wc (N, 3, 3))` after every integrated IMU sample (camera clock), before the
        accelerometer update that may follow it; needs `record_imu_estimates`."""
        if not self.record_t:
            return np.zeros(0), np.zeros((0, 3, 3))
        return np.concatenate(self.record_t), np.concatenate(self.record_R)

    def imu_trajectory_cov(self) -> np.ndarray:
        """(N, 3, 3) covariance (rad^2, right perturbation of `R_wc`) beside each `imu_trajectory`
        rotation: the one predicted to the end of the chunk that sample was integrated in."""
        return np.concatenate(self.record_P) if self.record_P else np.zeros((0, 3, 3))

    def estimate(self, t_s: float | None = None) -> Estimate:
        """Current estimate (at the state time, or stamped `t_s` s) without consuming status flags."""
        return self._make_estimate(self.t_state if t_s is None else t_s, self.flags)

    # ------------------------------------------------------------------ scheduling helpers
    def queue(self, batch: ImuBatch) -> None:
        """Hold released IMU samples until the motion strategy integrates them."""
        rows = batch.rows
        if rows.shape[0]:
            self.pending.append(batch)
            self.pending_span_s = float(rows[-1, 0] - self.pending[0].rows[0, 0]) + 1e-12

    def count_product(self) -> None:
        """One more product into R_wc / R_wm: re-orthonormalise them every `ORTHONORMALISE_EVERY`."""
        self.products_unnormalised += 1
        if self.products_unnormalised >= ORTHONORMALISE_EVERY:
            self.R_wc = orthonormal(self.R_wc)
            self.R_wm = orthonormal(self.R_wm)
            self.products_unnormalised = 0

    # ------------------------------------------------------------------ updates
    def accel_update(self) -> None:
        """Apply the accelerometer (and zero-rate) update of the period just completed."""
        rows = self._take_accel_rows()
        if rows is not None:
            self._kalman_update(*rows)

    def _take_accel_rows(self):
        """The due accelerometer update's `_accel_rows`, for a stacked update (no longer due)."""
        self.accel.due = False
        return self._accel_rows()

    def _accel_rows(self):
        """The period's zero-rate update (applied at once, with `rest_gyro_max_rad_s`), then the
        gravity measurement of its mean (or low-passed) direction: `(residual, R, H)` or None (near
        free fall). Consumes the period. """
        cfg = self.config
        accel_c, T = self.accel.take_mean()
        if cfg.rest_gyro_max_rad_s > 0:
            rows = self.accel.rest_measurement(T, self.t_state, self.b_c, cfg, self.q_gyro)
            if rows is not None:
                self._kalman_update(*rows)
                self.counters["rest_updates"] += 1
        accel_c = self.accel.lowpass(accel_c, T, cfg.accel_lowpass_tau_s)
        use_lp_J = cfg.accel_lowpass_tau_s > 0
        ok, r, var, H, downweighted = gravity_model(
            accel_c, T, self.R_wc, self.accel.lp_J[1], use_lp_J, cfg.gravity_m_s2,
            cfg.accel_tilt_noise_rad_sqrt_s, cfg.accel_norm_scale, cfg.accel_innovation_scale_rad,
            cfg.accel_downweight_flag_ratio)
        if not ok:
            self.counters["accel_skipped"] += 1
            return None
        note_accel_information(self.views["s"], var, T)
        if downweighted:
            self.flags |= status_bits.ACCEL_DOWNWEIGHTED
            self.counters["accel_downweighted"] += 1
        self.counters["accel_updates"] += 1
        return r, var * I3, H

    def _visual_update(self, visual: VisualRotation) -> None:
        """The frame's rotation as a measurement of `R_cm`, gated and Huber-weighted, its covariance
        and the vertical pseudo-measurement's variance as far as the camera is trusted
        (`source_trust.py`), stacked with the vertical pseudo-measurement and a due accelerometer
        update (`_accel_rows`) into one update; past the gate, the accelerometer rows alone."""
        cfg = self.config
        r, R_vis, H = self._visual_model(visual)
        t_s, t_prev_s = self.t_state, self.t_visual_s
        self.t_visual_s = t_s
        trust, var_v = (self._visual_trust(r, R_vis, t_s, t_prev_s) if self.motion.uses_imu
                        else (1.0, cfg.manhattan_vertical_std_rad**2))
        accel_rows = None
        if self.accel.due:
            rest_before = self.counters["rest_updates"]
            accel_rows = self._take_accel_rows()
            if self.counters["rest_updates"] > rest_before:  # the zero-rate update moved the state
                r, R_vis, H = self._visual_model(visual)
        else:
            accel_rows = self._gravity_rows()  # an accelerometer without gyro (visual only)
        if t_prev_s is not None:
            R_vis = R_vis * correlated_noise_scale(t_s - t_prev_s, cfg.visual_error_correlation_s)
        S = H @ self.P @ H.T + R_vis  # the gate and Huber weigh the frame's full error
        try:
            d2 = float(r @ np.linalg.solve(S, r))
        except np.linalg.LinAlgError:  # a singular innovation covariance: no usable measurement
            d2 = np.inf
        if not np.isfinite(d2) or d2 > cfg.visual_gate_chi2:
            self._count_rejection()
            self.x[S_VISUAL_INFO_RATE] = 0.0
            if not _finite(visual):
                self._count_nonfinite()
            if accel_rows is not None:
                self._kalman_update(*accel_rows)
            if self.rejections >= cfg.reinit_after_rejections:
                self._reinitialise(visual)
            return
        self.rejections = 0
        shared = not self.motion.uses_imu and self.noise_share.enabled
        if shared:  # fuse the independent share only (as estimated over the previous frames)
            R_vis = R_vis * self.noise_share.share
            self.noise_share.take(t_s, visual)  # labelled by the track (`labelling_track.py`)
        d = np.sqrt(d2)
        if d > cfg.visual_huber_k:  # Huber weight w = k / d  ->  covariance / w
            R_vis = R_vis * (d / cfg.visual_huber_k)
        if trust != 1.0:  # the independent share of the frame's error (gated on the full one)
            R_vis = R_vis * trust
        # "m's z is up" only where the world is not the Manhattan frame itself (visual only).
        vertical = (vertical_model(self.R_wm, np.sqrt(var_v), cfg.manhattan_vertical_max_rad)
                    if self.motion.uses_imu and var_v < np.inf else None)
        self._kalman_update(*stack([(r, R_vis, H), vertical, accel_rows]))
        self.counters["visual_updates"] += 1

    def _visual_model(self, visual: VisualRotation):
        """`measurements.visual_model` of the frame: labelled nearest the prediction with an IMU, as the
        track labelled it without (`labelling_track.py`)."""
        return visual_model(self.R_wc, self.R_wm, visual.R_cm, visual.cov, relabel=self.motion.uses_imu)

    def _visual_trust(self, r: np.ndarray, R_vis: np.ndarray, t_s: float, t_prev_s: float | None):
        """The camera's vertical against a quiet accelerometer's, taken into the running trust
        (`source_trust.py`): `(share, vertical_var)`, the factor on this frame's visual covariance and the
        vertical pseudo-measurement's variance (rad^2; inf: not applied)."""
        cfg, s = self.config, self.views["s"]
        var_v = cfg.manhattan_vertical_std_rad**2
        quiet = (cfg.accel_downweight_flag_ratio * cfg.accel_tilt_noise_rad_sqrt_s) ** 2
        e, v = visual_vertical_innovation(self.R_wc, self.R_wm, r, R_vis, self.accel.sum_c, self.accel.time_s,
                                          s[S_ACCEL_VAR_RATE], quiet, var_v)
        share, _ = update_visual_trust(s, e, v, cfg.visual_trust_frames, cfg.visual_trust_min_share,
                                       squared_rate(self.last_gyro_c, self.b_c))
        var_v = vertical_variance(s, var_v, cfg.visual_trust_frames)
        note_visual_information(s, R_vis, share, var_v, 0.0 if t_prev_s is None else t_s - t_prev_s)
        return share, var_v

    def _ignored_too_long(self, t_s: float, visual: VisualRotation) -> bool | None:
        """Whether the camera has been ignored long enough to re-initialise from `visual`, decided once
        per frame before either update path (reference or compiled) runs. A frame disagrees when its
        `R_cm`, labelled nearest the prediction, is further from it than the prediction's and its own
        covariance allow (d^2 over `disagreement_chi2` and angle over `disagreement_min_deg`): the gate
        then rejects it, or the Huber weight lets it move the estimate little, and persistent disagreement is drift the
        other flags do not show. Such a frame is flagged `VISUAL_IGNORED`; after
        `reinit_after_disagreement_s` (s) of them in a row, True (re-initialise). None: fuse the frame
        as usual (it agrees, or the IMU's gate and Huber weight handle it). False: skip it, without an
        IMU, where fusing a large innovation would also corrupt the constant-rate model's rate and
        spin the estimate away; the filter coasts. A non-finite frame changes nothing."""
        if not _finite(visual):
            return None
        cfg = self.config
        r, R_vis, H = self._visual_model(visual)
        angle = float(np.linalg.norm(r))
        try:
            # During a run, the covariance of its start: coasting grows P, and must not let the wrong
            # rotations in as a jump.
            P = self.P if self.disagree_since_s is None else self._disagree_P
            d2 = float(r @ np.linalg.solve(H @ P @ H.T + R_vis, r))
        except np.linalg.LinAlgError:
            d2 = np.inf
        # Without an IMU a gated-out frame is a disagreement too: the filter coasts through both alike.
        chi2 = cfg.disagreement_chi2 if self.motion.uses_imu else min(cfg.disagreement_chi2, cfg.visual_gate_chi2)
        if not (angle > np.radians(cfg.disagreement_min_deg) and not d2 <= chi2):
            self.disagree_since_s = self._disagree_R_cm = None
            return None
        # Without an IMU, a run re-initialises only on frames that agree with each other (the camera
        # turned, or the filter drifted): two wrong minima in a row point different ways.
        previous, self._disagree_R_cm = self._disagree_R_cm, visual.R_cm
        consistent = self.motion.uses_imu or (
            previous is not None and float(angle_between(previous, visual.R_cm)) < 0.5 * angle)
        self.flags |= status_bits.VISUAL_IGNORED
        self._counters["visual_ignored"] += 1
        if self.disagree_since_s is None:
            self.disagree_since_s, self._disagree_P = t_s, self.P.copy()
        limit_s = cfg.reinit_after_disagreement_s if self.motion.uses_imu else cfg.visual_only_reinit_after_s
        if t_s - self.disagree_since_s >= limit_s and consistent:
            return True
        return None if self.motion.uses_imu else False

    def _reinitialise(self, visual: VisualRotation) -> None:
        """After `reinit_after_rejections` frames gated out in a row, or `reinit_after_disagreement_s`
        of visual rotations ignored (`_ignored_too_long`): a new scene alignment from `visual`."""
        self.disagree_since_s = self._disagree_R_cm = None
        self.flags |= status_bits.REINITIALISED
        self.counters["reinitialised"] += 1
        self.motion.reinitialise(self, visual)

    def _count_nonfinite(self) -> None:
        """A gated-out frame whose rotation or covariance is not finite: counted apart
        (`visual_nonfinite`), and not a disagreement that leads to a re-initialisation."""
        self.counters["visual_nonfinite"] += 1
        self.rejections -= 1

    def _count_rejection(self) -> None:
        self.flags |= status_bits.VISUAL_REJECTED
        self.counters["visual_rejected"] += 1
        self.rejections += 1

    def _kalman_update(self, residual: np.ndarray, R: np.ndarray, H: np.ndarray) -> None:
        """filterpy update (Joseph form) of the zero-mean error state, then inject and reset. A
        non-finite result changes nothing; it is counted and flagged."""
        dx, P = kf_update(ZERO_STATE, self.P, residual, R, H)
        if not (np.isfinite(dx).all() and np.isfinite(P).all()):
            self.counters["nonfinite_updates"] += 1
            self.flags |= status_bits.UPDATE_NONFINITE
            return
        G = reset_jacobian(dx, self.manhattan_initialised)
        self.R_wc, self.R_wm, self.b_c, self.omega_c = inject(
            self.R_wc, self.R_wm, self.b_c, self.omega_c, dx, self.manhattan_initialised, self.motion.estimates_rate)
        self.count_product()
        self.accel.reinject(dx[BG])
        P = G @ P @ G.T
        self.P = 0.5 * (P + P.T)

    # ------------------------------------------------------------------ initialisation
    def initialise_manhattan(self, visual: VisualRotation, R_wm_ref: np.ndarray | None = None) -> bool:
        """`R_wm = R_wc R_cm`, labelled nearest `R_wm_ref` (3, 3; identity: m's z nearest up), with
        its covariance from the camera's and the measurement's: `dtheta_m = R_cm^T dtheta_c + delta`.
        The first frame with an IMU is refused (returns False, state kept) when its z axis is near
        up but fails the vertical pseudo-measurement's gate (`visual_gate_chi2`): it contradicts the
        accelerometer's tilt, and the pseudo-measurement would tilt the camera to it. A
        re-initialisation is not gated: then the filter's own tilt may be the wrong one."""
        cfg = self.config
        R_wm_ref = np.eye(3) if R_wm_ref is None else R_wm_ref
        visual = visual.symmetric_to(self.R_wc.T @ R_wm_ref)
        R_wm = orthonormal(self.R_wc @ visual.R_cm)
        T = np.eye(N_STATE)
        T[MF, MF] = 0.0
        T[MF, TH] = visual.R_cm.T
        P = T @ self.P @ T.T
        P[MF, MF] += visual.cov
        if self.motion.uses_imu and not self.manhattan_initialised:
            d2 = vertical_distance2(R_wm, P[MF, MF], cfg.manhattan_vertical_std_rad, cfg.manhattan_vertical_max_rad)
            if d2 is not None and not d2 <= cfg.visual_gate_chi2:
                return False
        self.R_wm = R_wm
        self.P = 0.5 * (P + P.T)
        self.manhattan_initialised = True
        self.rejections = 0
        return True

    # ------------------------------------------------------------------ output
    def _estimate(self, t_s: float) -> Estimate:
        est = self._make_estimate(t_s, self.flags)
        self.flags = status_bits.OK
        return est

    def _bias_in_imu(self, b_c: np.ndarray) -> np.ndarray:
        """The gyro bias `b_c` (3,) rad/s (camera frame, a copy) in the IMU frame."""
        return b_c if self.imu_is_camera else self.R_ci.T @ b_c

    def _make_estimate(self, t_s, bits: int) -> Estimate:
        """The estimate of the state now, stamped `t_s`, with the `Status` of the flag `bits`."""
        if not self.initialised:
            return Estimate(t_s, np.eye(3), np.eye(3), status_of(bits | status_bits.NOT_INITIALISED))
        # The fewest Python steps (a frame's estimate runs between solver calls, where each costs about
        # a microsecond, and a numba call more): one gather copies R_wc, R_wm, P[TH, TH], its transpose, b_c.
        R_wc, R_wm, P_th, P_th_T, b_c = self.x.take(_ESTIMATE_INDEX)
        cov = P_th + P_th_T  # into a new array: in place, numpy would check two views of one array for overlap
        cov *= 0.5
        if not self.motion.uses_imu:
            cov += self.noise_share.persistent_cov
            bias_i, shares = None, _CAMERA_ONLY
        else:
            bias_i, shares = self._bias_in_imu(b_c[0]), tilt_shares(self.views["s"])
        return Estimate(t_s, R_wc, cov, status_of(bits), R_wm if self.manhattan_initialised else None, bias_i, shares)
