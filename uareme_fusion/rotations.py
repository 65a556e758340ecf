"""Rotation helpers on top of scipy's `Rotation`.

Conventions (see docs/design.md):
- `R_ab` maps coordinates in frame b to frame a: `v_a = R_ab @ v_b`.
- Perturbations are on the right: `R = R_hat @ Exp(delta)`; a covariance is that of `delta` (rad^2).
- Every function accepts a single (3, 3) matrix or a stack (..., 3, 3) where it says so.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

WORLD_UP = np.array([0.0, 0.0, 1.0])
"""The world frame's up direction (z up; gravity is -9.81 m/s^2 along it)."""
R_CM_UPRIGHT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Labelling used when there is no prior: m's x is nearest camera right, m's z nearest image up
(-y in OpenCV), so that `R_wc = R_cm^T` is z-up for an upright camera."""


def rotation_problem(R, atol: float = 1e-6) -> str | None:
    """None when `R` is a finite (3, 3) rotation matrix (|R^T R - I| <= atol everywhere, det > 0),
    else what is wrong with it, in words for an error message. The one rotation validator: callers
    raise their own error type naming the option or file."""
    try:
        R = np.asarray(R, dtype=float)
    except (TypeError, ValueError):
        return "not a matrix of numbers"
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        return f"expected a finite 3x3 rotation matrix, got shape {R.shape}"
    deviation = np.abs(R.T @ R - np.eye(3)).max()
    if deviation > atol:
        return f"the 3x3 is not orthonormal (max |R^T R - I| = {deviation:.2g})"
    if np.linalg.det(R) <= 0:
        return "the 3x3 is a reflection (det -1), not a rotation"
    return None


def is_rotation(R, atol: float = 1e-6) -> bool:
    """True when `rotation_problem(R, atol)` finds nothing."""
    return rotation_problem(R, atol) is None


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix: `skew(a) @ b == np.cross(a, b)`. Works on (..., 3)."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def exp_so3(phi: np.ndarray) -> np.ndarray:
    """Exp: rotation vector (..., 3) in rad to rotation matrix (..., 3, 3)."""
    return Rotation.from_rotvec(np.asarray(phi, dtype=float)).as_matrix()


def log_so3(R: np.ndarray, assume_valid: bool = False) -> np.ndarray:
    """Log: rotation matrix (..., 3, 3) to rotation vector (..., 3) in rad, angle in [0, pi].

    `assume_valid`: `R` is a rotation to rounding (a product of rotations), so scipy's orthogonality
    check is skipped: the same numbers for such an `R`, a sixth of the time (130 -> 20 us for one)."""
    return Rotation.from_matrix(np.asarray(R, dtype=float), assume_valid=assume_valid).as_rotvec()


def angle_between(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Geodesic angle (rad) of `R_a^T R_b`, stack-wise; accurate near 0 (unlike the trace formula)."""
    R_rel = np.swapaxes(np.asarray(R_a, float), -1, -2) @ np.asarray(R_b, float)
    return np.linalg.norm(log_so3(R_rel), axis=-1)


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (Frobenius) to a 3x3 matrix or stack of them, via SVD."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones(U.shape[:-2] + (3,))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt


@lru_cache(maxsize=1)
def _symmetry_group() -> np.ndarray:
    group = np.rint(Rotation.create_group("O").as_matrix())
    # Put the identity first so that index 0 means "no relabelling".
    order = np.argsort(-np.einsum("gii->g", group), kind="stable")
    group = group[order]
    group.setflags(write=False)
    return group


def manhattan_symmetries() -> np.ndarray:
    """The 24 signed permutation matrices with det +1, shape (24, 3, 3); index 0 is identity.

    `R_cm` and `R_cm @ P` describe the same Manhattan scene for each P of this group.
    """
    return _symmetry_group()


def nearest_symmetric(R_cm: np.ndarray, R_ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The symmetric equivalent `R_cm @ P` closest to `R_ref` (geodesic distance).

    Returns `(R_cm @ P, P)`. Works on a single (3, 3) pair or stacks (..., 3, 3).
    """
    R_cm, R_ref = np.asarray(R_cm, float), np.asarray(R_ref, float)
    G = manhattan_symmetries()
    # trace(R_ref^T R_cm P) for every P; the largest trace is the smallest angle.
    A = np.swapaxes(R_ref, -1, -2) @ R_cm  # (..., 3, 3)
    traces = np.einsum("...ij,gji->...g", A, G)
    P = G[np.argmax(traces, axis=-1)]
    return R_cm @ P, P


def align_constant(R_est: np.ndarray, R_gt: np.ndarray) -> np.ndarray:
    """Constant rotation `A` minimising sum_i ||R_gt_i - A @ R_est_i||_F^2 (chordal least squares).

    Both inputs are stacks (N, 3, 3) of `R_wc`; `A` maps the estimate's world to the true world.
    """
    M = np.einsum("nij,nkj->ik", np.asarray(R_gt, float), np.asarray(R_est, float))
    return project_to_so3(M)


def are_deg(R_est: np.ndarray, R_gt: np.ndarray, align: bool = True) -> np.ndarray:
    """Absolute rotation error per frame in degrees, after one constant alignment (paper eq. 10, ARE).

    `R_est`, `R_gt`: (N, 3, 3) camera-to-world rotations `R_wc`. With `align=False` the frames are
    compared as they are.
    """
    R_est, R_gt = np.asarray(R_est, float), np.asarray(R_gt, float)
    if align:
        R_est = align_constant(R_est, R_gt) @ R_est
    return np.degrees(angle_between(R_gt, R_est))


def up_in_camera(R_wc: np.ndarray) -> np.ndarray:
    """World up expressed in the camera frame, `up_c = R_wc^T @ [0, 0, 1]`; (..., 3, 3) -> (..., 3)."""
    return np.swapaxes(np.asarray(R_wc, float), -1, -2) @ WORLD_UP


def vector_angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees (0..180) between the vectors `a` and `b` along their last axis (any length, not unit)."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    cos = np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def tilt_error_deg(up_est_c: np.ndarray, up_true_c: np.ndarray) -> np.ndarray:
    """Angle in degrees between estimated and true up vectors in the camera frame, (..., 3)."""
    return vector_angle_deg(up_est_c, up_true_c)


def nees(R_est: np.ndarray, R_true: np.ndarray, cov: np.ndarray, gauge_variance_rad2: float = 0.0) -> np.ndarray:
    """Normalised estimation error squared of a rotation estimate, stack-wise.

    `delta = Log(R_est^T R_true)` is the error in the right-perturbation convention
    `R_true = R_est @ Exp(delta)`, and `cov` (..., 3, 3) is its covariance in rad^2.
    A consistent estimator averages 3. Directions whose variance is at most `gauge_variance_rad2`
    are gauge freedoms (e.g. a filter's world yaw, fixed at initialisation with variance 0): they are
    left out rather than divided by zero, so give 0 only when the covariance is full rank.
    """
    delta = log_so3(np.swapaxes(np.asarray(R_est, float), -1, -2) @ np.asarray(R_true, float))
    cov = np.asarray(cov, float)
    if gauge_variance_rad2 <= 0:
        sol = np.linalg.solve(cov, delta[..., None])[..., 0]
        return np.sum(delta * sol, axis=-1)
    var, vec = np.linalg.eigh(cov)
    proj = np.einsum("...ji,...j->...i", vec, delta)
    keep = var > gauge_variance_rad2
    return np.sum(np.where(keep, proj**2 / np.where(keep, var, 1.0), 0.0), axis=-1)


def align_yaw(R_est: np.ndarray, R_gt: np.ndarray) -> np.ndarray:
    """Rotation about world z minimising sum_i ||R_gt_i - A @ R_est_i||_F^2: the alignment for
    estimates whose tilt is absolute (gravity known) and whose heading is a gauge."""
    M = np.einsum("nij,nkj->ik", np.asarray(R_gt, float), np.asarray(R_est, float))
    yaw = np.arctan2(M[1, 0] - M[0, 1], M[0, 0] + M[1, 1])
    return Rotation.from_rotvec([0.0, 0.0, yaw]).as_matrix()


def quat_xyzw(R: np.ndarray, assume_valid: bool = False) -> np.ndarray:
    """Rotation matrix (..., 3, 3) to unit quaternion (..., 4), order x y z w, w >= 0;
    `assume_valid`: the matrices are rotations (scipy skips its checks, ~7x faster)."""
    R = np.asarray(R, float)
    if R.size == 9:  # one matrix (3, 3) or (1, 3, 3), as sinks write per estimate: scipy costs ~100 us here
        return _quat_xyzw_one(R.reshape(3, 3)).reshape(R.shape[:-2] + (4,))
    return Rotation.from_matrix(R, assume_valid=assume_valid).as_quat(canonical=True)


def _quat_xyzw_one(R: np.ndarray) -> np.ndarray:
    """`quat_xyzw` of one rotation matrix in scalar arithmetic (Shepperd's method: the largest of
    the four squared components is computed first, so no division is ill-conditioned)."""
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    trace = a + e + i
    if trace >= a and trace >= e and trace >= i:
        w = 0.5 * math.sqrt(max(1.0 + trace, 0.0))
        s = 0.25 / w
        q = [(h - f) * s, (c - g) * s, (d - b) * s, w]
    elif a >= e and a >= i:
        x = 0.5 * math.sqrt(max(1.0 + a - e - i, 0.0))
        s = 0.25 / x
        q = [x, (b + d) * s, (c + g) * s, (h - f) * s]
    elif e >= i:
        y = 0.5 * math.sqrt(max(1.0 + e - a - i, 0.0))
        s = 0.25 / y
        q = [(b + d) * s, y, (f + h) * s, (c - g) * s]
    else:
        z = 0.5 * math.sqrt(max(1.0 + i - a - e, 0.0))
        s = 0.25 / z
        q = [(c + g) * s, (f + h) * s, z, (d - b) * s]
    out = np.array(q)
    out /= math.sqrt(float(out @ out))
    # scipy's canonical form: w > 0, or w == 0 and the first non-zero component positive.
    first = next((v for v in (out[3], out[0], out[1], out[2]) if v != 0.0), 1.0)
    return -out if first < 0 else out


def matrix_from_quat_xyzw(q: np.ndarray) -> np.ndarray:
    """Unit quaternion (..., 4) in order x y z w to rotation matrix (..., 3, 3)."""
    return Rotation.from_quat(np.asarray(q, float)).as_matrix()
