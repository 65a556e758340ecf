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


def log3_into(R, out):
    """Rotation vector (3,) of a rotation matrix `R` (3, 3), the logarithm map of SO(3), written into
    `out`: through its quaternion (Shepperd's method: the largest squared component first), angle
    `2 atan2(|v|, w)` with `w >= 0`, so that it stays exact near 0 and near pi."""
    a, b, c, d, e, f, g, h, i = R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2]
    trace = a + e + i
    if trace >= a and trace >= e and trace >= i:
        w = 0.5 * math.sqrt(max(1.0 + trace, 0.0))
        s = 0.25 / w
        x, y, z = (h - f) * s, (c - g) * s, (d - b) * s
    elif a >= e and a >= i:
        x = 0.5 * math.sqrt(max(1.0 + a - e - i, 0.0))
        s = 0.25 / x
        y, z, w = (b + d) * s, (c + g) * s, (h - f) * s
    elif e >= i:
        y = 0.5 * math.sqrt(max(1.0 + e - a - i, 0.0))
        s = 0.25 / y
        x, z, w = (b + d) * s, (f + h) * s, (c - g) * s
    else:
        z = 0.5 * math.sqrt(max(1.0 + i - a - e, 0.0))
        s = 0.25 / z
        x, y, w = (c + g) * s, (f + h) * s, (d - b) * s
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    norm_v = math.sqrt(x * x + y * y + z * z)
    scale = 2.0 * math.atan2(norm_v, w) / norm_v if norm_v > 1e-12 else 2.0 / w
    out[0], out[1], out[2] = scale * x, scale * y, scale * z
    return out
