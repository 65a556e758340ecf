"""Trajectories and IMU simulation: exact derivatives, gravity convention, bus limits."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.errors import InputError
from uareme_fusion.rotations import angle_between, exp_so3, up_in_camera
from uareme_fusion.sim.imu import ImuNoise, simulate_imu
from uareme_fusion.sim.trajectory import TRAJECTORY_NAMES, make_trajectory


def _integrate_gyro(R0, t_s, gyro_rad_s):
    """Right-multiplied Exp of the trapezoid-averaged rate over each interval (R_ci = I)."""
    dt = np.diff(t_s)[:, None]
    steps = exp_so3(0.5 * (gyro_rad_s[:-1] + gyro_rad_s[1:]) * dt)
    R = R0.copy()
    out = [R]
    for S in steps:
        R = R @ S
        out.append(R)
    return np.stack(out)


@pytest.mark.parametrize("name", ["walk", "shake", "bus"])
def test_noiseless_gyro_integrates_to_true_attitude_over_60s(name):
    traj = make_trajectory(name, 60.0, seed=3)
    t, gyro, _ = simulate_imu(traj, rate_hz=1000.0, noise=ImuNoise.noiseless())
    R_true = traj.sample(t).R_wc
    R_int = _integrate_gyro(R_true[0], t, gyro)
    err_deg = np.degrees(angle_between(R_true, R_int))
    assert err_deg.max() < 0.01


def test_angular_velocity_matches_finite_difference_of_attitude():
    traj = make_trajectory("shake", 5.0, seed=1)
    t = np.linspace(0.5, 4.5, 50)
    h = 1e-5
    R_a, R_b = traj.sample(t - h).R_wc, traj.sample(t + h).R_wc
    omega_fd = Rotation.from_matrix(np.swapaxes(R_a, 1, 2) @ R_b).as_rotvec() / (2 * h)
    np.testing.assert_allclose(traj.sample(t).omega_c_rad_s, omega_fd, atol=1e-5)


@pytest.mark.parametrize("name", ["walk", "bus"])
def test_acceleration_matches_second_difference_of_position(name):
    traj = make_trajectory(name, 30.0, seed=2)
    t = np.linspace(1.0, 29.0, 40)
    h = 1e-3
    p = [traj.sample(t + k * h).p_w for k in (-1, 0, 1)]
    accel_fd = (p[0] - 2 * p[1] + p[2]) / h**2
    np.testing.assert_allclose(traj.sample(t).accel_w_m_s2, accel_fd, atol=2e-3)


def test_static_noiseless_accelerometer_reads_plus_g_along_up():
    traj = make_trajectory("static", 2.0, seed=5)
    R_ci = Rotation.from_euler("xyz", [10, -20, 30], degrees=True).as_matrix()
    t, gyro, accel = simulate_imu(traj, 200.0, ImuNoise.noiseless(), R_ci=R_ci)
    up_i = up_in_camera(traj.sample(t).R_wc) @ R_ci  # R_ci^T up_c
    np.testing.assert_allclose(accel, 9.81 * up_i, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(accel, axis=1), 9.81)
    np.testing.assert_allclose(gyro, 0.0, atol=1e-15)


def test_bus_accelerations_and_sway_within_stated_limits():
    traj = make_trajectory("bus", 180.0, seed=7)
    t = np.arange(0.0, 180.0, 0.01)
    sample = traj.sample(t)
    R_wb = traj.R_wm(t)  # the Manhattan frame is the bus body
    a_b = np.einsum("nji,nj->ni", R_wb, sample.accel_w_m_s2)
    assert a_b[:, 0].max() <= 1.5 + 1e-6 and a_b[:, 0].max() > 1.4  # accelerating
    assert a_b[:, 0].min() >= -2.5 - 1e-6 and a_b[:, 0].min() < -2.3  # braking
    lateral = np.abs(a_b[:, 1])
    assert 2.0 <= lateral.max() <= 3.0 + 0.05  # centripetal in corners and roundabout
    sway_deg = np.degrees(Rotation.from_matrix(R_wb).as_euler("ZYX")[:, 1:])
    assert np.abs(sway_deg).max() < 2.0
    turned = np.degrees(np.abs(np.diff(np.unwrap(Rotation.from_matrix(R_wb).as_euler("ZYX")[:, 0]))))
    assert turned.sum() > 360  # it does corner
    # The camera is fixed in the bus: R_cm is constant.
    R_cm = traj.R_cm(t[::100])
    np.testing.assert_allclose(R_cm, np.broadcast_to(R_cm[0], R_cm.shape), atol=1e-12)


def test_buildings_have_constant_manhattan_frame():
    traj = make_trajectory("walk", 10.0, seed=0)
    np.testing.assert_array_equal(traj.R_wm(np.linspace(0, 10, 5)), np.broadcast_to(np.eye(3), (5, 3, 3)))


def test_time_offset_shifts_samples_and_noise_is_seeded():
    traj = make_trajectory("pan", 10.0, seed=0)
    t0, g0, _ = simulate_imu(traj, 100.0, ImuNoise.noiseless())
    t1, g1, _ = simulate_imu(traj, 100.0, ImuNoise.noiseless(), imu_time_offset_s=-0.05)
    # Stamp t in the shifted log measures camera time t - 0.05 (imu_time_offset_s = -0.05): same as stamp t - 0.05 unshifted.
    np.testing.assert_allclose(t1, t0 + 0.05, atol=1e-12)
    np.testing.assert_allclose(g1, g0, atol=1e-12)
    a = simulate_imu(traj, 100.0, ImuNoise(), seed=4)
    b = simulate_imu(traj, 100.0, ImuNoise(), seed=4)
    c = simulate_imu(traj, 100.0, ImuNoise(), seed=5)
    np.testing.assert_array_equal(a[1], b[1])
    assert not np.allclose(a[1], c[1])


def test_noise_statistics_match_densities():
    traj = make_trajectory("static", 100.0, seed=0)
    noise = ImuNoise(gyro_noise_rad_s_sqrt_hz=1e-3, accel_noise_m_s2_sqrt_hz=1e-2,
                     gyro_bias_rw_rad_s2_sqrt_hz=0.0, accel_bias_rw_m_s3_sqrt_hz=0.0,
                     gyro_bias_init_rad_s=(0.01, 0.0, 0.0))
    _, gyro, accel = simulate_imu(traj, 400.0, noise, seed=1)
    np.testing.assert_allclose(gyro.std(axis=0), 1e-3 * np.sqrt(400.0), rtol=0.03)
    np.testing.assert_allclose(gyro.mean(axis=0), [0.01, 0, 0], atol=5e-4)
    np.testing.assert_allclose(accel.std(axis=0), 1e-2 * np.sqrt(400.0), rtol=0.03)


def test_same_seed_same_trajectory_and_bad_input():
    for name in TRAJECTORY_NAMES:
        a = make_trajectory(name, 5.0, seed=1).sample(np.linspace(0, 5, 7))
        b = make_trajectory(name, 5.0, seed=1).sample(np.linspace(0, 5, 7))
        np.testing.assert_array_equal(a.R_wc, b.R_wc)
    walk_seed_1 = make_trajectory("walk", 5.0, seed=1).sample(np.linspace(0, 5, 7))
    walk_seed_2 = make_trajectory("walk", 5.0, seed=2).sample(np.linspace(0, 5, 7))
    assert not np.allclose(walk_seed_1.R_wc, walk_seed_2.R_wc)
    with pytest.raises(InputError, match="valid: walk"):
        make_trajectory("spin", 5.0)
    with pytest.raises(InputError, match="duration_s"):
        make_trajectory("walk", 0.0)
    with pytest.raises(InputError, match="rate_hz"):
        simulate_imu(make_trajectory("walk", 1.0), rate_hz=0.0)
