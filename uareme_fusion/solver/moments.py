"""Fourth-order weighted moments of a normal map: everything the Manhattan cost needs.

Paper eq. 1 summed over the three axes of an orthonormal frame R = [r_1 r_2 r_3]:
    E(R) = sum_i w_i sum_k sin^2 cos^2 = sum_i w_i (1 - sum_k (n_i . r_k)^4),
so E depends on the normals only through the symmetric tensor T = sum_i w_i n_i^(x4), whose 15
distinct entries are the moments S_uvw = sum_i w_i x^u y^v z^w (u + v + w = 4).

We get them in one pass as the 6x6 Gram matrix G = Q Q^T of the weighted quadratic monomials
q(n) = sqrt(w) (x^2, y^2, z^2, xy, xz, yz) / |n|^2: entry (a, b) of G is the moment of the product of
monomials a and b (dividing by |n|^2 makes every normal unit length at no extra pass).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError

# Index of the monomial n_a n_b in q(n) = (xx, yy, zz, xy, xz, yz).
PAIR_INDEX = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])

_MIN_SQUARED_NORM = 1e-12


@dataclass(frozen=True)
class NormalMoments:
    """The 15 fourth-order moments of a weighted normal map (as the 6x6 Gram matrix `G`)."""

    G: np.ndarray
    """(6, 6) float64: G[a, b] = sum_i w_i q_a(n_i) q_b(n_i), with q = (xx, yy, zz, xy, xz, yz)."""
    total_weight: float
    """sum_i w_i over the valid pixels."""
    n_valid: int
    """Pixels with a finite, non-zero normal and a finite kappa > 0."""
    n_invalid: int
    """Pixels ignored for NaN/Inf or zero-length normals, or NaN/Inf/negative kappa."""

    def tensor(self) -> np.ndarray:
        """T[a, b, c, d] = sum_i w_i n_a n_b n_c n_d, shape (3, 3, 3, 3)."""
        return self.G[PAIR_INDEX[:, :, None, None], PAIR_INDEX[None, None, :, :]]


def check_normal_map(normals, kappa=None) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate shapes and dtypes; return normals as (N, 3) float32/float64 and kappa as (N,) or None.

    Raises `InputError` (a `ValueError`) naming the problem and the shape or dtype received.
    """
    if not isinstance(normals, np.ndarray):
        normals = np.asarray(normals)
    if normals.ndim not in (2, 3) or normals.shape[-1] != 3:
        raise InputError(f"Expected normals of shape (H, W, 3) or (N, 3), got {normals.shape}")
    if not np.issubdtype(normals.dtype, np.floating):
        raise InputError(
            f"Expected normals of a floating dtype (unit vectors), got {normals.dtype} with shape "
            f"{normals.shape}; decode normal images with uareme_fusion.io.load_normal_map"
        )
    if normals.size == 0:
        raise InputError(f"Expected a non-empty normal map, got shape {normals.shape}")
    if normals.dtype not in (np.float32, np.float64):
        normals = normals.astype(np.float32)
    flat = normals.reshape(-1, 3)
    if kappa is None:
        return flat, None
    if not isinstance(kappa, np.ndarray):
        kappa = np.asarray(kappa)
    if kappa.shape != normals.shape[:-1]:
        raise InputError(
            f"Expected kappa of shape {normals.shape[:-1]} to match normals {normals.shape}, "
            f"got {kappa.shape}"
        )
    if not (np.issubdtype(kappa.dtype, np.floating) or np.issubdtype(kappa.dtype, np.integer)):
        raise InputError(f"Expected kappa of a real numeric dtype, got {kappa.dtype}")
    return flat, kappa.reshape(-1).astype(flat.dtype, copy=False)


def normal_moments(normals, kappa=None) -> NormalMoments:
    """The weighted fourth-order moments of a normal map, in one vectorised pass.

    `normals`: (H, W, 3) or (N, 3) float, any length (normalised here); `kappa`: matching (H, W) or
    (N,) confidence >= 0, or None for unit weights. Invalid pixels get weight 0 and are counted.
    """
    n, k = check_normal_map(normals, kappa)
    count = n.shape[0]
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    Q = np.empty((6, count), dtype=n.dtype)
    np.multiply(x, x, out=Q[0])
    np.multiply(y, y, out=Q[1])
    np.multiply(z, z, out=Q[2])
    np.multiply(x, y, out=Q[3])
    np.multiply(x, z, out=Q[4])
    np.multiply(y, z, out=Q[5])
    sq_norm = Q[0] + Q[1] + Q[2]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # scale = sqrt(w) / |n|^2 makes each column the weighted monomials of the unit normal.
        scale = np.divide(1.0, sq_norm) if k is None else np.sqrt(k) / sq_norm
        valid = np.isfinite(scale) & (sq_norm > _MIN_SQUARED_NORM)
    n_invalid = count - int(np.count_nonzero(valid))
    if n_invalid:
        scale[~valid] = 0.0
        np.nan_to_num(Q, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    Q *= scale
    G = (Q @ Q.T).astype(np.float64)
    # sum_i w_i = sum_i w_i (|n_i|^2)^2 = sum over the squared-monomial block (a, b < 3) of G.
    total_weight = float(G[:3, :3].sum())
    return NormalMoments(
        G=G, total_weight=total_weight, n_valid=int(np.count_nonzero(scale)), n_invalid=n_invalid
    )
