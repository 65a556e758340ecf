"""3x3 matrix helpers for the compiled kernels (`kernels.py` compiles them with numba): inverse,
SO(3) exponential (Rodrigues) and product, written without allocations where the caller gives `out`."""

from __future__ import annotations

import math

import numpy as np


def inv3(A):
    """Inverse of a 3x3 matrix by cofactors (NaN/Inf for a singular one, as numpy's would fail)."""
    out = np.empty((3, 3))
    out[0, 0] = A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1]
    out[0, 1] = A[0, 2] * A[2, 1] - A[0, 1] * A[2, 2]
    out[0, 2] = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    out[1, 0] = A[1, 2] * A[2, 0] - A[1, 0] * A[2, 2]
    out[1, 1] = A[0, 0] * A[2, 2] - A[0, 2] * A[2, 0]
    out[1, 2] = A[0, 2] * A[1, 0] - A[0, 0] * A[1, 2]
    out[2, 0] = A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]
    out[2, 1] = A[0, 1] * A[2, 0] - A[0, 0] * A[2, 1]
    out[2, 2] = A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    det = A[0, 0] * out[0, 0] + A[0, 1] * out[1, 0] + A[0, 2] * out[2, 0]
    return out / det


def exp3_into(p0, p1, p2, out):
    """Rodrigues' formula for the rotation vector (p0, p1, p2), with its Taylor series near 0 (the
    exponential map of SO(3)), written into `out` (3, 3): `I + a K + b K^2`, K = skew(p)."""
    theta2 = p0 * p0 + p1 * p1 + p2 * p2
    if theta2 < 1e-8:
        a = 1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0
        b = 0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0
    else:
        theta = math.sqrt(theta2)
        a = math.sin(theta) / theta
        b = (1.0 - math.cos(theta)) / theta2
    out[0, 0] = 1.0 + b * (-p2 * p2 - p1 * p1)
    out[0, 1] = -a * p2 + b * (p1 * p0)
    out[0, 2] = a * p1 + b * (p2 * p0)
    out[1, 0] = a * p2 + b * (p0 * p1)
    out[1, 1] = 1.0 + b * (-p2 * p2 - p0 * p0)
    out[1, 2] = -a * p0 + b * (p2 * p1)
    out[2, 0] = -a * p1 + b * (p0 * p2)
    out[2, 1] = a * p0 + b * (p1 * p2)
    out[2, 2] = 1.0 + b * (-p1 * p1 - p0 * p0)
    return out


def matmul3_into(A, B, out):
    """`out = A @ B` for (3, 3) arrays (`out` distinct from both), without allocating."""
    for i in range(3):
        a0, a1, a2 = A[i, 0], A[i, 1], A[i, 2]
        for j in range(3):
            out[i, j] = a0 * B[0, j] + a1 * B[1, j] + a2 * B[2, j]
    return out
