"""The visual-only EKF's prediction by the image rotation between frames (a visual gyro), a kernel of
the state buffer (numba-compiled by `kernels`, plain Python without numba).

`R_cp` (`VisualRotation.R_cp`, `solver/frame_motion.py`) maps the previous frame's camera coordinates to
this frame's; its error is the left perturbation `R_cp_true = Exp(eps) R_cp`, `eps` of std `sigma` per axis.
Then `R_wc = R_wc_p R_cp^T` and, with right perturbations, `dtheta_c = R_cp dtheta_p - eps`: `F[TH, TH] =
R_cp`, `Q[TH, TH] = sigma^2 I` (isotropic, so the same in either frame). The rate of the constant-rate
model is measured afresh by the step, `omega_c = Log(R_cp^T) / dt` (`domega = -eps / dt`), for the frames
that come without an image rotation and for the accelerometer's turning (`gravity_only.py`): its
covariance is `sigma^2 / dt^2 + q_rate dt / 3` (the step's error and how far the rate at the frame may be
from its mean over the step), its cross-covariance with the attitude `sigma^2 / dt`, and its earlier
correlations are dropped (the measured step replaces what the model knew of the rate).
"""

from __future__ import annotations

import numpy as np

from .kernel_update import matmul_into, state_views
from .matrix3 import log3_into, matmul3_into
from .state import orthonormal


def image_rotation_predict(x, t_s, R_cp, var_rad2, q_rate):
    """The state buffer `x` predicted to `t_s` (s) by the image rotation `R_cp` (3, 3) since the state's
    time, of variance `var_rad2` (rad^2 per axis), with the rate random walk `q_rate` ((rad/s^2)^2/Hz) for
    the rate's covariance (module docstring); `t_s` is later than the state's time."""
    s = x[0]
    R_wc, _, _, P, _, _, _, _, _, omega_c = state_views(x)
    dt = t_s - s.t_state_s
    R_pc = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            R_pc[i, j] = R_cp[j, i]
    R_wc[:, :] = orthonormal(matmul3_into(R_wc, R_pc, np.empty((3, 3))))
    F = np.eye(12)
    for i in range(3):
        for j in range(3):
            F[i, j] = R_cp[i, j]
    P_new = matmul_into(matmul_into(F, P, np.empty((12, 12))), F.T, np.empty((12, 12)))
    for i in range(3):
        P_new[i, i] += var_rad2
    w = np.empty(3)
    log3_into(R_pc, w)
    for i in range(3):
        omega_c[i] = w[i] / dt
    for i in range(9, 12):
        for j in range(12):
            P_new[i, j] = 0.0
            P_new[j, i] = 0.0
    for i in range(3):
        P_new[9 + i, 9 + i] = var_rad2 / (dt * dt) + q_rate * dt / 3.0
        P_new[i, 9 + i] = var_rad2 / dt
        P_new[9 + i, i] = var_rad2 / dt
    P[:, :] = P_new
    s.t_state_s = t_s
