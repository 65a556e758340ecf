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
    x, y, z = r[..., 0], r[..., 1], r[..., 2]
    return np.stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z], axis=-1)


def normalised_cost(G: np.ndarray, W: float, R_cm: np.ndarray) -> np.ndarray:
    """Paper eq. 1 summed over axes and pixels, divided by sum w: 1 - sum_k sum_i w_i (n_i.r_k)^4 / W.

    `R_cm` may be a stack (..., 3, 3); the result has shape (...).
    """
    a = axis_monomials(np.swapaxes(R_cm, -1, -2))  # rows of R^T are the axes r_k: (..., 3, 6)
    fourth = np.einsum("...ka,ab,...kb->...", a, G, a)
    return 1.0 - fourth / W


def gradient_hessian(T: np.ndarray, W: float, R_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (3,) and Hessian (3, 3) of `normalised_cost` with respect to the right perturbation.

    With M_k = R^T T(r_k, r_k, ., .) R (the tensor seen in Manhattan coordinates), v_k = M_k e_k and
    t_k = e_k^T v_k, expanding F = sum_k T(u_k^4), u_k = Exp(delta) e_k to second order gives
        grad F = 4 sum_k e_k x v_k
        Hess F = sum_k 12 [e_k]x^T M_k [e_k]x + 2 (e_k v_k^T + v_k e_k^T) - 4 t_k I,
    and the normalised cost is 1 - F / W.
    """
    A = np.einsum("ijab,ik,jk->kab", T, R_cm, R_cm)  # T(r_k, r_k, ., .)
    M = np.einsum("ak,xab,bl->xkl", R_cm, A, R_cm)  # R^T A_x R for each axis x
    idx = np.arange(3)
    v = M[idx, :, idx]  # v_k = M_k e_k, shape (3, 3): row k is v_k
    t = v[idx, idx]
    grad_F = 4.0 * np.cross(np.eye(3), v).sum(axis=0)
    ev = np.eye(3)[:, :, None] * v[:, None, :]  # e_k v_k^T
    hess_F = (
        12.0 * np.einsum("kba,kbc,kcd->ad", _E_SKEW, M, _E_SKEW)
        + 2.0 * (ev + np.swapaxes(ev, 1, 2)).sum(axis=0)
        - 4.0 * t.sum() * np.eye(3)
    )
    return -grad_F / W, -hess_F / W
