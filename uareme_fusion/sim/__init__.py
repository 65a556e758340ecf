"""Synthetic Manhattan world with exact ground truth.

Modules (import them directly; this package imports nothing on its own):
- `trajectory`: `make_trajectory(name, duration_s, seed)` -> `Trajectory` with `.sample(t)` giving
  `R_wc`, `p_w`, `omega_c_rad_s`, `accel_w_m_s2`, and `.R_wm(t)` (the bus body in the vehicle).
- `imu`: `simulate_imu(traj, rate_hz, ImuNoise, seed, R_ci, imu_time_offset_s)` -> `(t_s, gyro, accel)`.
- `scenes`, `materials`: seeded procedural scenes; `render`: vectorised ray caster.
- `scenarios`: named scene + trajectory + options; `dataset`: TUM/EuRoC/npz/scene.json writer.
- `normal_maps`: fast synthetic normal maps without rendering.
"""
