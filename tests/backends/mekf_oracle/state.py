"""The oracle's injection of an error estimate into the nominal state (scipy rotations); the layout,
the reset Jacobian and the re-orthonormalisation are the package's (`mekf.state`)."""

from __future__ import annotations

import numpy as np

from uareme_fusion.backends.mekf.state import BG, MF, N_STATE, RATE, TH
from uareme_fusion.rotations import exp_so3

_TH_AND_MF = np.stack([np.arange(N_STATE)[TH], np.arange(N_STATE)[MF]])
"""Indices that gather the two rotation blocks of the error state as a (2, 3) stack."""


def inject(R_wc, R_wm, b_c, omega_c, dx: np.ndarray, with_manhattan: bool, with_rate: bool):
    """The nominal state `(R_wc (3, 3), R_wm (3, 3), b_c (3,) rad/s, omega_c (3,) rad/s)` corrected by
    the error estimate `dx` (12,) (right perturbations): the Manhattan block only `with_manhattan`
    (once that frame is known), the rate only `with_rate` (constant-rate model)."""
    if with_manhattan:
        dR_c, dR_m = exp_so3(dx[_TH_AND_MF])
        R_wm = R_wm @ dR_m
    else:
        dR_c = exp_so3(dx[TH])
    omega_c = omega_c + dx[RATE] if with_rate else omega_c
    return R_wc @ dR_c, R_wm, b_c + dx[BG], omega_c
