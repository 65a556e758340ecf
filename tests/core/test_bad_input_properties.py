"""Property-based bad input (hypothesis), extending tests/solver/test_solver_properties.py and
tests/backends/test_mekf_bad_input.py: per-pixel kappa of any value, any rotation prior, extreme scales and
degenerate maps for the solver; any depth map and intrinsics for depth normals; visual rotations
with any covariance (tiny, huge, ill-conditioned) and any frame timing for the MEKF, through its
public API. Outputs stay finite, rotations orthonormal, covariances symmetric positive."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from uareme_fusion import InputError, solve_manhattan
from uareme_fusion.backends.mekf import Mekf, MekfConfig
from uareme_fusion.normals.depth import DepthNormals
from uareme_fusion.types import VisualRotation

any_float32 = st.floats(width=32)  # NaN and infinities included
unit_quaternions = arrays(np.float64, 4, elements=st.floats(-1.0, 1.0)).filter(lambda q: np.linalg.norm(q) > 0.1)


def assert_rotation(R, atol=1e-6):
    assert np.all(np.isfinite(R))
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=atol)
    assert np.linalg.det(R) > 0


def assert_covariance(P):
    assert np.all(np.isfinite(P))
    np.testing.assert_allclose(P, P.T, atol=1e-9 * max(1.0, np.abs(P).max()))
    assert np.linalg.eigvalsh(0.5 * (P + P.T)).min() > -1e-9 * max(1.0, np.abs(P).max())


@settings(max_examples=40, deadline=None)
@given(
    normals=arrays(np.float32, st.tuples(st.integers(1, 5), st.integers(1, 5), st.just(3)),
                   elements=st.floats(-1e3, 1e3, width=32)),
    kappa=arrays(np.float32, 25, elements=any_float32),
    prior=st.one_of(st.none(), unit_quaternions),
)
def test_solver_any_kappa_per_pixel_and_any_prior(normals, kappa, prior):
    kappa = kappa[: normals.shape[0] * normals.shape[1]].reshape(normals.shape[:2])
    R_init = None if prior is None else Rotation.from_quat(prior).as_matrix()
    try:
        result = solve_manhattan(normals, kappa, R_init=R_init)
    except InputError as exc:
        assert "No valid normals" in str(exc)
        return
    assert_rotation(result.R_cm, atol=1e-9)
    assert_covariance(result.cov)
    assert np.linalg.eigvalsh(result.cov).min() > 0
    assert result.n_valid + result.n_invalid <= kappa.size  # kappa 0 is "no information", neither
    assert result.n_invalid >= int(np.sum(~np.isfinite(kappa) | (kappa < 0)))


@settings(max_examples=30, deadline=None)
@given(scale_exp=st.integers(-5, 30), axes=st.integers(1, 3), quat=unit_quaternions, seed=st.integers(0, 2**16))
def test_solver_extreme_scales_and_degenerate_views(scale_exp, axes, quat, seed):
    """Normals of any length (1e-5 to 1e30) along 1, 2 or 3 Manhattan axes: rotation finite,
    unobservable axes capped. (Normals shorter than 1e-6 count as zero-length: invalid.)"""
    rng = np.random.default_rng(seed)
    R_cm = Rotation.from_quat(quat).as_matrix()
    signs = rng.choice([-1.0, 1.0], size=(60, 1))
    normals = (R_cm[:, rng.integers(0, axes, 60)].T * signs + rng.normal(0, 0.01, (60, 3))) * 10.0**scale_exp
    result = solve_manhattan(normals)
    assert result.n_valid == 60
    assert_rotation(result.R_cm, atol=1e-9)
    assert_covariance(result.cov)
    assert np.linalg.eigvalsh(result.cov).max() <= 1.0 + 1e-12  # SolverConfig.max_variance_rad2 cap


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    depth=arrays(np.float32, st.tuples(st.integers(9, 20), st.integers(9, 20)), elements=any_float32),
    f=st.floats(0.5, 1e5),
    c=st.tuples(st.floats(-1e3, 1e3), st.floats(-1e3, 1e3)),
)
def test_depth_normals_any_depth_and_intrinsics(depth, f, c):
    K = np.array([[f, 0.0, c[0]], [0.0, f * 1.1, c[1]], [0.0, 0.0, 1.0]])
    nm = DepthNormals().estimate(depth, K)
    assert nm.normals.shape == depth.shape + (3,) and nm.kappa.shape == depth.shape
    assert np.all(np.isfinite(nm.normals)) and np.all(np.isfinite(nm.kappa))
    assert np.all((nm.kappa >= 0) & (nm.kappa <= DepthNormals().config.kappa_max))
    length = np.linalg.norm(nm.normals, axis=-1)
    assert np.all((np.abs(length - 1) < 1e-3) | (length == 0))
    assert np.all(nm.kappa[~((depth > 0.1) & (depth < 20.0))] == 0)  # no confidence without own depth


def covariance_from(values, log_scale):
    """A symmetric positive matrix 10^log_scale * A A^T + tiny, possibly very ill-conditioned."""
    A = np.asarray(values, float).reshape(3, 3)
    return 10.0**log_scale * (A @ A.T) + 1e-14 * np.eye(3)


frame_events = st.lists(
    st.tuples(
        st.floats(1e-3, 3.0),  # time since the previous frame, s
        st.one_of(st.none(), unit_quaternions),  # visual R_cm, or no visual rotation
        st.lists(st.floats(-10, 10), min_size=9, max_size=9),
        st.integers(-12, 4),  # covariance scale 1e-12 .. 1e4 rad^2
    ),
    min_size=1,
    max_size=12,
)


@pytest.mark.parametrize("mode", ["visual_only", "auto"])
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(events=frame_events, gyro=st.lists(st.floats(-30, 30), min_size=3, max_size=3))
def test_mekf_any_visual_rotation_covariance_and_timing(mode, events, gyro):
    filt = Mekf(MekfConfig(mode=mode))
    t = 0.0
    for dt, quat, cov_values, log_scale in events:
        t_prev, t = t, t + dt
        if mode == "auto":  # constant-rate IMU between frames (up to a few hundred samples)
            t_imu = np.arange(t_prev, t, 0.005)[:600]
            if len(t_imu):
                n = len(t_imu)
                filt.process_imu(t_imu, np.tile(gyro, (n, 1)), np.tile([0.0, -9.81, 0.0], (n, 1)))
        visual = None
        if quat is not None:
            cov = covariance_from(cov_values, log_scale)
            assume(np.all(np.isfinite(cov)))
            visual = VisualRotation(R_cm=Rotation.from_quat(quat).as_matrix(), cov=cov, cost=0.05, iterations=3,
                                    n_valid=100, t_s=t)
        est = filt.process_frame(t, visual)
        assert_rotation(est.R_wc)
        assert_covariance(est.cov)
        if est.R_wm is not None:
            assert_rotation(est.R_wm)
        assert np.all(np.isfinite(est.up_c)) and abs(np.linalg.norm(est.up_c) - 1) < 1e-6
        predicted = filt.predicted_R_cm(t + 0.01)
        if predicted is not None:
            assert_rotation(predicted)


BROKEN_COVARIANCES = {
    "nan": np.full((3, 3), np.nan), "inf": np.diag([np.inf] * 3), "negative": -np.eye(3), "zero": np.zeros((3, 3)),
    "asymmetric": np.array([[1e-4, 1.0, 0], [0, 1e-4, 0], [0, 0, 1e-4]]), "wrong_shape": np.eye(2),
}
@pytest.mark.parametrize(
    "bad", list(BROKEN_COVARIANCES))
@pytest.mark.parametrize("rotvec", [(0.0, 0.0, 0.0), (0.3, 0.2, 0.1), (2.0, 0.5, -1.0)], ids=["same", "near", "far"])
def test_mekf_rejects_or_survives_a_broken_visual_covariance(bad, rotvec):
    """A visual rotation whose covariance is not a covariance: a clear error, or a finite state."""
    filt = Mekf(MekfConfig(mode="visual_only"))
    good = VisualRotation(R_cm=np.eye(3), cov=1e-4 * np.eye(3), cost=0.05, iterations=3, n_valid=100)
    filt.process_frame(0.0, good)
    visual = VisualRotation(R_cm=Rotation.from_rotvec(rotvec).as_matrix(), cov=BROKEN_COVARIANCES[bad], cost=0.05,
                            iterations=3, n_valid=100)
    try:
        with np.errstate(invalid="ignore"):
            est = filt.process_frame(0.1, visual)
    except InputError:
        return
    assert_rotation(est.R_wc)
    assert_covariance(est.cov)
