"""An accelerometer without a gyro (TUM's Kinect, some phones and boards) as a gravity measurement of
`Mekf`'s visual-only model.

Without a gyro nothing integrates between frames: the constant-rate model (`motion.ConstantRateMotion`)
carries the attitude, and at each frame the accelerometer samples of a window around it
(`accel_only_window_s`, ending `accel_only_lookahead_s` after the frame) are averaged into one
direction that measures up in the camera frame, through the same model as with a gyro
(`measurements.gravity_model`: gated by its own norm, inflated by its innovation). The samples are
turned to the frame's time with the model's rate (`omega_c`; the rate's error enters H), since the
camera turns within the window. What a gyro's common frame would cancel (a handheld camera's
shaking) is averaged here, and the update is also inflated by the samples' rms deviation from their
mean (`accel_only_shake_m_s2`: rest against motion) and by the overlap of successive windows
(`correlated_noise_scale`). It is skipped when a sample is at the range (`accel_range_m_s2`:
saturated, flagged `ACCEL_DOWNWEIGHTED`) or when the stream stopped (no sample within
`imu_gap_limit_s` of the window's end: flagged `IMU_GAP`); the camera carries on alone.

The visual-only world is the first Manhattan frame, its z the axis nearest image up. The first gravity
update relabels it so that z is the Manhattan axis nearest the measured up (`gravity_world`) and gives
the Manhattan frame a tilt prior (`manhattan_vertical_std_rad`, "walls are vertical") shared with the
camera attitude (`world_tilt_prior`): from then on the world's z is up.

The noise density (`accel_only_noise_rad_sqrt_s`) is a handheld camera's, fitted on the real TUM fr1 rpy
training frames: the Kinect's accelerometer reads the camera's accelerations too (its 0.2 s mean direction
errs 2.7 deg there with the true rotation known). Learning it per run from the data was tried and is not
used (same frames, mekf, tilt after the alignment, depth / learned normals, measured with the learned
normals' visual bias cap then at 0.15 of the frame's variance (0.3 since); fixed 0.015 then: 1.48 / 1.82 deg):
- from the gravity update's own innovations (Mehra's `mean |r|^2 - H P H^T`, over 30-240 frames): the error
  lasts longer than a window (the camera's swing) and the prediction follows it, so the innovations stay
  small and the accelerometer over-trusted (1.55-1.69 / 1.80-2.17 deg, NEES 11-50);
- from its disagreement with each frame's own up (`R_cm R_wm^T up`) less the frame's covariance on those
  axes: the depth frames' covariance (2-27 deg) exceeds the disagreement (1-6 deg), which leaves nothing;
- the whole disagreement put on the accelerometer, capped at 0.05 rad: 1.43 / 1.75 deg on TUM, but a
  still accelerometer beside a noisy or leaning camera is then weighted as the camera errs (the seeded
  tilt NEES and the tilted-Manhattan-frame tests here fail: tilt 2.8 deg where the lean should be learned);
- the varying part of that disagreement in the world frame (the scene's lean left out) less the camera's
  frame-to-frame noise (`u_k - R_cp u_(k-1)`), capped at 0.05 rad, floor 0.001 (branch kinect16-trust):
  the tests here pass, training frames 1.48 / 1.80 deg (NEES 6.01 / 3.28), a tie with the fixed 0.015
  (NEES 5.45 / 3.19); evaluation frames 1.12 / 2.55 against 1.33 / 2.33, their first 60 (depth) 1.33
  against 1.37 without the accelerometer (the fixed one: 1.14). Not taken: no better where it was tuned."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...rotations import manhattan_symmetries, skew
from . import status_bits
from .image_rotation_motion import bias_std_rad
from .measurements import correlated_noise_scale, gravity_model
from .source_trust import note_accel_information, note_visual_information
from .state import I3, MF, N_STATE, RATE, TH

KEEP_S = 1.0
"""Samples older than the window by this much are dropped from the buffer, s."""


def world_tilt_prior(P: np.ndarray, R_wc: np.ndarray, R_wm: np.ndarray, std_rad: float) -> np.ndarray:
    """The error covariance (12, 12) with the world's tilt made uncertain by `std_rad` (rad, about world
    x and y): a world rotation `Exp(delta)` moves both `R_wc` and `R_wm`, whose right perturbations
    take `R_wc^T delta` and `R_wm^T delta`."""
    J = np.zeros((N_STATE, 3))
    J[TH], J[MF] = R_wc.T, R_wm.T
    P = P + std_rad**2 * J[:, :2] @ J[:, :2].T
    return 0.5 * (P + P.T)


class GravityOnly:
    """Accelerometer samples without gyro (camera frame, camera clock), and the per-frame gravity rows.

    `add(t_s, accel_m_s2)` takes samples on the IMU clock and in the IMU frame (`MekfConfig.R_ci`,
    `imu_time_offset_s`); `update_rows(filt)` gives a frame's measurement. `counts`: samples dropped
    (non-finite, out of order), updates made, skipped (free fall), saturated windows, and frames with
    the stream stopped.
    """

    def __init__(self, cfg):
        self.R_ci = np.asarray(cfg.R_ci, float)
        self.offset_s = float(cfg.imu_time_offset_s)
        self.t_s = np.zeros(0)
        self.accel_c = np.zeros((0, 3))
        self.counts = dict(accel_only_dropped=0, accel_only_updates=0, accel_only_skipped=0,
                           accel_only_saturated=0, accel_only_stopped=0)
        self._t_update_s: float | None = None
        self.world_aligned = False
        """Whether the world was relabelled to gravity (`update_rows`, once)."""

    @property
    def active(self) -> bool:
        """Whether samples ever came (a run without them never looks here)."""
        return self.t_s.size > 0 or self._t_update_s is not None or self.counts["accel_only_dropped"] > 0

    def add(self, t_s, accel_m_s2) -> None:
        t = np.asarray(t_s, float).reshape(-1) + self.offset_s
        a = np.asarray(accel_m_s2, float).reshape(-1, 3)
        newest = self.t_s[-1] if self.t_s.size else -np.inf
        keep = np.isfinite(t) & np.isfinite(a).all(axis=1)
        keep[keep] &= t[keep] > np.maximum.accumulate(np.concatenate([[newest], t[keep][:-1]]))
        self.counts["accel_only_dropped"] += int((~keep).sum())
        self.t_s = np.concatenate([self.t_s, t[keep]])
        self.accel_c = np.concatenate([self.accel_c, a[keep] @ self.R_ci.T])

    def update_rows(self, filt):
        """`gravity_rows`, and no tilt share for the accelerometer while it gives nothing (`Estimate.tilt_shares`)."""
        rows, bits = self.gravity_rows(filt)
        if rows is None:
            filt.views["s"].accel_info_rate = 0.0
        return rows, bits

    def gravity_rows(self, filt):
        """The gravity measurement of filter `filt` (a visual-only `Mekf`) at its state time from the
        samples of the trailing window: `((residual (3,), R (3, 3), H (3, 12)) or None, status bits)`.
        The first one relabels the world so that its z is the Manhattan axis nearest the measured up
        (`gravity_world`); whenever the Manhattan frame is certain (first, and after a re-initialisation)
        the world's tilt gets its prior (`world_tilt_prior`)."""
        cfg, t_s = filt.config, filt.t_state
        mean, dmean_domega, covered_s, shake2, bits = self.window_mean(t_s, filt.omega_c, cfg)
        if mean is None:
            return None, bits
        if not np.linalg.norm(mean) > 0.1 * cfg.gravity_m_s2:  # free fall: no direction
            self.counts["accel_only_skipped"] += 1
            return None, bits
        if not self.world_aligned:
            S = gravity_world(filt.R_wc @ mean)
            filt.R_wc, filt.R_wm = S @ filt.R_wc, S @ filt.R_wm
            self.world_aligned = True
        if not filt.P[MF, MF].any():
            filt.P = world_tilt_prior(filt.P, filt.R_wc, filt.R_wm, cfg.manhattan_vertical_std_rad)
        gravity, downweighted = gravity_model(
            mean, covered_s, filt.R_wc, np.zeros((3, 3)), False, cfg.gravity_m_s2, cfg.accel_only_noise_rad_sqrt_s,
            cfg.accel_norm_scale, cfg.accel_only_innovation_scale_rad, cfg.accel_downweight_flag_ratio)
        r, var, H = gravity.residual, gravity.covariance[0, 0], gravity.jacobian  # covariance var I
        z = mean / np.linalg.norm(mean)
        H[:, RATE] = -(I3 - np.outer(z, z)) @ dmean_domega / np.linalg.norm(mean)  # z = normalise(mean(omega))
        shake_factor = 1.0 + shake2 / cfg.accel_only_shake_m_s2**2
        dt = np.inf if self._t_update_s is None else t_s - self._t_update_s
        var *= shake_factor * correlated_noise_scale(dt, cfg.accel_only_window_s)
        # Its tilt information per second (`Estimate.tilt_shares`): one update of `var` per `dt` (the first,
        # per window); overlapping windows are counted once by the scale above.
        note_accel_information(filt.views["s"], var, dt if np.isfinite(dt) else cfg.accel_only_window_s)
        self._t_update_s = t_s
        self.counts["accel_only_updates"] += 1
        if downweighted or shake_factor > cfg.accel_downweight_flag_ratio**2:
            bits |= status_bits.ACCEL_DOWNWEIGHTED
        return (r, var * I3, H), bits

    @staticmethod
    def note_visual_information(filt, visual, scale: float, t_previous_s) -> None:
        """The camera's tilt information per second beside this accelerometer (`Estimate.tilt_shares`), as
        with an IMU (`source_trust.note_visual_information`): the frame's tilt variance as fused (`scale`
        times its own, on the Manhattan frame's x and y axes) plus what the Manhattan frame's lean from
        gravity may be, the visual bias's variance when it is a state (`ImageRotationMotion.has_bias`), else
        the walls-vertical prior's (`manhattan_vertical_std_rad`), one frame per the time since the previous
        visual update (`t_previous_s`, s; None: the first) of the visual-only filter `filt`."""
        cfg = filt.config
        lean_std_rad = bias_std_rad(cfg, visual) if filt.motion.has_bias(filt) else cfg.manhattan_vertical_std_rad
        dt_s = filt.t_state - t_previous_s if t_previous_s is not None else 0.0
        note_visual_information(filt.views["s"], np.asarray(visual.cov) * scale, 1.0, lean_std_rad**2, dt_s)

    def window_mean(self, t_s: float, omega_c: np.ndarray, cfg):
        """`(mean specific force (3,) m/s^2 or None, its derivative by the rate (3, 3) s*m/s^2, time it
        covers s, mean squared deviation of the samples from it (m/s^2)^2, status bits)` of the samples
        in the trailing window before `t_s` (s), each turned to `t_s` with the rate `omega_c` (3,) rad/s:
        `v_c(t_s) = Exp(omega (t_k - t_s)) v_c(t_k)`, whose derivative by omega is about
        `-(t_k - t_s) skew(v_c)`. None when the stream stopped (`IMU_GAP`) or a sample is saturated
        (`ACCEL_DOWNWEIGHTED`)."""
        window = cfg.accel_only_window_s
        old = int(np.searchsorted(self.t_s, t_s - window - KEEP_S))
        if old:
            self.t_s, self.accel_c = self.t_s[old:], self.accel_c[old:]
        ahead = cfg.accel_only_lookahead_s
        lo, hi = np.searchsorted(self.t_s, [t_s + ahead - window, t_s + ahead], side="right")
        if hi == 0 or t_s + ahead - self.t_s[hi - 1] > cfg.imu_gap_limit_s:  # the stream stopped (or not started)
            self.counts["accel_only_stopped"] += 1
            return None, None, 0.0, 0.0, status_bits.IMU_GAP
        t, a = self.t_s[lo:hi], self.accel_c[lo:hi]
        if (np.abs(a) >= cfg.accel_range_m_s2).any():
            self.counts["accel_only_saturated"] += 1
            return None, None, 0.0, 0.0, status_bits.ACCEL_DOWNWEIGHTED
        tau = t - t_s
        if not cfg.accel_only_turn_samples:
            tau = np.zeros_like(tau)
        a_s = Rotation.from_rotvec(np.outer(tau, omega_c)).apply(a)
        mean = a_s.mean(axis=0)
        covered_s = max(min(window, t[-1] - t[0]), window / 2 if t.size == 1 else 1e-3)
        return (mean, -skew((tau[:, None] * a_s).mean(axis=0)), covered_s,
                float(((a_s - mean) ** 2).sum(axis=1).mean()), status_bits.OK)


def gravity_world(up_w: np.ndarray) -> np.ndarray:
    """The Manhattan relabelling `S` (3, 3; one of the 24, nearest identity) of a world that is a
    Manhattan frame, whose z is the axis nearest the measured up `up_w` (3,): the new world is `S` times the old."""
    G = manhattan_symmetries()
    return G[int(np.argmax(G[:, 2] @ up_w))].copy()
