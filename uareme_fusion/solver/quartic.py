"""The Manhattan cost as a quartic in R, with its gradient and Hessian on SO(3).

Conventions: `R_cm` has the Manhattan axes r_k (in camera coordinates) as columns; the perturbation
is on the right, `R = R_hat @ Exp(delta)`, so derivatives are with respect to `delta` (rad).
All functions take the 6x6 moment Gram matrix `G` (see `moments.py`) and the total weight `W`.
"""

from __future__ import annotations

import math

import numpy as np

from .. import jit
from ..rotations import skew

_E_SKEW = skew(np.eye(3))  # [e_k]x for k = 0, 1, 2


def axis_monomials(r: np.ndarray) -> np.ndarray:
    """(r . n)^2 = axis_monomials(r) . q(n): (..., 3) -> (..., 6) = (x^2, y^2, z^2, 2xy, 2xz, 2yz)."""
    return r[..., _FIRST] * r[..., _SECOND] * _TWICE_CROSS


_FIRST, _SECOND = np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2])
_TWICE_CROSS = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def normalised_cost(G: np.ndarray, W: float, R_cm: np.ndarray) -> np.ndarray:
    """Paper eq. 1 summed over axes and pixels, divided by sum w: 1 - sum_k sum_i w_i (n_i.r_k)^4 / W.

    `R_cm` may be a stack (..., 3, 3); the result has shape (...). Compiled when numba is there
    (`_fourth_moment_sums`; numpy's small products cost 13 us for one rotation, the kernel 1).
    """
    R = np.asarray(R_cm, dtype=float)
    if _fourth_kernel and R.ndim >= 2 and R.shape[-2:] == (3, 3):
        stack, fourth = np.ascontiguousarray(R.reshape(-1, 3, 3)), np.empty(math.prod(R.shape[:-2]))
        if _fourth_kernel(G, stack, fourth) is not jit.FALLBACK:
            cost = 1.0 - fourth / W
            return cost[0] if R.ndim == 2 else cost.reshape(R.shape[:-2])
    a = axis_monomials(np.swapaxes(R, -1, -2))  # rows of R^T are the axes r_k: (..., 3, 6)
    fourth = np.sum((a @ G) * a, axis=(-2, -1))  # sum_k a_k^T G a_k
    return 1.0 - fourth / W


def _fourth_moment_sums(G, Rs, out):
    """out[i] = sum_k a_k^T G a_k for each rotation Rs[i] (n, 3, 3), a_k = `axis_monomials` of its column r_k."""
    a = np.empty(6)
    for s in range(Rs.shape[0]):
        total = 0.0
        for k in range(3):
            x, y, z = Rs[s, 0, k], Rs[s, 1, k], Rs[s, 2, k]
            a[0], a[1], a[2], a[3], a[4], a[5] = x * x, y * y, z * z, 2.0 * x * y, 2.0 * x * z, 2.0 * y * z
            for j in range(6):
                row = 0.0
                for i in range(6):
                    row += a[i] * G[i, j]
                total += row * a[j]
        out[s] = total


_fourth_kernel = jit.Kernel(_fourth_moment_sums, cache=True, nogil=False)


def gradient_hessian(T: np.ndarray, W: float, R_cm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (3,) and Hessian (3, 3) of `normalised_cost` with respect to the right perturbation.

    With M_k = R^T T(r_k, r_k, ., .) R (the tensor seen in Manhattan coordinates), v_k = M_k e_k and
    t_k = e_k^T v_k, expanding F = sum_k T(u_k^4), u_k = Exp(delta) e_k to second order gives
        grad F = 4 sum_k e_k x v_k
        Hess F = sum_k 12 [e_k]x^T M_k [e_k]x + 2 (e_k v_k^T + v_k e_k^T) - 4 t_k I,
    and the normalised cost is 1 - F / W. (Small matrix products, not einsum: this runs in every
    solver iteration; compiled, `_quartic_derivatives`, when numba is there.)
    """
    R = np.asarray(R_cm, dtype=float)
    if _derivatives_kernel:
        grad, hess = np.empty(3), np.empty((3, 3))
        if _derivatives_kernel(T, R, _E_SKEW, grad, hess) is not jit.FALLBACK:
            return grad / W, hess / W
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


def _quartic_derivatives(T, R, e_skew, grad, hess):
    """`gradient_hessian`'s -grad F (3,) and -Hess F (3, 3) into `grad` and `hess` (before the division by W),
    by loops over its small products: T (3, 3, 3, 3), R (3, 3), `e_skew` the three [e_k]x (3, 3, 3)."""
    M = np.zeros((3, 3, 3))
    A = np.empty((3, 3))
    for k in range(3):
        A[:, :] = 0.0
        for a in range(3):
            for b in range(3):
                rr = R[a, k] * R[b, k]
                for c in range(3):
                    for d in range(3):
                        A[c, d] += rr * T[a, b, c, d]
        for i in range(3):  # M_k = R^T A_k R
            for j in range(3):
                s = 0.0
                for c in range(3):
                    for d in range(3):
                        s += R[c, i] * A[c, d] * R[d, j]
                M[k, i, j] = s
    v = np.empty((3, 3))  # row k: v_k = M_k e_k
    for k in range(3):
        for i in range(3):
            v[k, i] = M[k, i, k]
    grad[0] = -4.0 * (v[1, 2] - v[2, 1])
    grad[1] = -4.0 * (v[2, 0] - v[0, 2])
    grad[2] = -4.0 * (v[0, 1] - v[1, 0])
    trace = v[0, 0] + v[1, 1] + v[2, 2]
    for a in range(3):
        for d in range(3):
            sandwich = 0.0  # sum_k ([e_k]x^T M_k [e_k]x)[a, d]
            for k in range(3):
                for b in range(3):
                    for c in range(3):
                        sandwich += e_skew[k, b, a] * M[k, b, c] * e_skew[k, c, d]
            hess[a, d] = -(12.0 * sandwich + 2.0 * (v[a, d] + v[d, a]) - (4.0 * trace if a == d else 0.0))


_derivatives_kernel = jit.Kernel(_quartic_derivatives, cache=True, nogil=False)
