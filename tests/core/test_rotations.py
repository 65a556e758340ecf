import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from uareme_fusion.rotations import (
    align_constant,
    angle_between,
    are_deg,
    exp_so3,
    log_so3,
    manhattan_symmetries,
    matrix_from_quat_xyzw,
    nearest_symmetric,
    nees,
    project_to_so3,
    quat_xyzw,
    skew,
    tilt_error_deg,
    up_in_camera,
)


def test_exp_log_round_trip_and_skew():
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(50, 3))
    phi *= (np.pi * 0.99 * rng.random(50) / np.linalg.norm(phi, axis=1))[:, None]
    np.testing.assert_allclose(log_so3(exp_so3(phi)), phi, atol=1e-9)
    a, b = rng.normal(size=3), rng.normal(size=3)
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b))
    # Small-angle: Exp(phi) ~ I + [phi]x
    small = 1e-7 * a
    np.testing.assert_allclose(exp_so3(small), np.eye(3) + skew(small), atol=1e-13)


def test_symmetry_group_is_the_24_proper_signed_permutations():
    G = manhattan_symmetries()
    assert G.shape == (24, 3, 3)
    np.testing.assert_array_equal(G[0], np.eye(3))
    assert np.allclose(np.linalg.det(G), 1.0)
    assert set(np.unique(np.abs(G))) == {0.0, 1.0}
    keys = {np.rint(g).astype(int).tobytes() for g in G}
    assert len(keys) == 24
    # Closed under composition.
    for a in G[::5]:
        for b in G[::7]:
            assert np.rint(a @ b).astype(int).tobytes() in keys


def test_nearest_symmetric_finds_the_closest_relabelling():
    rng = np.random.default_rng(1)
    G = manhattan_symmetries()
    for _ in range(20):
        R_ref = exp_so3(rng.normal(size=3))
        P_true = G[rng.integers(24)]
        R_cm = R_ref @ exp_so3(0.2 * rng.normal(size=3) / np.sqrt(3)) @ P_true.T
        R_near, P = nearest_symmetric(R_cm, R_ref)
        np.testing.assert_allclose(P, P_true)
        angles = angle_between(R_ref, R_cm @ G)
        assert angle_between(R_ref, R_near) == pytest.approx(angles.min())


def test_constant_alignment_and_are():
    rng = np.random.default_rng(2)
    R_gt = exp_so3(rng.normal(size=(30, 3)))
    A = exp_so3([0.3, -1.0, 2.0])
    R_est = A.T @ R_gt  # the estimate's world differs by a constant rotation
    np.testing.assert_allclose(align_constant(R_est, R_gt), A, atol=1e-9)
    assert are_deg(R_est, R_gt).max() < 1e-6
    assert are_deg(R_est, R_gt, align=False).min() > 10
    # Per-frame errors of 2 degrees about random axes survive the alignment (it absorbs little).
    axes = rng.normal(size=(30, 3))
    R_err = R_est @ exp_so3(np.radians(2.0) * axes / np.linalg.norm(axes, axis=1, keepdims=True))
    assert np.median(are_deg(R_err, R_gt)) == pytest.approx(2.0, abs=0.4)


def test_up_and_tilt():
    R_wc = Rotation.from_euler("x", -90, degrees=True).as_matrix()  # camera looking horizontally
    # Camera z forward is horizontal, camera y (down) must point to world -z.
    np.testing.assert_allclose(up_in_camera(R_wc), [0, -1, 0], atol=1e-12)
    tilted = R_wc @ exp_so3([0, 0, np.radians(5)])  # roll of 5 degrees
    assert tilt_error_deg(up_in_camera(tilted), up_in_camera(R_wc)) == pytest.approx(5.0)


def test_nees_of_exact_gaussian_errors_averages_three():
    rng = np.random.default_rng(3)
    L = np.array([[0.02, 0, 0], [0.01, 0.05, 0], [0.0, -0.01, 0.03]])
    cov = L @ L.T
    R_est = exp_so3(rng.normal(size=(4000, 3)))
    R_true = R_est @ exp_so3(rng.normal(size=(4000, 3)) @ L.T)
    values = nees(R_est, R_true, np.broadcast_to(cov, (4000, 3, 3)))
    assert values.mean() == pytest.approx(3.0, abs=0.15)


def test_quaternion_order_and_projection():
    R = exp_so3([0.1, 0.2, 0.3])
    q = quat_xyzw(R)
    assert q[3] > 0
    np.testing.assert_allclose(matrix_from_quat_xyzw(q), R, atol=1e-12)
    np.testing.assert_allclose(quat_xyzw(np.eye(3)), [0, 0, 0, 1])
    noisy = R + 1e-3 * np.random.default_rng(4).normal(size=(3, 3))
    P = project_to_so3(noisy)
    np.testing.assert_allclose(P.T @ P, np.eye(3), atol=1e-12)
    assert np.linalg.det(P) == pytest.approx(1.0)


def test_nees_leaves_gauge_directions_out_and_yaw_alignment():
    rng = np.random.default_rng(5)
    cov = np.diag([1e-4, 4e-4, 0.0])  # third direction is a gauge (variance 0)
    R_est = exp_so3(rng.normal(size=(3000, 3)))
    d = rng.normal(size=(3000, 3)) * np.sqrt([1e-4, 4e-4, 0.0])
    R_true = R_est @ exp_so3(d)
    values = nees(R_est, R_true, np.broadcast_to(cov, (3000, 3, 3)), gauge_variance_rad2=1e-12)
    assert values.mean() == pytest.approx(2.0, abs=0.15)  # two degrees of freedom remain
    from uareme_fusion.rotations import align_yaw

    A = exp_so3([0.0, 0.0, 0.7])
    R_gt = exp_so3(rng.normal(size=(20, 3)))
    np.testing.assert_allclose(align_yaw(A.T @ R_gt, R_gt), A, atol=1e-9)
