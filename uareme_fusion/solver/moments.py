"""Fourth-order weighted moments of a normal map: everything the Manhattan cost needs.

Paper eq. 1 summed over the three axes of an orthonormal frame R = [r_1 r_2 r_3]:
    E(R) = sum_i w_i sum_k sin^2 cos^2 = sum_i w_i (1 - sum_k (n_i . r_k)^4),
so E depends on the normals only through the symmetric tensor T = sum_i w_i n_i^(x4), whose 15
distinct entries are the moments S_uvw = sum_i w_i x^u y^v z^w (u + v + w = 4).

We hold them as the 6x6 Gram matrix G[a, b] = sum_i w_i q_a(n_i) q_b(n_i) of the quadratic
monomials q(n) = (x^2, y^2, z^2, xy, xz, yz) / |n|^2 (dividing by |n|^2 makes every normal unit
length at no extra pass). Only 15 entries are distinct.

Two implementations of the same sums: `fused_moments`, one compiled pass (numba) that reads each
normal and kappa from memory once and accumulates in float64 (blocks of 1024 pixels; a block with
holes is summed again from cache with selects, see `_fused_sums`), and `normal_moments_reference`,
the vectorised numpy one (about ten passes over the pixels), kept as the reference that tests and
the benchmark compare against and used when numba is missing.
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


def _gram_index() -> np.ndarray:
    """(6, 6) index of each Gram entry in the 15 distinct moments (`_DISTINCT_PAIRS` order)."""
    index = np.empty((6, 6), dtype=np.intp)
    for j, (a, b) in enumerate(_DISTINCT_PAIRS):
        index[a, b] = index[b, a] = j
    for (a, b), (c, d) in _REPEATED_PAIRS:
        index[a, b] = index[b, a] = index[c, d]
    index.setflags(write=False)
    return index


_GRAM_INDEX = _gram_index()


def _from_distinct(distinct, n_valid: int, n_invalid: int) -> NormalMoments:
    """`NormalMoments` from the 15 distinct moments in `_DISTINCT_PAIRS` order."""
    G = np.asarray(distinct, dtype=np.float64)[_GRAM_INDEX]
    # sum_i w_i = sum_i w_i (|n_i|^2)^2 = sum of the squared-monomial block (a, b < 3) of G.
    return NormalMoments(G=G, total_weight=float(G[:3, :3].sum()), n_valid=n_valid, n_invalid=n_invalid)


BLOCK_PIXELS = 1024
"""Pixels per block of the compiled pass (12-24 KB of normals: a block summed again stays in cache)."""

# How a block is summed, cheapest first (`_fused_sums`).
_CLEAN, _WEIGHT_SELECT, _FULL_SELECT = 0, 1, 2


def _add_moments(s, w, x, y, z):
    """The 15-tuple `s` of distinct moments (`_DISTINCT_PAIRS` order) plus one vector's terms
    w q_a q_b, from the squared monomials (a < 3) weighted once: 9 products and 15 fused adds."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    a, b, c = w * xx, w * yy, w * zz
    return (s[0] + a * xx, s[1] + b * yy, s[2] + c * zz, s[3] + a * yy, s[4] + a * zz, s[5] + b * zz,
            s[6] + a * xy, s[7] + a * xz, s[8] + a * yz, s[9] + b * xy, s[10] + b * xz, s[11] + b * yz,
            s[12] + c * xy, s[13] + c * xz, s[14] + c * yz)


def _vector(n, k, unit_weights, i):
    """Vector i of a block in float64 (read once), its weight kappa / |n|^4 and |n|^2. Computed in
    float64, they cannot overflow for float32 input."""
    x, y, z = np.float64(n[3 * i]), np.float64(n[3 * i + 1]), np.float64(n[3 * i + 2])
    sq = x * x + y * y + z * z
    return x, y, z, (1.0 if unit_weights else np.float64(k[i])) / (sq * sq), sq


def _is_valid(sq, w, largest, min_sq_norm):
    """Validity as in `_reference_moments`, where |n|^2 and kappa/|n|^4 are computed in the input's
    dtype and must be finite: here they must not exceed `largest` (that dtype's largest finite
    value), which differs only within one rounding of the overflow threshold. NaN fails every
    comparison; -0.0 (a negative kappa that underflowed) counts as negative."""
    return (sq > min_sq_norm) & (sq <= largest) & (w <= largest) & (math.copysign(1.0, w) > 0.0)


def _add_to(out, s, n_positive, n_invalid):
    """Add a block's 15 sums and its two counts to the kernel's output (layout of `_fused_sums`)."""
    for j in range(15):
        out[j] += s[j]
    out[15] += n_positive
    out[16] += n_invalid


def _clean_block_sums(n, k, unit_weights, largest, min_sq_norm, out):
    """Block `n` (3M,: x y z of each vector in turn) and `k` (M,) when every vector is valid with a
    weight > 0: adds its sums to `out` and returns `_CLEAN`. Otherwise adds nothing and returns
    `_WEIGHT_SELECT`. No selects: one test per vector (the path of a map without holes)."""
    s = _ZERO_MOMENTS
    clean = 0.0
    m = n.shape[0] // 3
    for i in range(m):
        x, y, z, w, sq = _vector(n, k, unit_weights, i)
        # `_is_valid` and w > 0 (which also rules out -0.0), in four comparisons.
        clean += 1.0 if (sq > min_sq_norm) & (sq <= largest) & (w > 0.0) & (w <= largest) else 0.0
        s = _add_moments(s, w, x, y, z)
    if clean != m:
        return _WEIGHT_SELECT
    _add_to(out, s, m, 0.0)
    return _CLEAN


def _selected_block_sums(n, k, unit_weights, largest, min_sq_norm, out, zero_coordinates):
    """Any block, with selects: an invalid vector's weight is set to 0, which zeroes its terms when
    its coordinates are finite; with `zero_coordinates` (NaN or Inf normals) they are set to 0 too.
    Adds the sums and counts to `out` and returns the cheapest path this block would have allowed,
    for the next one. Without `zero_coordinates`, a block whose sums are not finite (0 * Inf) adds
    nothing and returns `_FULL_SELECT`: it must be summed again."""
    s = _ZERO_MOMENTS
    n_positive = 0.0
    n_invalid = 0.0
    sq_total = 0.0  # finite when every vector is (an add, cheaper than a count)
    m = n.shape[0] // 3
    for i in range(m):
        x, y, z, w, sq = _vector(n, k, unit_weights, i)
        valid = _is_valid(sq, w, largest, min_sq_norm)
        n_invalid += 0.0 if valid else 1.0
        n_positive += 1.0 if valid and w > 0.0 else 0.0
        sq_total += sq
        if zero_coordinates:  # selects, not branches: LLVM vectorises the loop
            x, y, z = (x, y, z) if valid else (0.0, 0.0, 0.0)
        s = _add_moments(s, w if valid else 0.0, x, y, z)
    if not zero_coordinates:
        total = 0.0
        for j in range(15):
            total += s[j]
        if not math.isfinite(total):
            return _FULL_SELECT
    _add_to(out, s, n_positive, n_invalid)
    if n_positive == m:
        return _CLEAN
    return _WEIGHT_SELECT if math.isfinite(sq_total) else _FULL_SELECT


def _fused_sums(n, k, unit_weights, largest, min_sq_norm, out):
    """One pass over `n` (3N,: x y z of each vector in turn) and `k` (N,) in blocks of
    `BLOCK_PIXELS`: out[:15] the distinct moments in `_DISTINCT_PAIRS` order (float64 sums), out[15]
    valid vectors with weight > 0, out[16] invalid vectors; `k` is ignored with `unit_weights`.

    Each block takes the cheapest path that the block before it allowed (holes come in patches):
    no selects (`_clean_block_sums`), a select on the weight (`_selected_block_sums`), or
    selects on weight and coordinates (the same with `zero_coordinates`, NaN or Inf normals); a path that
    finds its block needs a stricter one adds nothing, and the block is summed again from cache."""
    out[:] = 0.0
    m = n.shape[0] // 3
    path = _CLEAN
    for start in range(0, m, BLOCK_PIXELS):
        stop = min(start + BLOCK_PIXELS, m)
        block = n[3 * start:3 * stop]
        weights = k if unit_weights else k[start:stop]
        if path == _CLEAN:
            path = _clean_block_sums(block, weights, unit_weights, largest, min_sq_norm, out)
            if path == _CLEAN:
                continue
        if path == _WEIGHT_SELECT:
            path = _selected_block_sums(block, weights, unit_weights, largest, min_sq_norm, out, False)
            if path != _FULL_SELECT:
                continue
        path = _selected_block_sums(block, weights, unit_weights, largest, min_sq_norm, out, True)


_ZERO_MOMENTS = (0.0,) * 15
_FASTMATH = {"reassoc", "contract"}
"""Sums may be regrouped (vectorised partial sums) and a * b + s fused: float64 rounding either way.
No flag that assumes finite values: NaN and Inf must still fail the validity tests."""
# Machine code cached on disk (`jit.compiled`): compiling takes about 5 s per dtype.
if jit.available():  # the kernel calls these as compiled functions
    _add_moments = jit.compiled(_add_moments, cache=True, inline="always", fastmath=_FASTMATH)
    _vector = jit.compiled(_vector, cache=True, inline="always", fastmath=_FASTMATH, error_model="numpy")
    _is_valid = jit.compiled(_is_valid, cache=True, inline="always")
    _add_to = jit.compiled(_add_to, cache=True, inline="always")
    _clean_block_sums = jit.compiled(_clean_block_sums, cache=True, fastmath=_FASTMATH, error_model="numpy")
    _selected_block_sums = jit.compiled(_selected_block_sums, cache=True, fastmath=_FASTMATH, error_model="numpy")
_fused_kernel = jit.Kernel(_fused_sums, cache=True, fastmath=_FASTMATH, error_model="numpy")


_LARGEST = {np.dtype(t): float(np.finfo(t).max) for t in (np.float32, np.float64)}
_NO_WEIGHTS = {np.dtype(t): np.empty(0, t) for t in (np.float32, np.float64)}


def fused_moments(vectors: np.ndarray, weights: np.ndarray | None) -> NormalMoments | None:
    """`NormalMoments` of checked arrays (`vectors` (N, 3) float32/float64, `weights` (N,) of the
    same dtype or None for unit weights) in one compiled pass; None when numba is unavailable.
    Any unit-vector field whose cost is a fourth-order form (normals here) can use it."""
    if not _fused_kernel:
        return None
    out = np.empty(17)
    n = np.ascontiguousarray(vectors).reshape(-1)
    unit = weights is None
    k = _NO_WEIGHTS[n.dtype] if unit else np.ascontiguousarray(weights, dtype=n.dtype)
    if _fused_kernel(n, k, unit, _LARGEST[n.dtype], _MIN_SQUARED_NORM, out) is jit.FALLBACK:
        return None
    return _from_distinct(out[:15], int(out[15]), int(out[16]))
