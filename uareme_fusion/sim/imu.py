"""IMU simulation from a `Trajectory`: gyro and specific force in the IMU frame, with noise.

Public API::

    noise = ImuNoise(gyro_noise_rad_s_sqrt_hz=1.7e-4, ...)     # or ImuNoise.noiseless()
    t_s, gyro_rad_s, accel_m_s2 = simulate_imu(traj, rate_hz=200.0, noise=noise, seed=0,
                                              R_ci=np.eye(3), imu_time_offset_s=0.0)

Conventions (docs/design.md):
- IMU frame `i`; `R_ci` (3, 3) maps IMU coordinates to camera coordinates (`v_c = R_ci @ v_i`).
  The IMU sits at the camera centre (no lever arm).
- `gyro_rad_s` (N, 3): angular velocity in `i`, `omega_i = R_ci^T omega_c`, plus bias and noise.
- `accel_m_s2` (N, 3): specific force in `i`, `f_i = R_ci^T R_wc^T (a_w - g_w)` with
  `g_w = (0, 0, -9.81)`, plus bias and noise: at rest it reads +9.81 m/s^2 along up.
- Time offset: `t_cam = t_imu + imu_time_offset_s` (as `SourceInfo`). A sample stamped `t_s` (IMU
  clock, the returned times) measures the motion at camera time `t_s + imu_time_offset_s`.
  Samples are stamped `k / rate_hz` for every k with `t_s + imu_time_offset_s` inside
  [0, duration_s] of the trajectory.
- Noise: white noise of density `*_noise_*_sqrt_hz` becomes a per-sample standard deviation of
  `density * sqrt(rate_hz)`; biases start at `*_bias_init` and follow a random walk of density
  `*_bias_rw_*` (per-sample step std `density / sqrt(rate_hz)`). Default densities are those of
  an ADIS16448-class IMU as listed for EuRoC. `simulate_imu(..., return_bias=True)` also returns
  the true bias trajectories for filter tests.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..errors import InputError
from ..rotations import is_rotation
from .trajectory import Trajectory

GRAVITY_W_M_S2 = np.array([0.0, 0.0, -9.81])
"""Gravity in the world frame (z up), m/s^2."""


@dataclass(frozen=True)
class ImuNoise:
    """IMU error model; every field is SI with its unit in the name."""

    gyro_noise_rad_s_sqrt_hz: float = 1.7e-4
    """Gyro white-noise density, rad/s/sqrt(Hz)."""
    accel_noise_m_s2_sqrt_hz: float = 2.0e-3
    """Accelerometer white-noise density, m/s^2/sqrt(Hz)."""
    gyro_bias_rw_rad_s2_sqrt_hz: float = 1.9e-5
    """Gyro bias random-walk density, rad/s^2/sqrt(Hz)."""
    accel_bias_rw_m_s3_sqrt_hz: float = 3.0e-3
    """Accelerometer bias random-walk density, m/s^3/sqrt(Hz)."""
    gyro_bias_init_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Gyro bias at the first sample, rad/s, in the IMU frame."""
    accel_bias_init_m_s2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Accelerometer bias at the first sample, m/s^2, in the IMU frame."""

    @classmethod
    def noiseless(cls) -> "ImuNoise":
        """No noise, no bias."""
        return cls(0.0, 0.0, 0.0, 0.0)

    def as_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(self).items()}


def ideal_imu(traj: Trajectory, t_cam_s: np.ndarray, R_ci: np.ndarray | None = None):
    """Noiseless (gyro_rad_s, accel_m_s2), each (N, 3) in the IMU frame, at camera times `t_cam_s`."""
    R_ci = np.eye(3) if R_ci is None else np.asarray(R_ci, float)
    R_wc, _, omega_c, accel_w = traj.sample(t_cam_s)
    specific_force_w = accel_w - GRAVITY_W_M_S2
    specific_force_c = np.einsum("nji,nj->ni", R_wc, specific_force_w)  # R_wc^T f_w
    return omega_c @ R_ci, specific_force_c @ R_ci  # row-vector form of R_ci^T v_c


def _bias_walk(rng, n, init, rw_density, rate_hz):
    steps = rng.standard_normal((n, 3)) * (rw_density / np.sqrt(rate_hz))
    steps[0] = 0.0
    return np.asarray(init, float) + np.cumsum(steps, axis=0)


def simulate_imu(
    traj: Trajectory,
    rate_hz: float = 200.0,
    noise: ImuNoise | None = None,
    seed: int = 0,
    R_ci: np.ndarray | None = None,
    imu_time_offset_s: float = 0.0,
    return_bias: bool = False,
):
    """Simulated IMU readings `(t_s, gyro_rad_s, accel_m_s2)` over the trajectory; see module doc.

    `t_s` (N,) are IMU-clock stamps in seconds; `gyro_rad_s`, `accel_m_s2` are (N, 3) in the IMU
    frame. With `return_bias=True` also returns `(gyro_bias_rad_s, accel_bias_m_s2)`, each (N, 3).
    Same seed, same readings.
    """
    if not np.isfinite(rate_hz) or not 1.0 <= rate_hz <= 10000.0:
        raise InputError(f"IMU rate_hz must be within [1, 10000] Hz, got {rate_hz}")
    R_ci = np.eye(3) if R_ci is None else np.asarray(R_ci, float)
    if R_ci.shape != (3, 3) or not is_rotation(R_ci):
        raise InputError(f"R_ci must be a (3, 3) rotation matrix, got shape {R_ci.shape}")
    noise = ImuNoise() if noise is None else noise
    k0 = int(np.ceil(-imu_time_offset_s * rate_hz - 1e-9))
    k1 = int(np.floor((traj.duration_s - imu_time_offset_s) * rate_hz + 1e-9))
    t_s = np.arange(k0, k1 + 1) / rate_hz
    gyro, accel = ideal_imu(traj, t_s + imu_time_offset_s, R_ci)
    rng = np.random.default_rng(seed)
    n = t_s.size
    gyro_bias = _bias_walk(rng, n, noise.gyro_bias_init_rad_s, noise.gyro_bias_rw_rad_s2_sqrt_hz,
                           rate_hz)
    accel_bias = _bias_walk(rng, n, noise.accel_bias_init_m_s2, noise.accel_bias_rw_m_s3_sqrt_hz,
                            rate_hz)
    gyro = gyro + gyro_bias + rng.standard_normal((n, 3)) * (
        noise.gyro_noise_rad_s_sqrt_hz * np.sqrt(rate_hz))
    accel = accel + accel_bias + rng.standard_normal((n, 3)) * (
        noise.accel_noise_m_s2_sqrt_hz * np.sqrt(rate_hz))
    if return_bias:
        return t_s, gyro, accel, gyro_bias, accel_bias
    return t_s, gyro, accel
