"""The vanishing-line cost as a sextic in R, over sixth-order moments of interpretation planes.

A segment with end points x1, x2 (pixels) lies in the plane through the camera centre with unit
normal p ~ (K^-1 x1) x (K^-1 x2) (its interpretation plane). A segment along Manhattan axis r_k has
p . r_k = 0, so for R = [r1 r2 r3] (Manhattan axes as columns, camera coordinates) we use

    (L)   E_L(R) = sum_j w_j prod_k (p_j . r_k)^2 / sum_j w_j,

which is zero when each segment runs along some axis. It is bounded (prod_k c_k^2 <= 1/27 for
c on the unit sphere), so a clutter segment pulls with at most a fixed force, and it is a
homogeneous sextic in p: E_L depends on the segments only through the symmetric tensor
T6 = sum_j w_j p_j^(x6), held as the 27x27 matrix T = sum_j w_j (p^(x3))(p^(x3))^T. One pass
builds T from its 28 distinct sums (compiled, as the normals' moments; the (N, 27) cube product is
the reference); each solver iteration then rotates it (T' = K3^T T K3 with
K3 = R (x) R (x) R, the tensor seen in Manhattan coordinates) and reads off the cost, gradient and
Hessian as fixed linear functionals of T'. Those functionals come from the per-segment formulas of
`segment_derivatives` (exact polynomials) evaluated on generic points: one place for the maths.

Conventions: right perturbation `R = R_hat @ Exp(delta)`; derivatives are with respect to delta
(rad). Near a segment on axis r1, E_L ~ w (c2^2 c3^2) theta^2 with theta the plane's angle to r1:
segments whose plane also nearly contains a second axis (e.g. on the horizon line) weigh less.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .. import jit
from ..errors import InputError
from ..rotations import skew

RANDOM_LINES_COST = 1.0 / 105.0
"""E[x^2 y^2 z^2] over the unit sphere: the line cost of a rotation unrelated to the segments."""
INLIER_SINE = 0.035
"""A segment whose plane is within 2 deg of containing an axis counts as lying along it."""
AMBIGUOUS_SINE = 0.05
"""A segment whose plane nearly contains two axes (second-smallest |p . r_k| below this, 3 deg) could run
along either: it carries no information (`line_information`)."""
MIN_OTHER_AXES_SUPPORT = 0.05
"""Below this share of segments off axis k, rotation about r_k counts as unseen (`line_information`)."""
_MIN_PLANE_NORM = 1e-12


@dataclass(frozen=True)
class LineMoments:
    """Sixth-order moments of weighted interpretation-plane normals."""

    T: np.ndarray
    """(27, 27): sum_j w_j (p_j (x) p_j (x) p_j)(p_j (x) p_j (x) p_j)^T, camera coordinates."""
    total_weight: float
    n_segments: int
    n_effective: float
    """Kish's effective count (sum w)^2 / sum w^2: the number of independent segments."""
    planes: np.ndarray
    """(N, 3) the unit plane normals behind T (kept for `line_information`: N is small)."""
    weights: np.ndarray
    """(N,) their weights w_j > 0."""


def interpretation_planes(endpoints_px: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N, 3) of the planes through the camera centre and each segment, and a (N,) mask
    of the segments that define one (distinct end points). `endpoints_px` (N, 2, 2), K (3, 3)."""
    ends = np.asarray(endpoints_px, float)
    if ends.ndim != 3 or ends.shape[1:] != (2, 2):
        raise InputError(f"Expected segment end points of shape (N, 2, 2), got {ends.shape}")
    K_inv = np.linalg.inv(np.asarray(K, float))
    # K^-1 (u, v, 1) for both end points as one (2N, 2) x (2, 3) product (a stack of small
    # products is 20x slower), then the cross product by components (np.cross is 3x slower).
    rays = (ends.reshape(-1, 2) @ K_inv[:, :2].T + K_inv[:, 2]).reshape(-1, 2, 3)
    (ax, ay, az), (bx, by, bz) = np.moveaxis(rays[:, 0], 1, 0), np.moveaxis(rays[:, 1], 1, 0)
    p = np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=1)
    norm = np.sqrt(np.einsum("ij,ij->i", p, p))
    ok = np.isfinite(norm) & (norm > _MIN_PLANE_NORM)
    p = np.divide(p, norm[:, None], out=np.zeros_like(p), where=ok[:, None])
    return p, ok


def line_moments(planes: np.ndarray, weights: np.ndarray) -> LineMoments:
    """The weighted sixth-order moments (as `LineMoments`) of unit plane normals (N, 3)."""
    p = np.asarray(planes, float)
    w = np.asarray(weights, float)
    finite = np.isfinite(p[:, 0]) & np.isfinite(p[:, 1]) & np.isfinite(p[:, 2])  # 5x faster than np.all(axis=1)
    ok = np.isfinite(w) & (w > 0) & finite
    p, w = (p.copy(), w.copy()) if ok.all() else (p[ok], w[ok])  # own C-contiguous copies either way
    T = _sextic_tensor(p, w)
    s2 = float(np.dot(w, w))
    return LineMoments(T=T, total_weight=float(w.sum()), n_segments=int(len(w)),
                       n_effective=float(w.sum() ** 2 / s2) if s2 > 0 else 0.0, planes=p, weights=w)


def _cubes(p: np.ndarray) -> np.ndarray:
    """p (x) p (x) p flattened, (N, 27)."""
    return np.einsum("na,nb,nc->nabc", p, p, p).reshape(len(p), 27)


def sextic_tensor_reference(p: np.ndarray, w: np.ndarray) -> np.ndarray:
    """T = sum_j w_j (p_j^(x3))(p_j^(x3))^T, (27, 27), by one matrix product over (N, 27) cubes
    (the reference that the compiled pass of `_sextic_tensor` is tested against)."""
    P3 = _cubes(p)
    return (P3 * w[:, None]).T @ P3


def _sextic_exponents() -> tuple[np.ndarray, np.ndarray]:
    """The 28 distinct monomials x^i y^j z^k of degree 6 as exponents (28, 3), and the (27, 27)
    index of each entry of T in them (entry (abc, def) is the monomial p_a p_b p_c p_d p_e p_f)."""
    exponents = np.array([(i, j, 6 - i - j) for i in range(7) for j in range(7 - i)])
    number = {tuple(e): m for m, e in enumerate(exponents)}
    axes = np.stack(np.unravel_index(np.arange(27), (3, 3, 3)), axis=1)  # (27, 3): a, b, c of row abc
    counts = (axes[:, :, None] == np.arange(3)).sum(axis=1)  # (27, 3): how often x, y, z occur
    index = np.array([[number[tuple(ca + cb)] for cb in counts] for ca in counts])
    for a in (exponents, index):
        a.setflags(write=False)
    return exponents, index


_SEXTIC_EXPONENTS, _SEXTIC_INDEX = _sextic_exponents()


def _sextic_sums(p, w, exponents, out):
    """out[m] = sum_j w_j p_jx^i p_jy^k p_jz^l for the exponents (i, k, l) in row m: powers of each
    coordinate in (7, N) tables (one read of `p`), then one vectorised pass per monomial over them."""
    n = p.shape[0]
    wx, y, z = np.empty((7, n)), np.empty((7, n)), np.empty((7, n))
    for j in range(n):
        wx[0, j], y[0, j], z[0, j] = w[j], 1.0, 1.0
    for e in range(1, 7):
        for j in range(n):
            wx[e, j] = wx[e - 1, j] * p[j, 0]
            y[e, j] = y[e - 1, j] * p[j, 1]
            z[e, j] = z[e - 1, j] * p[j, 2]
    for m in range(exponents.shape[0]):
        a, b, c = wx[exponents[m, 0]], y[exponents[m, 1]], z[exponents[m, 2]]
        s = 0.0
        for j in range(n):
            s += a[j] * b[j] * c[j]
        out[m] = s


_sextic_kernel = jit.Kernel(_sextic_sums, cache=True, fastmath={"reassoc", "contract"})


def _sextic_tensor(p: np.ndarray, w: np.ndarray) -> np.ndarray:
    """`sextic_tensor_reference` from its 28 distinct sums, in one compiled pass (the reference
    without numba). `p` (N, 3) float64 C-contiguous, `w` (N,)."""
    if _sextic_kernel:
        sums = np.empty(len(_SEXTIC_EXPONENTS))
        if _sextic_kernel(p, w, _SEXTIC_EXPONENTS, sums) is not jit.FALLBACK:
            return sums[_SEXTIC_INDEX]
    return sextic_tensor_reference(p, w)


def normalised_line_cost(moments: LineMoments, R_cm: np.ndarray) -> np.ndarray:
    """Equation (L) for one rotation (3, 3) or a stack (..., 3, 3): T6(r1, r1, r2, r2, r3, r3) / W.
    Compiled when numba is there (`_sextic_forms`; numpy's einsums cost 11 us for one rotation, the kernel 1)."""
    R = np.asarray(R_cm, float)
    if _form_kernel and R.ndim >= 2 and R.shape[-2:] == (3, 3):
        stack, out = np.ascontiguousarray(R.reshape(-1, 3, 3)), np.empty(math.prod(R.shape[:-2]))
        if _form_kernel(moments.T, stack, out) is not jit.FALLBACK:
            out /= moments.total_weight
            return out[0] if R.ndim == 2 else out.reshape(R.shape[:-2])
    r1, r2, r3 = R[..., :, 0], R[..., :, 1], R[..., :, 2]
    a = np.einsum("...a,...b,...c->...abc", r1, r1, r2).reshape(R.shape[:-2] + (27,))
    b = np.einsum("...a,...b,...c->...abc", r2, r3, r3).reshape(R.shape[:-2] + (27,))
    return np.einsum("...a,ab,...b->...", a, moments.T, b) / moments.total_weight


def _sextic_forms(T, Rs, out):
    """out[i] = a^T T b for each rotation R = Rs[i] (n, 3, 3), a = r1 (x) r1 (x) r2 and b = r2 (x) r3 (x) r3
    (r_k its columns)."""
    a, b = np.empty(27), np.empty(27)
    for s in range(Rs.shape[0]):
        R = Rs[s]
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    a[9 * i + 3 * j + k] = R[i, 0] * R[j, 0] * R[k, 1]
                    b[9 * i + 3 * j + k] = R[i, 1] * R[j, 2] * R[k, 2]
        total = 0.0
        for m in range(27):
            row = 0.0
            for n in range(27):
                row += T[m, n] * b[n]
            total += a[m] * row
        out[s] = total


_form_kernel = jit.Kernel(_sextic_forms, cache=True, nogil=False)


def segment_derivatives(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per segment: g = prod_k u_k^2 and its gradient (3,) and Hessian (3, 3) with respect to the
    right perturbation of R at R (u = R^T p, the plane normal in Manhattan coordinates).

    With Exp(-delta) u = u + u x delta + 1/2 delta x (delta x u) + O(3):
        grad = dg(u) x u,
        Hess = [u]x^T d2g(u) [u]x + 1/2 (dg u^T + u dg^T) - (dg . u) I,   dg . u = 6 g.
    Every entry is a homogeneous sextic in u (no normalisation is used), so sums over segments
    are linear in the sixth moments. `u` is (N, 3).
    """
    u = np.asarray(u, float)
    x, y, z = u[:, 0], u[:, 1], u[:, 2]
    g = (x * y * z) ** 2
    dg = 2.0 * np.stack([x * y * y * z * z, x * x * y * z * z, x * x * y * y * z], axis=1)
    d2g = np.empty((len(u), 3, 3))
    d2g[:, 0, 0], d2g[:, 1, 1], d2g[:, 2, 2] = 2 * (y * z) ** 2, 2 * (x * z) ** 2, 2 * (x * y) ** 2
    d2g[:, 0, 1] = d2g[:, 1, 0] = 4 * x * y * z * z
    d2g[:, 0, 2] = d2g[:, 2, 0] = 4 * x * y * y * z
    d2g[:, 1, 2] = d2g[:, 2, 1] = 4 * x * x * y * z
    U = skew(u)
    grad = np.cross(dg, u)
    outer = dg[:, :, None] * u[:, None, :]
    hess = (np.swapaxes(U, 1, 2) @ d2g @ U + 0.5 * (outer + np.swapaxes(outer, 1, 2))
            - (dg * u).sum(axis=1)[:, None, None] * np.eye(3))
    return g, grad, hess


@lru_cache(maxsize=1)
def _functionals() -> np.ndarray:
    """(13, 729): cost, gradient (3) and Hessian (9) of `segment_derivatives` as linear functionals
    of the rotated sixth-moment tensor (exact: fitted on generic points, where they are polynomials)."""
    u = np.random.default_rng(6).normal(size=(120, 3))
    g, grad, hess = segment_derivatives(u)
    values = np.concatenate([g[:, None], grad, hess.reshape(-1, 9)], axis=1)  # (120, 13)
    P3 = _cubes(u)
    basis = np.einsum("na,nb->nab", P3, P3).reshape(len(u), 729)
    coef, *_ = np.linalg.lstsq(basis, values, rcond=None)
    out = coef.T.copy()
    out.setflags(write=False)
    return out


def _kron(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """np.kron of two square matrices by one broadcast product (the same numbers; np.kron's general
    path cost 26 us of the 6 us here for R x R x R, called at every solver iteration)."""
    n, m = len(A), len(B)
    return (A[:, None, :, None] * B[None, :, None, :]).reshape(n * m, n * m)


def line_cost_gradient_hessian(moments: LineMoments, R_cm: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Equation (L), its gradient (3,) and Hessian (3, 3) with respect to the right perturbation of `R_cm`.
    Compiled when numba is there (`_rotated_functionals`; 87 us a call with numpy's products, 26 with the kernel)."""
    R = np.asarray(R_cm, float)
    values = np.empty(13)
    if not _functionals_kernel or _functionals_kernel(moments.T, np.ascontiguousarray(R), _functionals(),
                                                      values) is jit.FALLBACK:
        K3 = _kron(_kron(R, R), R)
        values = _functionals() @ (K3.T @ moments.T @ K3).reshape(729)
    values /= moments.total_weight
    hess = values[4:].reshape(3, 3)
    return float(values[0]), values[1:4], 0.5 * (hess + hess.T)


def _rotated_functionals(T, R, F, out):
    """out = F @ vec(K3^T T K3) with K3 = R (x) R (x) R (27, 27): the functionals F (13, 729) of the
    tensor T (27, 27) seen in Manhattan coordinates."""
    K = np.empty((27, 27))  # `_kron(_kron(R, R), R)`: entry (9i + 3j + k, 9a + 3b + c) is R_ia R_jb R_kc
    for p in range(27):
        for q in range(27):
            K[p, q] = R[p // 9, q // 9] * R[p // 3 % 3, q // 3 % 3] * R[p % 3, q % 3]
    out[:] = F @ (K.T @ (T @ K)).reshape(729)


_functionals_kernel = jit.Kernel(_rotated_functionals, cache=True, nogil=False, fastmath={"reassoc", "contract"})


def line_information(moments: LineMoments, R_cm: np.ndarray) -> np.ndarray:
    """Gauss-Newton Hessian (3, 3) of equation (L) at `R_cm`, each segment assigned to its nearest axis.

    Near the minimum a segment's term is w a theta^2, theta = c_k the sine of its plane's angle to
    the assigned axis r_k and a = prod_{l != k} c_l^2 held fixed, and grad c_k = e_k x u (u = R^T p).
    Unlike the full Hessian this has no curvature from the a factors, which vary with rotations that
    the segments cannot see (about the axis of parallel-only lines): such a direction gets zero.
    """
    u = moments.planes @ np.asarray(R_cm, float)
    if len(u) == 0:
        return np.zeros((3, 3))
    order = np.argsort(np.abs(u), axis=1)
    k, second = order[:, 0], np.abs(u[np.arange(len(u)), order[:, 1]])
    others = u**2
    others[np.arange(len(u)), k] = 1.0
    a = np.prod(others, axis=1) * (second >= AMBIGUOUS_SINE)
    grad = np.cross(np.eye(3)[k], u)
    info = 2.0 * np.einsum("n,na,nb->ab", moments.weights * a, grad, grad) / moments.total_weight
    # Rotation about r_k is seen only by segments along the other axes: with (almost) none, drop it.
    support = np.bincount(k, weights=moments.weights * (second >= AMBIGUOUS_SINE), minlength=3)
    blind = (support.sum() - support) < MIN_OTHER_AXES_SUPPORT * max(support.sum(), 1e-300)
    info[blind, :] = 0.0
    info[:, blind] = 0.0
    return info


def inlier_fraction(moments: LineMoments, R_cm: np.ndarray, max_sine: float = INLIER_SINE) -> float:
    """Weighted fraction of segments whose plane is within asin(`max_sine`) of containing some axis."""
    if moments.total_weight <= 0:
        return 0.0
    c = nearest_axis_sine(moments, R_cm)
    return float(moments.weights[c < max_sine].sum() / moments.total_weight)


def nearest_axis_sine(moments: LineMoments, R_cm: np.ndarray) -> np.ndarray:
    """c_j = min_k |p_j . r_k| (N,), or (..., N) for a stack of rotations (..., 3, 3): the sine of each
    segment plane's angle to the axis it nearly contains."""
    return np.abs(moments.planes @ np.asarray(R_cm, float)).min(axis=-1)


def cauchy_line_cost(moments: LineMoments, R_cm: np.ndarray, scale_sine: float) -> float | np.ndarray:
    """The robust line cost sum_j w_j log(1 + (c_j / scale)^2) / sum_j w_j (c_j of `nearest_axis_sine`).

    Quadratic in c_j near an axis like equation (L), but it grows only logarithmically for clutter
    instead of in proportion to the other axes' factors, so it ranks rotations by how many segments they
    explain. One value for a rotation (3, 3), an array for a stack (..., 3, 3)."""
    if moments.total_weight <= 0:
        return 0.0 if np.ndim(R_cm) == 2 else np.zeros(np.shape(R_cm)[:-2])
    c = nearest_axis_sine(moments, R_cm)
    cost = np.log1p((c / scale_sine) ** 2) @ moments.weights / moments.total_weight
    return float(cost) if np.ndim(cost) == 0 else cost


def cauchy_reweighted(moments: LineMoments, R_cm: np.ndarray, scale_sine: float) -> LineMoments:
    """The moments of the same planes with weights w_j / (1 + (c_j / scale)^2) at `R_cm`: one step of
    iteratively reweighted least squares for the Cauchy loss of `cauchy_line_cost`, on equation (L)."""
    c = nearest_axis_sine(moments, R_cm)
    return line_moments(moments.planes, moments.weights / (1.0 + (c / scale_sine) ** 2))
