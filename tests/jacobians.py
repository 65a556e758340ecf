"""Finite-difference Jacobians for testing analytic ones (a helper module, not a test module)."""

from __future__ import annotations

import numpy as np


def fd_jacobian(f, n: int, eps: float = 1e-6) -> np.ndarray:
    """(m, n) central-difference Jacobian at 0 of `f`, a map from an (n,) perturbation to an (m,)
    vector: column i is `(f(eps e_i) - f(-eps e_i)) / (2 eps)`."""
    columns = []
    for i in range(n):
        d = np.zeros(n)
        d[i] = eps
        columns.append((np.asarray(f(d), float) - np.asarray(f(-d), float)) / (2 * eps))
    return np.stack(columns, axis=1)


def check_measurement_model(measure, n: int = 12, eps: float = 1e-6, atol: float = 1e-8):
    """A measurement model against the contract of `backends.mekf.measurements`: `measure(dx)` is the
    model's `Measurement` of one fixed measurement at the state `x (+) dx` (n,). At `x` it applies, its
    covariance is symmetric positive definite and its jacobian H is the central-difference derivative
    of `residual(x) - residual(x (+) dx)`. Returns the `Measurement` at `x`."""
    at_x = measure(np.zeros(n))
    assert at_x.ok
    R = np.asarray(at_x.covariance)
    np.testing.assert_array_equal(R, R.T)
    assert np.linalg.eigvalsh(R).min() > 0
    fd = fd_jacobian(lambda dx: at_x.residual - measure(dx).residual, n, eps)
    np.testing.assert_allclose(fd, at_x.jacobian, atol=atol)
    return at_x
