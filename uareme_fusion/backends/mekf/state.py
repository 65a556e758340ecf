"""The error state of `Mekf`: block layout, injection into the nominal state, and the reset.

Error state (12,): `[dtheta_c, db_c, dtheta_m, domega_c]` with RIGHT perturbations,
`R_wc = R_wc_hat @ Exp(dtheta_c)`, `R_wm = R_wm_hat @ Exp(dtheta_m)`, `b_c = b_c_hat + db_c` (rad/s,
camera frame), `omega_c = omega_c_hat + domega_c` (rad/s, visual-only constant-rate model).
After an update the estimated error `dx` is injected into the nominal state and reset to zero; the
covariance then takes the reset Jacobian `G = I - skew(dtheta)/2` on each rotation block.
`reset_jacobian` and `orthonormal` are plain-array functions that the compiled kernels share.
"""

from __future__ import annotations

import numpy as np


TH, BG, MF, RATE = slice(0, 3), slice(3, 6), slice(6, 9), slice(9, 12)
"""Blocks of the 12-dimensional error state: camera attitude, gyro bias, Manhattan attitude, rate."""
N_STATE = 12
I3 = np.eye(3)
ZERO_STATE = np.zeros(N_STATE)
ZERO_STATE.setflags(write=False)
ROTATION_BLOCKS = (TH.start, MF.start)
"""Where the two rotation blocks (camera attitude, Manhattan frame) of the error state start (Python
ints: compile-time constants in the kernels); the reset acts on them alone."""
ORTHONORMALISE_EVERY = 16
"""Products (integration chunks and update corrections) between re-orthonormalisations of R_wc and
R_wm: rounding drift grows by ~1e-16 per product, far below anything that matters in 16."""


def orthonormal(R: np.ndarray) -> np.ndarray:
    """One Newton step of the polar decomposition, `R (3 I - R^T R) / 2`, of a (3, 3) near-rotation:
    removes the rounding drift of a product of rotations (exact rotations are fixed points)."""
    return 0.5 * R @ (3.0 * I3 - R.T @ R)


def reset_jacobian(dx, with_manhattan):
    """(12, 12) Jacobian of the error reset after injecting `dx` (12,): `I - skew(dtheta)/2` on the
    camera attitude block and, when `with_manhattan`, on the Manhattan block; identity elsewhere."""
    G = np.eye(N_STATE)
    for block in range(2 if with_manhattan else 1):  # the camera's, then the Manhattan frame's
        offset = ROTATION_BLOCKS[block]
        a, b, c = 0.5 * dx[offset], 0.5 * dx[offset + 1], 0.5 * dx[offset + 2]
        G[offset, offset + 1] += c
        G[offset, offset + 2] -= b
        G[offset + 1, offset] -= c
        G[offset + 1, offset + 2] += a
        G[offset + 2, offset] += b
        G[offset + 2, offset + 1] -= a
    return G
