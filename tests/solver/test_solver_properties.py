"""Property-based: for any finite input the solver's outputs are finite and R_cm is a rotation."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from uareme_fusion import InputError, solve_manhattan

finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False, width=32)
anything = st.floats(width=32)  # NaN and infinities included


@settings(max_examples=60, deadline=None)
@given(
    normals=arrays(np.float32, st.tuples(st.integers(1, 6), st.integers(1, 6), st.just(3)), elements=anything),
    kappa_scale=st.floats(0.0, 1e4),
    use_prior=st.booleans(),
)
def test_outputs_finite_and_orthonormal_or_clear_error(normals, kappa_scale, use_prior):
    kappa = np.full(normals.shape[:2], kappa_scale, np.float32)
    R_init = np.eye(3) if use_prior else None
    try:
        result = solve_manhattan(normals, kappa, R_init=R_init)
    except InputError as exc:
        assert "No valid normals" in str(exc)
        return
    assert np.all(np.isfinite(result.R_cm)) and np.all(np.isfinite(result.cov))
    np.testing.assert_allclose(result.R_cm.T @ result.R_cm, np.eye(3), atol=1e-9)
    assert np.linalg.det(result.R_cm) > 0
    assert np.all(np.linalg.eigvalsh(result.cov) > 0)
    assert 0.0 <= result.cost <= 1.0 + 1e-9
    assert result.n_valid + result.n_invalid <= normals.shape[0] * normals.shape[1]


@settings(max_examples=40, deadline=None)
@given(normals=arrays(np.float64, st.tuples(st.integers(3, 40), st.just(3)), elements=finite))
def test_any_finite_point_cloud_of_normals(normals):
    try:
        result = solve_manhattan(normals)
    except InputError:
        assert not np.any(np.sum(normals.astype(np.float32) ** 2, axis=1) > 1e-12)
        return
    np.testing.assert_allclose(result.R_cm.T @ result.R_cm, np.eye(3), atol=1e-9)
    assert np.all(np.isfinite(result.cov))
