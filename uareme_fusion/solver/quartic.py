"""The Manhattan cost as a quartic in R, with its gradient and Hessian on SO(3).

Conventions: `R_cm` has the Manhattan axes r_k (in camera coordinates) as columns; the perturbation
is on the right, `R = R_hat @ Exp(delta)`, so derivatives are with respect to `delta` (rad).
All functions take the 6x6 moment Gram matrix `G` (see `moments.py`) and the total weight `W`.
"""

from __future__ import annotations

import numpy as np

from ..rotations import skew

_E_SKEW = skew(np.eye(3))  # [e_k]x for k = 0, 1, 2


def axis_monomials(r: np.ndarray) -> np.ndarray:
    """(r . n)^2 = axis_monomials(r) . q(n): (..., 3) -> (..., 6) = (x^2, y^2, z^2, 2xy, 2xz, 2yz)."""
    return r[..., _FIRST] * r[..., _SECOND] * _TWICE_CROSS


_FIRST, _SECOND = np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2])
_TWICE_CROSS = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def normalised_cost(G: np.ndarray, W: float, R_cm: np.ndarray) -> np.ndarray:
    """Paper eq. 1 summed over axes and pixels, divided by sum w: 1 - sum_k sum_i w_i (n_i.r_k)^4 / W.

    `R_cm` may be a stack (..., 3, 3); the result has shape (...).
    """
    a = axis_monomials(np.swapaxes(R_cm, -1, -2))  # rows of R^T are the axes r_k: (..., 3, 6)
    fourth = np.sum((a @ G) * a, axis=(-2, -1))  # sum_k a_k^T G a_k
    return 1.0 - fourth / W


def gradient_hessian(T: np.ndarray, W: float, R_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (3,) and Hessian (3, 3) of `normalised_cost` with respect to the right perturbation.

    With M_k = R^T T(r_k, r_k, ., .) R (the tensor seen in Manhattan coordinates), v_k = M_k e_k and
    t_k = e_k^T v_k, expanding F = sum_k T(u_k^4), u_k = Exp(delta) e_k to second order gives
        grad F = 4 sum_k e_k x v_k
        Hess F = sum_k 12 [e_k]x^T M_k [e_k]x + 2 (e_k v_k^T + v_k e_k^T) - 4 t_k I,
    and the normalised cost is 1 - F / W. (Small matrix products, not einsum: this runs in every
    solver iteration.)
    """
    R = np.asarray(R_cm, dtype=float)
    rr = (R[:, None, :] * R[None, :, :]).reshape(9, 3)  # column k: r_k (x) r_k
    A = (rr.T @ T.reshape(9, 9)).reshape(3, 3, 3)  # A[k] = T(r_k, r_k, ., .)
    M = R.T @ A @ R  # M[k] = R^T A_k R
    v = M[_AXES, :, _AXES]  # v_k = M_k e_k, shape (3, 3): row k is v_k
    grad_F = 4.0 * np.array([v[1, 2] - v[2, 1], v[2, 0] - v[0, 2], v[0, 1] - v[1, 0]])  # sum_k e_k x v_k
    hess_F = (12.0 * (_SKEW_SANDWICH @ M.reshape(27)).reshape(3, 3)
              + 2.0 * (v + v.T)  # sum_k e_k v_k^T is the matrix with rows v_k
              - 4.0 * np.trace(v) * np.eye(3))
    return -grad_F / W, -hess_F / W


_AXES = np.arange(3)
_SKEW_SANDWICH = np.einsum("kba,kcd->adkbc", _E_SKEW, _E_SKEW).reshape(9, 27)
"""sum_k [e_k]x^T M_k [e_k]x as a linear map of M (3, 3, 3) flattened."""
