"""The EKF's oracle: the numpy/scipy/filterpy reference of `uareme_fusion.backends.mekf.Mekf`, which
the tests run beside the production filter (its kernels) on the same streams.

`Mekf` here is the production filter with its maths done by the reference instead of the kernels: the
propagation (`motion.py`: numpy chunks, filterpy `predict`), the accelerometer period (`accel.py`),
the accelerometer, zero-rate, gravity and visual updates and the disagreement test (below: scipy's
rotations, filterpy's Joseph-form `update`, the error injected with `state.inject` and reset). The
scheduling (buffers, modes, initialisation, re-initialisation, flags, estimates) is the production
filter's, inherited, so that a difference between the two is one of the maths.
"""

from __future__ import annotations

import numpy as np
from filterpy.kalman import update as kf_update

from uareme_fusion.backends.base import Backend
from uareme_fusion.backends.mekf import filter as production
from uareme_fusion.backends.mekf import status_bits
from uareme_fusion.backends.mekf.config import MekfMode
from uareme_fusion.backends.mekf.source_trust import (note_accel_information, note_visual_information,
                                                      share_tilt_covariance, squared_rate,
                                                      update_visual_trust, vertical_variance,
                                                      visual_vertical_innovation)
from uareme_fusion.backends.mekf.state import BG, N_STATE, ORTHONORMALISE_EVERY, ZERO_STATE, orthonormal, reset_jacobian
from uareme_fusion.types import VisualRotation

from .accel import AccelPeriod
from .measurements import correlated_noise_scale, gravity_model, stack, vertical_model, visual_model
from .motion import ConstantRateMotion, GyroMotion, ImageRotationMotion
from .state import inject


def motion_for(mode: MekfMode, image_rotation: bool = False):
    """The oracle's motion strategy of a mode (visual only, by the image rotation with `image_rotation`)."""
    if mode != MekfMode.VISUAL_ONLY:
        return GyroMotion(mode)
    return ImageRotationMotion() if image_rotation else ConstantRateMotion()


class Mekf(production.Mekf):
    """`production.Mekf` on the reference maths (module docstring)."""

    def __init__(self, config=None):
        super().__init__(config)
        self.accel = AccelPeriod(self.x)
        self.F_buffer = np.eye(12)  # gyro transition: only its TH rows change between chunks
        self.set_motion(motion_for(self.motion.mode, self.config.visual_only_image_rotation))

    def set_motion(self, motion) -> None:
        """The oracle's strategy for `motion`'s mode; no stage (each batch goes through the stream)."""
        if not isinstance(motion, (ConstantRateMotion, GyroMotion, ImageRotationMotion)):
            motion = motion_for(motion.mode, self.config.visual_only_image_rotation)
        super().set_motion(motion)
        self._stages_frames = False

    def resolve_mode(self, mode: MekfMode) -> None:
        if not self._mode_resolved:
            self._mode_resolved = True
            self.set_motion(motion_for(mode, self.config.visual_only_image_rotation))

    def warm_up(self, has_imu: bool, has_frames: bool) -> None:
        """Nothing to compile."""

    def process_imu_segments(self, t_s, gyro_rad_s, accel_m_s2, ends):
        """Segment by segment (`Backend.process_imu_segments`)."""
        return Backend.process_imu_segments(self, t_s, gyro_rad_s, accel_m_s2, ends)

    def count_product(self) -> None:
        """One more product into R_wc / R_wm: re-orthonormalise them every `ORTHONORMALISE_EVERY`."""
        self.products_unnormalised += 1
        if self.products_unnormalised >= ORTHONORMALISE_EVERY:
            self.R_wc = orthonormal(self.R_wc)
            self.R_wm = orthonormal(self.R_wm)
            self.products_unnormalised = 0

    def _gravity_update(self) -> None:
        """`_gravity_rows` alone, for a frame without a visual update."""
        rows = self._gravity_rows()
        if rows is not None:
            self._kalman_update(*rows)

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
        (ok, r, R, H), downweighted = gravity_model(
            accel_c, T, self.R_wc, self.accel.lp_J[1], use_lp_J, cfg.gravity_m_s2,
            cfg.accel_tilt_noise_rad_sqrt_s, cfg.accel_norm_scale, cfg.accel_innovation_scale_rad,
            cfg.accel_downweight_flag_ratio)
        if not ok:
            self.counters["accel_skipped"] += 1
            return None
        note_accel_information(self.views["s"], R[0, 0], T)
        if downweighted:
            self.flags |= status_bits.ACCEL_DOWNWEIGHTED
            self.counters["accel_downweighted"] += 1
        self.counters["accel_updates"] += 1
        return r, R, H

    def _visual_update(self, visual: VisualRotation) -> None:
        """The frame's rotation as a measurement of `R_cm`, gated and Huber-weighted, its covariance
        and the vertical pseudo-measurement's variance as far as the camera is trusted
        (`source_trust.py`), stacked with the vertical pseudo-measurement and a due accelerometer
        update (`_accel_rows`) into one update; past the gate, the accelerometer rows alone."""
        cfg = self.config
        r, R_vis, H = self._visual_model(visual)
        share = self.motion.visual_noise_scale(self) if not self.motion.uses_imu else 1.0  # before t_visual_s moves
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
            self.views["s"].visual_info_rate = 0.0
            if not visual.is_finite():
                self._count_nonfinite()
            if accel_rows is not None:
                self._kalman_update(*accel_rows)
            if self.rejections >= cfg.reinit_after_rejections:
                self._reinitialise(visual)
            return
        self.rejections = 0
        shared = not self.motion.uses_imu and self.noise_share.enabled
        if shared:  # fuse the independent share only (as estimated over the previous frames)
            R_vis = R_vis * share
            self.noise_share.take(t_s, visual)  # labelled by the track (`labelling_track.py`)
        d = np.sqrt(d2)
        if d > cfg.visual_huber_k:  # Huber weight w = k / d  ->  covariance / w
            R_vis = R_vis * (d / cfg.visual_huber_k)
        if trust != 1.0:  # the independent share of the frame's tilt error (gated on the full one)
            R_vis = np.array(R_vis, float)
            share_tilt_covariance(R_vis, trust, self.R_wm)
        # "m's z is up" only where the world is not the Manhattan frame itself (visual only).
        vertical = None
        if self.motion.uses_imu and var_v < np.inf:
            ok, *rows = vertical_model(self.R_wm, np.sqrt(var_v), cfg.manhattan_vertical_max_rad)
            vertical = rows if ok else None
        bias_gain = 1.0  # the frames' persistent error, as the gyro bias sees it: a partial update of BG
        if self.motion.uses_imu and t_prev_s is not None:
            bias_gain = 1.0 / correlated_noise_scale(t_s - t_prev_s, cfg.gyro_bias_visual_correlation_s)
        self._kalman_update(*stack([(r, R_vis, H), vertical, accel_rows]), bias_gain=bias_gain)
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
                                          s.accel_var_rate, quiet, var_v)
        share, _ = update_visual_trust(s, e, v, cfg.visual_trust_frames, cfg.visual_trust_min_share,
                                       squared_rate(self.last_gyro_c, self.b_c))
        var_v = vertical_variance(s, var_v, cfg.visual_trust_frames)
        note_visual_information(s, R_vis, share, var_v, 0.0 if t_prev_s is None else t_s - t_prev_s)
        return share, var_v

    def _fuse_visual(self, visual: VisualRotation) -> bool:
        """The reference visual update (`_visual_update`); the estimate is made from the state after it."""
        self._visual_update(visual)
        return False

    def visual_distance(self, visual: VisualRotation, P: np.ndarray) -> tuple[float, float]:
        """`(angle, d2)` of a frame against the prediction, by the reference visual model."""
        r, R_vis, H = self._visual_model(visual)
        try:
            d2 = float(r @ np.linalg.solve(H @ P @ H.T + R_vis, r))
        except np.linalg.LinAlgError:
            d2 = np.inf
        return float(np.linalg.norm(r)), d2

    def _kalman_update(self, residual: np.ndarray, R: np.ndarray, H: np.ndarray, bias_gain: float = 1.0) -> None:
        """filterpy update (Joseph form) of the zero-mean error state, then inject and reset; with
        `bias_gain` != 1 the bias's gain on the first three rows scaled by it and the Joseph form written out (filterpy takes
        the optimal gain only). A non-finite result changes nothing; it is counted and flagged."""
        if bias_gain == 1.0:
            dx, P = kf_update(ZERO_STATE, self.P, residual, R, H)
        else:
            with np.errstate(all="ignore"):
                K = self.P @ H.T @ np.linalg.inv(H @ self.P @ H.T + R)  # as filterpy
                K[BG, :3] *= bias_gain  # the frame's rotation rows, stacked first
                A = np.eye(N_STATE) - K @ H
                dx, P = K @ residual, A @ self.P @ A.T + K @ R @ K.T
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
