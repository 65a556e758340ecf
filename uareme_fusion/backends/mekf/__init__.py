"""Multiplicative (error-state) EKF fusing visual Manhattan rotations with a gyro and accelerometer.

Modules: `config` (MekfConfig), `state` (error state, reset), `motion` (the motion strategy of a
mode), `measurements` (the measurement models' one contract, `Measurement`, and the vertical, gravity
and zero-rate models; the visual one is `kernel_visual.visual_model`), `accel` (the accelerometer
period), `scene` (Manhattan-frame initialisation and re-initialisation), `filter` (`Mekf`, the scheduler),
`kernels` (the one implementation: `kernel_imu`, `kernel_update`, `kernel_visual`, numba-compiled or
plain Python), `compiled` (the filter's calls into them), `parameters` (their named parameter record),
`state_buffer` (the one record of named fields holding the state, which the kernels update in place), `offline`
(forward-backward).

See docs/design.md "Backends". Conventions:
- Nominal state: `R_wc` (camera to world, world z up), gyro bias `b_c` (rad/s, held in the camera
  frame, reported in the IMU frame), the Manhattan frame's attitude `R_wm`, and (visual-only mode)
  the camera's angular rate `omega_c` (rad/s, camera frame).
- Error state (12,): `[dtheta_c, db_c, dtheta_m, domega_c]` with RIGHT perturbations,
  `R_wc = R_wc_hat @ Exp(dtheta_c)`, `R_wm = R_wm_hat @ Exp(dtheta_m)`; covariance `P` in rad^2,
  (rad/s)^2. The kernels (`kernels.py`) do the covariance algebra (Joseph form) and correct the
  nominal rotations after each update (error reset with its Jacobian `I - skew(dtheta)/2`).
- World yaw is a gauge: it is the camera's heading at initialisation (its yaw variance starts at 0).
  With an IMU, world z is up from the accelerometer; without one, the world is the first Manhattan
  frame labelled with its z the axis nearest image up (`R_wm = I`).
- Visual measurement: `R_cm = R_wc^T R_wm`, covariance from the solver; Manhattan labelling resolved
  against the prediction. The IMU: `omega_c = R_ci (gyro_i - b_i)`, `accel_c = R_ci accel_i`; an
  IMU sample stamped `t` measures the camera time `t + imu_time_offset_s`.
- Updates: gyro samples are integrated in one chunk per frame (or per accelerometer period in a long
  batch); the accelerometer updates once per `accel_update_period_s`, and an update that falls due
  at a frame is stacked into that frame's visual update (one Kalman update, same state time). With
  `accel_lowpass_tau_s` the update measures the low-passed direction, whose sensitivity to the gyro
  bias (it was carried along by the gyro) enters H; with `rest_gyro_max_rad_s` the mean gyro reading
  at rest measures the bias (zero-rate update); with `gyro_bias_visual_correlation_s` a frame's rotation
  rows move the gyro bias by a partial gain (`kernel_update.kalman_update`'s `bias_gain`).
"""


from .config import GyroSampling, MekfConfig, MekfMode
from .filter import Mekf
from .state import BG, MF, N_STATE, RATE, TH

__all__ = ["BG", "MF", "N_STATE", "RATE", "TH", "GyroSampling", "Mekf", "MekfConfig", "MekfMode"]
