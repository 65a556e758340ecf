"""The gyro-aided variant of the sliding-window smoother (see `backends/smoother.py`, "Gyro-aided mode").

Between consecutive frames an `AHRSFactor` from gyro preintegration, a random walk of the gyro bias
`B(k)`, and an `AttitudeFactorRot3` from the mean accelerometer direction; the world is gravity
aligned and the Manhattan frame `R_wm` is a variable `M` kept in the window.
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, X

from ..rotations import WORLD_UP
from ..types import VisualRotation
from .imu_stream import check_imu_arrays
from .smoother import MANHATTAN_KEY, Smoother, _robust, label_up_as_z


class GyroSmoother(Smoother):
    """Gyro-aided graph: gyro preintegration, gravity factors, a Manhattan-frame variable and a gyro
    bias per frame (IMU samples in the IMU frame, rotated to the camera by `R_ci`)."""

    name = "smoother-gyro"

    def __init__(self, config=None):
        self._t_imu: float | None = None
        super().__init__(config)

    # ----------------------------------------------------------------------------- IMU
    def _reset_interval(self) -> None:
        if not hasattr(self, "_pim_params"):
            self._pim_params = gtsam.PreintegratedRotationParams()
            self._pim_params.setGyroscopeCovariance(self.config.gyro_noise_rad_s_sqrt_hz**2 * np.eye(3))
        self._pim = gtsam.PreintegratedAhrsMeasurements(self._pim_params, self._bias)
        self._accel_c: list[np.ndarray] = []
        self._gyro_c: list[np.ndarray] = []

    def process_imu(self, t_s: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray) -> None:
        """Preintegrate gyro samples and collect accelerometer samples.

        `t_s` (N,), `gyro_rad_s` (N, 3), `accel_m_s2` (N, 3) in the IMU frame, rotated to the camera
        by `R_ci`. Non-finite or out-of-order samples are dropped and counted (`Status.IMU_DROPPED`).
        """
        t_s, gyro, accel = check_imu_arrays(t_s, gyro_rad_s, accel_m_s2)
        t_s = t_s + self.config.imu_time_offset_s
        finite = np.isfinite(t_s) & np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(accel), axis=1)
        gyro_c, accel_c = gyro @ self._R_ci.T, accel @ self._R_ci.T
        for t, w_c, a_c, ok in zip(t_s, gyro_c, accel_c, finite):
            if not ok or (self._t_imu is not None and t <= self._t_imu):
                self._dropped_imu += 1
                continue
            if self._t_imu is not None:
                self._pim.integrateMeasurement(w_c, t - self._t_imu)
            self._t_imu = t
            self._accel_c.append(a_c)
            self._gyro_c.append(w_c)

    def _gravity_factor(self, key: int) -> gtsam.NonlinearFactor | None:
        """Paper-free addition: accelerometer up direction since the last frame, noise inflated by motion."""
        if not self._accel_c:
            return None
        accel = np.asarray(self._accel_c)
        mean = accel.mean(axis=0)
        norm = np.linalg.norm(mean)
        if norm < 1e-6:
            return None
        spread = np.sqrt(np.mean(np.sum((accel - mean) ** 2, axis=1)))
        cfg = self.config
        # Still (the bias-corrected gyro below `still_rate_rad_s`): the spread is noise or a vibrating
        # platform's shaking, which averages out of the mean (its standard error, rad); turning: it is
        # taken as the platform's own acceleration, inflated per m/s^2 with |a| away from g.
        rate = np.linalg.norm(np.mean(self._gyro_c, axis=0) - self._bias) if self._gyro_c else np.inf
        if rate < cfg.still_rate_rad_s:
            sigma = (cfg.accel_std_rad + cfg.accel_inflation_rad_per_m_s2 * abs(norm - cfg.gravity_m_s2)
                     + spread / (cfg.gravity_m_s2 * np.sqrt(len(accel))))
        else:
            sigma = cfg.accel_std_rad + cfg.accel_inflation_rad_per_m_s2 * (abs(norm - cfg.gravity_m_s2) + spread)
        noise = _robust(cfg.gravity_huber_k, gtsam.noiseModel.Isotropic.Sigma(2, sigma))
        # Error: up_w (x) R_wc @ up_c, with up_c the measured specific-force direction.
        return gtsam.AttitudeFactorRot3(key, gtsam.Unit3(WORLD_UP), noise, gtsam.Unit3(mean / norm))

    # ----------------------------------------------------------------------------- variant hooks
    def _predicted_R_wc(self, visual: VisualRotation | None = None) -> np.ndarray:
        """The last estimate propagated by the gyro preintegrated since its frame."""
        R_wc = self._last.R_wc
        if self._pim.deltaTij() > 0:
            R_wc = R_wc @ self._pim.deltaRij().matrix()
        return R_wc

    def _visual_factor(self, k: int, visual: VisualRotation, noise) -> gtsam.NonlinearFactor:
        """f^z as a measurement of `R_mc = R_wm^T R_wc`, relative to the Manhattan variable M."""
        return gtsam.BetweenFactorRot3(MANHATTAN_KEY, X(k), gtsam.Rot3(visual.R_cm.T), noise)

    def _labelled(self, t_s: float, visual: VisualRotation, R_wc_pred: np.ndarray) -> VisualRotation:
        """`visual` relabelled nearest the gyro-propagated estimate (the gyro turns it better than the
        image rotation would, and the gravity factors hold its tilt)."""
        return visual.symmetric_to(R_wc_pred.T @ self._R_wm)

    def _visual_huber_k(self, visual: VisualRotation) -> float | None:
        """`visual_huber_k` (the gyro, not the image rotation, ties the frames)."""
        return self.config.visual_huber_k

    def _add_motion_factors(self, graph, values, stamps, k: int, t_s: float, visual: VisualRotation | None) -> None:
        """Gyro preintegration (or the paper's smoothness factor when no gyro sample came), the bias
        random walk and the gravity factor."""
        if self._pim.deltaTij() > 0:
            graph.add(gtsam.AHRSFactor(X(k - 1), X(k), B(k - 1), self._pim))
        else:  # no gyro sample between the frames: fall back to the paper's smoothness factor
            graph.add(self._smoothness_factor(k))
        dt = max(t_s - self._t_frame, 1e-3)
        walk = gtsam.noiseModel.Isotropic.Sigma(3, self.config.gyro_bias_rw_rad_s2_sqrt_hz * np.sqrt(dt))
        graph.add(gtsam.BetweenFactorVector(B(k - 1), B(k), np.zeros(3), walk))
        values.insert(B(k), self._bias)
        stamps[B(k)] = float(k)
        gravity = self._gravity_factor(X(k))
        if gravity is not None:
            graph.add(gravity)

    def _window_stamps(self, stamps, k: int) -> None:
        stamps[MANHATTAN_KEY] = float(k)  # keep R_wm inside the window

    def _start_priors(self, graph, values, stamps, t_s: float, visual: VisualRotation) -> VisualRotation:
        """World priors and the first gravity factor; the first visual rotation relabelled so that its
        z axis is the Manhattan axis nearest the measured up."""
        if self._accel_c:
            up_c = np.mean(self._accel_c, axis=0)
            visual = visual.symmetric_to(label_up_as_z(visual.R_cm, up_c / np.linalg.norm(up_c)))
        self._add_world_priors(graph, values, stamps, 0, np.eye(3), self._bias,
                               self.config.gyro_bias_initial_std_rad_s**2 * np.eye(3))
        gravity = self._gravity_factor(X(0))
        if gravity is not None:
            graph.add(gravity)
        return visual

    def _restart_priors(self, graph, values, stamps, k: int) -> None:
        self._add_world_priors(graph, values, stamps, k, self._R_wm, self._bias,
                               self.config.gyro_bias_initial_std_rad_s**2 * np.eye(3))

    def _world_and_bias(self, values) -> tuple[np.ndarray, np.ndarray]:
        return values.atRot3(MANHATTAN_KEY).matrix(), np.asarray(values.atVector(B(self._k)), dtype=float)

    def _add_world_priors(self, graph, values, stamps, k: int, R_wm: np.ndarray, bias: np.ndarray,
                          bias_cov: np.ndarray) -> None:
        """R_wm (gauge on yaw, loose tilt) and the gyro bias B(k)."""
        cfg = self.config
        sig = [cfg.manhattan_vertical_std_rad, cfg.manhattan_vertical_std_rad, cfg.world_yaw_std_rad]
        graph.add(gtsam.PriorFactorRot3(MANHATTAN_KEY, gtsam.Rot3(R_wm), gtsam.noiseModel.Diagonal.Sigmas(sig)))
        graph.add(gtsam.PriorFactorVector(B(k), bias, gtsam.noiseModel.Gaussian.Covariance(bias_cov)))
        values.insert(MANHATTAN_KEY, gtsam.Rot3(R_wm))
        values.insert(B(k), bias)
        stamps[MANHATTAN_KEY] = float(k)
        stamps[B(k)] = float(k)
