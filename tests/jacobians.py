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
