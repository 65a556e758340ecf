"""The EKF's models against finite differences: every measurement model's H (the kernels' visual
model, the vertical, gravity and zero-rate models, all as plain Python), the gyro and constant-rate
transitions F of the kernels, the reset Jacobian; and, on the oracle (`mekf_oracle`, which the
kernels are cross-tested against), the low-pass bias sensitivity and a stacked update against
updates in turn.

Convention (`mekf.state`): a state `x (+) dx` has `R_wc Exp(dtheta_c)`, `b_c + db`, `R_wm Exp(dtheta_m)`,
`omega_c + domega`; a model's H satisfies `residual(x) - residual(x (+) dx) = H dx` to first order
for the same measurement (its prediction moved by `H dx`): `jacobians.check_measurement_model`."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.kalman import update as kf_update

from jacobians import check_measurement_model, fd_jacobian

from uareme_fusion.backends.mekf import kernel_imu, kernel_visual
from uareme_fusion.backends.mekf.measurements import gravity_model, vertical_model, zero_rate_model
from uareme_fusion.backends.mekf.state import BG, MF, N_STATE, RATE, TH, ZERO_STATE, reset_jacobian
from uareme_fusion.backends.mekf.state_buffer import field_views, new_state_buffer, python_state
from uareme_fusion.rotations import WORLD_UP, angle_between, exp_so3, log_so3

from mekf_oracle.accel import AccelPeriod  # tests/backends/mekf_oracle: pytest puts tests/backends on sys.path
from mekf_oracle.measurements import stack
from mekf_oracle.measurements import visual_model as oracle_visual_model
from mekf_oracle.propagation import gyro_chunk, gyro_rates, prefix_products
from mekf_oracle.state import inject


def plain(f):
    """A kernel as plain Python (numba's `py_func`), so that the test runs it with any argument."""
    return getattr(f, "py_func", f)


visual_model = plain(kernel_visual.visual_model)

GRAVITY_ARGS = dict(gravity_m_s2=9.81, noise_rad_sqrt_s=0.02, norm_scale=0.05, innovation_scale_rad=0.05,
                    flag_ratio=2.0)


def perturbed(R_wc, R_wm, b_c, omega_c, dx):
    """The state `x (+) dx` (right perturbations)."""
    return R_wc @ exp_so3(dx[TH]), R_wm @ exp_so3(dx[MF]), b_c + dx[BG], omega_c + dx[RATE]


def random_state(seed):
    rng = np.random.default_rng(seed)
    return exp_so3(rng.normal(size=3)), exp_so3(rng.normal(size=3)), 0.01 * rng.normal(size=3), rng.normal(size=3)


def visual_at(relabel):
    """The visual model at `x (+) dx` of the rotation that `x` predicts (H is its Jacobian at a zero residual)."""
    x = random_state(3)
    R_cm = x[0].T @ x[1]
    cov = np.diag([1e-4, 2e-4, 3e-4])
    return lambda dx: plain(visual_model)(*perturbed(*x, dx)[:2], R_cm, cov, relabel)


def vertical_at():
    x = random_state(4)
    R_wm = exp_so3([0.05, -0.03, 1.2])  # z within the gate of up
    return lambda dx: plain(vertical_model)(perturbed(x[0], R_wm, *x[2:], dx)[1], 0.02, 0.35)


def gravity_at(use_lp_J):
    """The gravity model of a low-passed specific force, which follows the bias estimate: `lp + J db`
    (the kernels' injection, `kernel_update.inject_and_reset`)."""
    x = random_state(5)
    rng = np.random.default_rng(6)
    lp = x[0].T @ (9.81 * WORLD_UP) + 0.3 * rng.normal(size=3)  # m/s^2
    J = rng.normal(size=(3, 3)) if use_lp_J else np.zeros((3, 3))

    def measure(dx):
        R_wc = perturbed(*x, dx)[0]
        return plain(gravity_model)(lp + J @ dx[BG], 0.04, R_wc, J, use_lp_J, **GRAVITY_ARGS)[0]
    return measure


def resting(seed=7):
    """A state, 50 gyro readings at rest about its bias and the rest sums of `zero_rate_model` over them."""
    x = random_state(seed)
    rng = np.random.default_rng(seed + 1)
    gyro = x[2] + 1e-4 * rng.normal(size=(50, 3))
    accel = np.tile([0.0, -9.81, 0.0], (50, 1))
    return x, gyro, np.r_[gyro.sum(axis=0), (gyro**2).sum(), accel.sum(axis=0), (accel**2).sum()]


def zero_rate_at():
    x, _, sums = resting()
    return lambda dx: plain(zero_rate_model)(sums, 50, 0.25, perturbed(*x, dx)[2], 4e-6, 0.035, 0.5, 5e-4)


MODELS = {"visual": lambda: visual_at(True), "visual as labelled": lambda: visual_at(False),
          "vertical": vertical_at, "gravity": lambda: gravity_at(False), "gravity low-passed": lambda: gravity_at(True),
          "zero rate": zero_rate_at}
"""Every measurement model of the EKF (`mekf.measurements`), as the kernels run it (plain Python), at a
state `x (+) dx`."""


def test_fd_jacobian_of_a_known_map():
    A = np.arange(12.0).reshape(3, 4)
    np.testing.assert_allclose(fd_jacobian(lambda d: A @ d + np.sin(d[0]) * np.array([1.0, 0, 0]), 4),
                               A + np.array([[1.0, 0, 0, 0], [0, 0, 0, 0], [0, 0, 0, 0]]), atol=1e-8)


@pytest.mark.parametrize("name", MODELS)
def test_measurement_model_jacobian_against_finite_differences(name):
    """One contract for all: each model's `Measurement` at a state, its H the derivative of its residual."""
    check_measurement_model(MODELS[name](), atol=1e-7)


def test_measurement_models_covariances_and_where_they_apply():
    visual = visual_at(True)(np.zeros(12))
    np.testing.assert_allclose(visual.covariance, np.diag([1e-4, 2e-4, 3e-4]), atol=1e-18)  # nearest as labelled
    np.testing.assert_array_equal(vertical_at()(np.zeros(12)).covariance, 0.02**2 * np.eye(3))
    assert not vertical_model(exp_so3([0.5, 0.0, 0.0]), 0.02, 0.35).ok  # m's z 29 deg from up
    gravity = gravity_at(False)(np.zeros(12))
    assert gravity.covariance[0, 0] > 0.02**2 / 0.04 and np.all(gravity.jacobian[:, BG] == 0)
    rest = zero_rate_at()(np.zeros(12))
    np.testing.assert_array_equal(rest.covariance, (4e-6 / 0.25 + 5e-4**2) * np.eye(3))


def test_visual_model_at_its_prediction_and_the_kernels_rows():
    """At the prediction the residual is zero; the kernels write the model into a stacked update's rows."""
    R_wc, R_wm, _, _ = random_state(3)
    at = visual_model(R_wc, R_wm, R_wc.T @ R_wm, 1e-4 * np.eye(3), True)
    assert np.abs(at.residual).max() < 1e-12
    r, R, H = np.ones(6), np.ones((6, 6)), np.ones((6, 12))
    plain(kernel_visual.visual_rows)(R_wc, R_wm, R_wc.T @ R_wm, 1e-4 * np.eye(3), True, r, R, H)
    np.testing.assert_array_equal(r[:3], at.residual)
    np.testing.assert_array_equal(R[:3, :3], at.covariance)
    np.testing.assert_array_equal(H[:3], at.jacobian)
    assert np.all(r[3:] == 1) and np.all(R[3:] == 1) and np.all(H[3:] == 1)  # the other rows left


def test_visual_model_relabels_nearest_the_prediction_and_its_covariance_with_it():
    """A rotation labelled by another cube symmetry gives the same residual, and its covariance turned
    with the relabelling; the oracle's model (scipy) agrees."""
    from uareme_fusion.rotations import manhattan_symmetries

    R_wc, R_wm, _, _ = random_state(13)
    R_cm = R_wc.T @ R_wm @ exp_so3([0.01, -0.02, 0.005])
    cov = np.diag([1e-4, 2e-4, 3e-4])
    G = manhattan_symmetries()[7]
    _, r0, R0, _ = visual_model(R_wc, R_wm, R_cm, cov, True)
    _, r, R, H = visual_model(R_wc, R_wm, R_cm @ G, G.T @ cov @ G, True)
    np.testing.assert_allclose(r, r0, atol=1e-12)
    np.testing.assert_allclose(R, R0, atol=1e-15)
    for mine, oracle in zip((r, R, H), oracle_visual_model(R_wc, R_wm, R_cm @ G, G.T @ cov @ G)):
        np.testing.assert_allclose(mine, oracle, atol=1e-12)


def test_gravity_model_skips_free_fall():
    gravity, _ = gravity_model(np.array([0.0, -0.5, 0.0]), 0.04, np.eye(3), np.zeros((3, 3)), False, **GRAVITY_ARGS)
    assert not gravity.ok and np.all(gravity.jacobian == 0)


def test_zero_rate_model_residual_and_motion():
    x, gyro, sums = resting()
    limits = (4e-6, 0.035, 0.5, 5e-4)
    np.testing.assert_allclose(zero_rate_model(sums, 50, 0.25, x[2], *limits).residual, gyro.mean(axis=0) - x[2],
                               atol=1e-12)
    moving = gyro + [0.1, 0.0, 0.0]
    sums_moving = np.r_[moving.sum(axis=0), (moving**2).sum(), sums[4:]]
    assert not zero_rate_model(sums_moving, 50, 0.25, x[2], *limits).ok


def kernel_chunk(gyro, dt, b, trapezoid, P=np.zeros((12, 12))):
    """`kernel_imu.propagate_chunk` over readings `gyro` (n + 1, 3) and steps `dt` (n,): `(C_N, F, P_pred)`
    with the transition `F` (12, 12) it applies (identity but `F[TH, TH] = C_N^T`, `F[TH, BG] = -A_bias`)."""
    C_out = np.empty((dt.size, 3, 3))
    C_N, A_bias, P_pred = plain(kernel_imu.propagate_chunk)(b, P, gyro, dt, trapezoid, 0.0, 0.0, 0.0, float(dt.sum()),
                                                            0.0, C_out)
    F = np.eye(N_STATE)
    F[TH, TH], F[TH, BG] = C_N.T, -A_bias
    return C_N, F, P_pred


@pytest.mark.parametrize("trapezoid", [False, True])
def test_gyro_transition_F(trapezoid):
    """Attitude and bias columns of the kernels' chunk transition against re-integration of a perturbed
    state, and the covariance it predicts is `F P F^T` (no process noise here)."""
    rng = np.random.default_rng(1)
    dt = np.full(9, 0.005)
    gyro = rng.normal(size=(10, 3))  # the reading before the chunk, then its 9 samples
    R0, _, b0, _ = random_state(9)

    def end_attitude(dth, db):
        return R0 @ exp_so3(dth) @ kernel_chunk(gyro, dt, b0 + db, trapezoid)[0]

    A = rng.normal(size=(12, 12))
    P = A @ A.T
    _, F, P_pred = kernel_chunk(gyro, dt, b0, trapezoid, P)
    np.testing.assert_allclose(P_pred, F @ P @ F.T, rtol=1e-12, atol=1e-12)
    R_N = end_attitude(np.zeros(3), np.zeros(3))
    fd = fd_jacobian(lambda d: log_so3(R_N.T @ end_attitude(d[:3], d[3:])), 6)
    np.testing.assert_allclose(fd[:, :3], F[TH, TH], atol=1e-8)
    # The bias columns are first order in the chunk's rotation (|rate dt| ~ 0.01 per step here).
    np.testing.assert_allclose(fd[:, 3:], F[TH, BG], atol=2e-4)
    assert np.abs(F[TH, BG]).max() > 0.04
    np.testing.assert_array_equal(F[3:, :], np.eye(N_STATE)[3:, :])


def constant_rate_step(R_wc, omega, P, dt_s, q_rate):
    """`kernel_visual.constant_rate_predict` from a state buffer holding `R_wc`, `omega`, `P` at t = 0:
    `(R_wc, P)` at `dt_s`."""
    x = new_state_buffer()
    views = field_views(x)
    views["R_wc"][...], views["omega_c"][...], views["P"][...] = R_wc, omega, P
    x["t_state_s"] = 0.0
    plain(kernel_visual.constant_rate_predict)(python_state(x), dt_s, q_rate)
    return views["R_wc"].copy(), views["P"].copy()


def test_constant_rate_transition_F():
    """The kernels' constant-rate prediction: the attitude it reaches, and the covariance it predicts,
    `F P F^T + Q`, against the transition `F` of a perturbed state (finite differences) and the
    integrated random walk `Q`."""
    R0, _, _, omega = random_state(10)
    R_N, Q = constant_rate_step(R0, omega, np.zeros((12, 12)), 0.05, 3.0**2)

    def end_attitude(d):
        return R0 @ exp_so3(d[:3]) @ exp_so3((omega + d[3:]) * 0.05)

    np.testing.assert_allclose(R_N, end_attitude(np.zeros(6)), atol=1e-12)
    fd = fd_jacobian(lambda d: log_so3(R_N.T @ end_attitude(d)), 6)
    F = np.eye(N_STATE)
    F[TH, TH], F[TH, RATE] = fd[:, :3], 0.05 * np.eye(3)  # the kernel keeps dt I (below)
    np.testing.assert_allclose(Q, Q.T)
    np.testing.assert_allclose(np.diag(Q)[[0, 9]], [9.0 * 0.05**3 / 3, 9.0 * 0.05])
    A = np.random.default_rng(14).normal(size=(12, 12))
    P = 1e-3 * A @ A.T
    _, P_pred = constant_rate_step(R0, omega, P, 0.05, 3.0**2)
    np.testing.assert_allclose(P_pred, F @ P @ F.T + Q, rtol=1e-6, atol=1e-9)
    # F keeps dt I: the right Jacobian of Exp(omega dt) is dropped, an error of |omega| dt^2 / 2.
    np.testing.assert_allclose(fd[:, 3:], F[TH, RATE], atol=np.linalg.norm(omega) * 0.05**2 / 2)


def test_reset_jacobian_against_finite_differences():
    """After injecting dtheta, an error e about the old nominal is `Log(Exp(-dtheta) Exp(e))` about the
    new one: its derivative at e = dtheta is G to first order in |dtheta|."""
    dx = np.zeros(N_STATE)
    dx[TH], dx[MF] = [1e-3, -2e-3, 5e-4], [-1e-3, 1e-3, 2e-3]
    G = reset_jacobian(dx, True)
    for block in (TH, MF):
        fd = fd_jacobian(lambda e: log_so3(exp_so3(-dx[block]) @ exp_so3(dx[block] + e)), 3)
        np.testing.assert_allclose(fd, G[block, block], atol=1e-6)
    np.testing.assert_array_equal(reset_jacobian(dx, False)[MF, MF], np.eye(3))


def test_prefix_products_match_sequential_products_in_the_oracle():
    rng = np.random.default_rng(0)
    M = exp_so3(rng.normal(size=(11, 3)))
    C = prefix_products(M)
    acc = np.eye(3)
    for k in range(11):
        acc = acc @ M[k]
        np.testing.assert_allclose(C[k], acc, atol=1e-12)


def test_lowpass_bias_sensitivity_matches_finite_differences():
    """The oracle's `AccelPeriod.lp_J` (how the low-passed accelerometer, carried along by the gyro, depends on the
    gyro bias) against re-running the same samples with a perturbed bias."""
    rng = np.random.default_rng(4)
    gyro = 0.5 * rng.normal(size=(401, 3))
    accel = rng.normal(size=(400, 3)) + [0.0, -9.81, 0.0]
    dt = np.full(400, 1.0 / 200.0)

    def run(b):
        period = AccelPeriod()
        for a in range(0, 400, 4):  # 0.02 s periods, low-pass time constant 1 s
            C, A_bias = gyro_chunk(gyro_rates(gyro[a:a + 5], b, trapezoid=True), dt[a:a + 4])
            period.add_chunk(C, accel[a:a + 4], dt[a:a + 4], 0.02, 0.02)
            period.carry_lowpass(C[-1], A_bias)
            period.lowpass(*period.take_mean(), tau_s=1.0)
        return period

    b0 = 0.01 * rng.normal(size=3)
    nominal = run(b0)
    fd = fd_jacobian(lambda d: run(b0 + d).lp_c.ravel(), 3).reshape(2, 3, 3)
    # The model takes each period's own mean as bias-free: short periods against long low-pass stages.
    np.testing.assert_allclose(fd, nominal.lp_J, rtol=0.03, atol=0.02)


def test_stacked_update_matches_sequential_updates():
    """A visual and an accelerometer measurement in one stacked update equal the two applied in turn
    (with injection and reset between) to first order."""
    R_wc, R_wm, b, w = random_state(11)
    rng = np.random.default_rng(12)
    P = np.diag(np.r_[np.full(3, 1e-4), np.full(3, 1e-6), np.full(3, 1e-4), np.zeros(3)])
    R_cm = R_wc.T @ R_wm @ exp_so3(0.003 * rng.normal(size=3))
    acc = R_wc.T @ (9.81 * WORLD_UP) + [0.05, 0.0, 0.02]

    def visual(R_wc, R_wm):
        return oracle_visual_model(R_wc, R_wm, R_cm, 1e-4 * np.eye(3))

    def accel_rows(R_wc):
        return gravity_model(acc, 0.1, R_wc, np.zeros((3, 3)), False, **GRAVITY_ARGS)[0][1:]

    def update(state, P, rows):
        dx, P = kf_update(ZERO_STATE, P, *rows)
        G = reset_jacobian(dx, True)
        return inject(*state, dx, True, False), G @ P @ G.T

    x = (R_wc, R_wm, b, w)
    stacked, P_stacked = update(x, P, stack([visual(R_wc, R_wm), accel_rows(R_wc)]))
    mid, P_mid = update(x, P, accel_rows(R_wc))
    sequential, P_seq = update(mid, P_mid, visual(mid[0], mid[1]))
    assert np.degrees(angle_between(stacked[0], sequential[0])) < 1e-4
    np.testing.assert_allclose(P_stacked, P_seq, rtol=1e-3, atol=1e-12)
