"""The Manhattan solver against the numbers of issue 2, brute force and finite differences."""

import numpy as np
import pytest

from uareme_fusion import InputError, solve_manhattan
from uareme_fusion.rotations import angle_between, exp_so3, manhattan_symmetries, nearest_symmetric, nees
from uareme_fusion.sim.normal_maps import manhattan_normal_map, random_noisy_maps
from uareme_fusion.solver.moments import normal_moments
from uareme_fusion.solver.quartic import gradient_hessian, normalised_cost


def error_deg(R_cm, R_true):
    R_near, _ = nearest_symmetric(R_cm, R_true)
    return float(np.degrees(angle_between(R_near, R_true)))


def test_moments_match_brute_force_tensor_in_both_precisions():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(4000, 3)) * rng.uniform(0.5, 2.0, size=(4000, 1))  # not unit length
    k = rng.uniform(0, 3, size=4000)
    u = n / np.linalg.norm(n, axis=1, keepdims=True)
    T = np.einsum("i,ia,ib,ic,id->abcd", k, u, u, u, u)
    m64 = normal_moments(n, k)
    m32 = normal_moments(n.astype(np.float32), k.astype(np.float32))
    np.testing.assert_allclose(m64.tensor(), T, rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(m32.tensor(), T, rtol=1e-4, atol=1e-3)
    assert m64.total_weight == pytest.approx(k.sum())
    assert (m64.n_valid, m64.n_invalid) == (4000, 0)


def test_cost_gradient_and_hessian_against_finite_differences():
    rng = np.random.default_rng(1)
    nm = manhattan_normal_map(exp_so3([0.3, 0.1, -0.2]), rng, noise_deg=8.0, dtype=np.float64)
    m = normal_moments(nm.normals, nm.kappa)
    for _ in range(3):
        R = exp_so3(rng.normal(size=3))
        u = nm.normals.reshape(-1, 3) @ R
        brute = np.sum(nm.kappa.reshape(-1) * (1 - np.sum(u**4, axis=1))) / nm.kappa.sum()
        assert normalised_cost(m.G, m.total_weight, R) == pytest.approx(brute, rel=1e-10)
        grad, hess = gradient_hessian(m.tensor(), m.total_weight, R)

        def f(d):
            return normalised_cost(m.G, m.total_weight, R @ exp_so3(d))

        h = 1e-4
        E = np.eye(3) * h
        grad_fd = np.array([(f(e) - f(-e)) / (2 * h) for e in E])
        hess_fd = np.array([[(f(a + b) - f(a - b) - f(b - a) + f(-a - b)) / (4 * h * h) for b in E] for a in E])
        np.testing.assert_allclose(grad, grad_fd, atol=1e-8)
        np.testing.assert_allclose(hess, hess_fd, atol=1e-5)


@pytest.mark.parametrize("seed", range(5))
def test_ten_degree_noise_three_axes_within_0_3_deg_from_any_start(seed):
    rng = np.random.default_rng(seed)
    R_true = exp_so3(rng.normal(size=3) * 2)
    nm = manhattan_normal_map(R_true, rng, height=240, width=320, noise_deg=10.0)
    starts = [None, np.eye(3)] + [exp_so3(rng.normal(size=3) * 2) for _ in range(6)]
    for R_init in starts:
        result = solve_manhattan(nm.normals, nm.kappa, R_init=R_init)
        assert error_deg(result.R_cm, R_true) <= 0.3
        assert result.converged


def test_kappa_weighting_beats_unweighted_with_30_percent_outliers():
    weighted, unweighted = [], []
    for seed in range(8):
        rng = np.random.default_rng(100 + seed)
        R_true = exp_so3(rng.normal(size=3) * 2)
        # The maps of the 10-degree test, with 30% random-direction outliers carrying low kappa.
        nm = manhattan_normal_map(R_true, rng, height=240, width=320, noise_deg=10.0,
                                  outlier_fraction=0.3, outlier_kappa=0.05)
        weighted.append(error_deg(solve_manhattan(nm.normals, nm.kappa).R_cm, R_true))
        unweighted.append(error_deg(solve_manhattan(nm.normals).R_cm, R_true))
    assert max(weighted) <= 1.0
    assert np.mean(weighted) < np.mean(unweighted)


@pytest.mark.slow
def test_covariance_is_calibrated_mean_nees_over_500_correlated_maps():
    values = []
    for R_true, nm in random_noisy_maps(500, seed=2024):  # held out: calibration used seeds 0 and 1
        result = solve_manhattan(nm.normals, nm.kappa).symmetric_to(R_true)
        values.append(nees(result.R_cm, R_true, result.cov))
    assert 2.0 <= np.mean(values) <= 4.5


def test_one_visible_axis_gives_finite_output_and_a_capped_large_variance_about_it():
    rng = np.random.default_rng(5)
    R_true = exp_so3([0.2, -0.4, 0.9])
    nm = manhattan_normal_map(R_true, rng, axes=(1,), noise_deg=3.0)
    result = solve_manhattan(nm.normals, nm.kappa)
    assert np.all(np.isfinite(result.R_cm)) and np.all(np.isfinite(result.cov))
    eigval, eigvec = np.linalg.eigh(result.cov)
    # The unobservable direction is the visible axis itself (in Manhattan coordinates of R_cm).
    visible_c = R_true[:, 1]
    weak_axis_c = result.R_cm @ eigvec[:, -1]
    assert abs(weak_axis_c @ visible_c) > 0.99
    assert eigval[-1] >= 100 * eigval[1]
    assert eigval[-1] <= 1.0 + 1e-12  # capped
    # The visible axis itself is still found accurately.
    axis_error = np.degrees(np.arccos(np.max(np.abs(result.R_cm.T @ visible_c))))
    assert axis_error < 0.5


def test_two_visible_axes_are_fully_observable():
    rng = np.random.default_rng(6)
    R_true = exp_so3([1.0, 0.2, -0.3])
    nm = manhattan_normal_map(R_true, rng, axes=(0, 2), noise_deg=5.0)
    result = solve_manhattan(nm.normals, nm.kappa)
    assert error_deg(result.R_cm, R_true) < 0.3
    assert np.linalg.eigvalsh(result.cov)[-1] < 1e-3


def test_starts_differing_by_any_symmetry_give_equivalent_rotations():
    rng = np.random.default_rng(7)
    R_true = exp_so3([0.4, 0.3, -0.2])
    nm = manhattan_normal_map(R_true, rng, noise_deg=10.0)
    R_start = R_true @ exp_so3([0.15, -0.1, 0.05])
    base = solve_manhattan(nm.normals, nm.kappa, R_init=R_start)
    for P in manhattan_symmetries():
        result = solve_manhattan(nm.normals, nm.kappa, R_init=R_start @ P)
        np.testing.assert_allclose(result.R_cm, base.R_cm @ P, atol=1e-7)
        np.testing.assert_allclose(result.cov, P.T @ base.cov @ P, rtol=1e-5, atol=1e-12)


def test_noiseless_map_is_exact_and_covariance_stays_finite():
    rng = np.random.default_rng(8)
    R_true = exp_so3([-0.7, 0.5, 0.25])
    nm = manhattan_normal_map(R_true, rng, noise_deg=0.0, dtype=np.float64)
    result = solve_manhattan(nm.normals, nm.kappa)
    assert error_deg(result.R_cm, R_true) < 1e-6
    assert result.cost < 1e-12
    assert np.all(np.linalg.eigvalsh(result.cov) > 0)


def test_global_result_uses_the_upright_labelling():
    rng = np.random.default_rng(9)
    # An upright camera looking at a room: R_wc = Rx(-90 deg) with a 30 degree yaw.
    from scipy.spatial.transform import Rotation

    R_wc = Rotation.from_euler("zx", [30, -90], degrees=True).as_matrix()
    nm = manhattan_normal_map(R_wc.T, rng, noise_deg=5.0)
    result = solve_manhattan(nm.normals, nm.kappa)
    # m's z axis is the axis nearest image up (-y): R_wc = R_cm^T is then z-up.
    np.testing.assert_allclose((result.R_cm.T)[2], R_wc[2], atol=0.01)


def test_invalid_pixels_are_ignored_and_counted():
    rng = np.random.default_rng(10)
    R_true = exp_so3([0.1, 0.2, 0.3])
    nm = manhattan_normal_map(R_true, rng, noise_deg=5.0)
    normals, kappa = nm.normals.copy(), nm.kappa.copy()
    normals[0, :10] = np.nan
    normals[1, :5] = 0.0
    normals[2, :3] = np.inf
    kappa[3, :7] = np.nan
    kappa[4, :2] = -1.0
    result = solve_manhattan(normals, kappa)
    assert result.n_invalid == 10 + 5 + 3 + 7 + 2
    assert result.n_valid == normals.shape[0] * normals.shape[1] - result.n_invalid
    assert error_deg(result.R_cm, R_true) < 0.3
    assert np.all(np.isfinite(result.cov))


@pytest.mark.parametrize(
    "normals, kappa, message",
    [
        (np.zeros((4, 5, 2), np.float32), None, r"shape \(H, W, 3\).*\(4, 5, 2\)"),
        (np.zeros((4, 5, 3, 1), np.float32), None, r"\(4, 5, 3, 1\)"),
        (np.zeros((4, 5, 3), np.uint8), None, "floating dtype.*uint8"),
        (np.zeros((0, 5, 3), np.float32), None, "non-empty"),
        (np.ones((4, 5, 3), np.float32), np.ones((5, 4)), r"kappa of shape \(4, 5\).*got \(5, 4\)"),
        (np.ones((4, 5, 3), np.float32), np.ones((4, 5), bool), "kappa of a real numeric dtype"),
        (np.full((4, 5, 3), np.nan, np.float32), None, r"No valid normals.*\(4, 5, 3\)"),
        (np.zeros((4, 5, 3), np.float32), None, "No valid normals"),
        (np.ones((4, 5, 3), np.float32), np.zeros((4, 5)), "kappa <= 0"),
    ],
)
def test_bad_maps_raise_value_errors_that_name_the_problem(normals, kappa, message):
    with pytest.raises(ValueError, match=message):
        solve_manhattan(normals, kappa)


@pytest.mark.parametrize("R_init", [np.eye(2), np.full((3, 3), np.nan), 2 * np.eye(3), -np.eye(3)])
def test_bad_initial_rotation_is_rejected(R_init):
    nm = manhattan_normal_map(np.eye(3), np.random.default_rng(0))
    with pytest.raises(InputError, match="R_init"):
        solve_manhattan(nm.normals, nm.kappa, R_init=R_init)


def test_float64_and_float32_inputs_agree():
    rng = np.random.default_rng(11)
    nm = manhattan_normal_map(exp_so3([0.5, 0.5, 0.5]), rng, noise_deg=6.0, dtype=np.float64)
    r64 = solve_manhattan(nm.normals, nm.kappa)
    r32 = solve_manhattan(nm.normals.astype(np.float32), nm.kappa.astype(np.float32), R_init=r64.R_cm)
    assert np.degrees(angle_between(r64.R_cm, r32.R_cm)) < 1e-3
