"""Fourth-order weighted moments of a normal map: everything the Manhattan cost needs.

Paper eq. 1 summed over the three axes of an orthonormal frame R = [r_1 r_2 r_3]:
    E(R) = sum_i w_i sum_k sin^2 cos^2 = sum_i w_i (1 - sum_k (n_i . r_k)^4),
so E depends on the normals only through the symmetric tensor T = sum_i w_i n_i^(x4), whose 15
distinct entries are the moments S_uvw = sum_i w_i x^u y^v z^w (u + v + w = 4).

We hold them as the 6x6 Gram matrix G[a, b] = sum_i w_i q_a(n_i) q_b(n_i) of the quadratic
monomials q(n) = (x^2, y^2, z^2, xy, xz, yz) / |n|^2 (dividing by |n|^2 makes every normal unit
length at no extra pass). Only 15 entries are distinct.

Two implementations of the same sums: `fused_moments`, one compiled pass (numba) that reads each
normal and kappa once and accumulates in float64, and `normal_moments_reference`, the vectorised
numpy one (about ten passes over the pixels), kept as the reference that tests and the benchmark
compare against and used when numba is missing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import jit
from ..errors import InputError

# Index of the monomial n_a n_b in q(n) = (xx, yy, zz, xy, xz, yz).
PAIR_INDEX = np.array([[0, 3, 4], [3, 1, 5], [4, 5, 2]])

_MIN_SQUARED_NORM = 1e-12

# The 15 distinct moments as (a, b) pairs of monomials of q = (xx, yy, zz, xy, xz, yz), a < 3 always,
# and the 6 remaining Gram entries that repeat one of them (e.g. xy*xy = xx*yy = x^2 y^2).
_DISTINCT_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2), (0, 3), (0, 4), (0, 5),
                   (1, 3), (1, 4), (1, 5), (2, 3), (2, 4), (2, 5))
_REPEATED_PAIRS = (((3, 3), (0, 1)), ((4, 4), (0, 2)), ((5, 5), (1, 2)),
                   ((3, 4), (0, 5)), ((3, 5), (1, 4)), ((4, 5), (2, 3)))


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
    """The weighted fourth-order moments of a normal map, in one compiled pass (`fused_moments`;
    the numpy reference without numba).

    `normals`: (H, W, 3) or (N, 3) float, any length (normalised here); `kappa`: matching (H, W) or
    (N,) confidence >= 0, or None for unit weights. Invalid pixels get weight 0 and are counted.
    """
    n, k = check_normal_map(normals, kappa)
    moments = fused_moments(n, k)
    return moments if moments is not None else _reference_moments(n, k)


def normal_moments_reference(normals, kappa=None) -> NormalMoments:
    """`normal_moments` by vectorised numpy passes (the reference the compiled pass is tested against)."""
    return _reference_moments(*check_normal_map(normals, kappa))


def _reference_moments(n: np.ndarray, k: np.ndarray | None) -> NormalMoments:
    x, y, z = np.ascontiguousarray(n.T)  # contiguous coordinates: 4x faster products below
    Q = np.empty((6, x.shape[0]), dtype=n.dtype)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # such pixels become invalid
        for row, (a, b) in enumerate(((x, x), (y, y), (z, z), (x, y), (x, z), (y, z))):
            np.multiply(a, b, out=Q[row])
        sq_norm = Q[0] + Q[1]
        sq_norm += Q[2]
        # w_i / |n_i|^4 turns the monomials of n_i into those of the unit normal.
        weight = np.divide(1.0 if k is None else k, sq_norm)
        weight /= sq_norm  # two divisions: |n|^4 itself would overflow float32 for |n| > 1e9
        valid = np.isfinite(weight)
        valid &= sq_norm > _MIN_SQUARED_NORM
        valid &= np.isfinite(sq_norm)
        valid &= ~np.signbit(weight)  # also a negative kappa whose weight underflows to -0.0
    n_invalid = valid.size - int(np.count_nonzero(valid))
    if n_invalid:
        weight[~valid] = 0.0
        np.nan_to_num(Q, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    # Every distinct moment is (squared monomial a < 3) x (monomial b): weight only the first side.
    Qw = Q[:3] * weight
    distinct = [np.dot(Qw[a], Q[b]) for a, b in _DISTINCT_PAIRS]
    return _from_distinct(distinct, int(np.count_nonzero(weight > 0)), n_invalid)


def _from_distinct(distinct, n_valid: int, n_invalid: int) -> NormalMoments:
    """`NormalMoments` from the 15 distinct moments in `_DISTINCT_PAIRS` order."""
    G = np.empty((6, 6))
    for value, (a, b) in zip(distinct, _DISTINCT_PAIRS):
        G[a, b] = G[b, a] = value
    for (a, b), (c, d) in _REPEATED_PAIRS:
        G[a, b] = G[b, a] = G[c, d]
    # sum_i w_i = sum_i w_i (|n_i|^2)^2 = sum of the squared-monomial block (a, b < 3) of G.
    return NormalMoments(G=G, total_weight=float(G[:3, :3].sum()), n_valid=n_valid, n_invalid=n_invalid)


def _fused_sums(n, k, unit_weights, largest, min_sq_norm, out):
    """One pass over `n` (3N,: x y z of each vector in turn) and `k` (N,): out[:15] the distinct
    moments in `_DISTINCT_PAIRS` order (float64 sums), out[15] valid pixels with weight > 0, out[16]
    invalid pixels; `k` is ignored with `unit_weights`. All in float64; validity as in
    `_reference_moments`, where |n|^2 and kappa/|n|^4 are computed in the input's dtype and must be
    finite: here they must not exceed `largest` (that dtype's largest finite value), which differs
    only within one rounding of the overflow threshold. Flat indexing and selects instead of
    branches let LLVM vectorise the loop."""
    s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = s9 = s10 = s11 = s12 = s13 = s14 = 0.0
    n_pos = 0.0
    n_bad = 0.0
    for i in range(n.shape[0] // 3):
        x, y, z = np.float64(n[3 * i]), np.float64(n[3 * i + 1]), np.float64(n[3 * i + 2])
        kk = 1.0 if unit_weights else np.float64(k[i])
        xx, yy, zz = x * x, y * y, z * z
        sq = xx + yy + zz
        w = kk / (sq * sq)  # float64: no overflow for float32 input
        # NaN fails every comparison; -0.0 (a negative kappa that underflowed) counts as negative.
        valid = (sq > min_sq_norm) & (sq <= largest) & (w <= largest) & (math.copysign(1.0, w) > 0.0)
        n_bad += 0.0 if valid else 1.0
        n_pos += 1.0 if valid and w > 0.0 else 0.0
        w = w if valid else 0.0
        x = x if valid else 0.0
        y = y if valid else 0.0
        z = z if valid else 0.0
        xx, yy, zz = x * x, y * y, z * z
        xy, xz, yz = x * y, x * z, y * z
        wd = w
        a, b, c = wd * xx, wd * yy, wd * zz
        s0 += a * xx
        s1 += b * yy
        s2 += c * zz
        s3 += a * yy
        s4 += a * zz
        s5 += b * zz
        s6 += a * xy
        s7 += a * xz
        s8 += a * yz
        s9 += b * xy
        s10 += b * xz
        s11 += b * yz
        s12 += c * xy
        s13 += c * xz
        s14 += c * yz
    out[0], out[1], out[2], out[3], out[4] = s0, s1, s2, s3, s4
    out[5], out[6], out[7], out[8], out[9] = s5, s6, s7, s8, s9
    out[10], out[11], out[12], out[13], out[14] = s10, s11, s12, s13, s14
    out[15] = n_pos
    out[16] = n_bad


# cache=True: compiling it (float32 and float64) takes about a second, paid once per install, not per process.
_fused_kernel = jit.compiled(_fused_sums, cache=True, fastmath={"reassoc", "contract"}, error_model="numpy")


def fused_moments(vectors: np.ndarray, weights: np.ndarray | None) -> NormalMoments | None:
    """`NormalMoments` of checked arrays (`vectors` (N, 3) float32/float64, `weights` (N,) of the
    same dtype or None for unit weights) in one compiled pass; None when numba is unavailable.
    Any unit-vector field whose cost is a fourth-order form (normals here) can use it."""
    global _fused_kernel
    if _fused_kernel is None:
        return None
    out = np.empty(17)
    n = np.ascontiguousarray(vectors).reshape(-1)
    unit = weights is None
    k = np.ones(1, n.dtype)[:0] if unit else np.ascontiguousarray(weights, dtype=n.dtype)
    try:
        _fused_kernel(n, k, unit, float(np.finfo(n.dtype).max), _MIN_SQUARED_NORM, out)
    except Exception as exc:  # noqa: BLE001 -- a compiler failure falls back to the reference
        jit.disable(exc)
        _fused_kernel = None
        return None
    return _from_distinct(out[:15], int(out[15]), int(out[16]))
