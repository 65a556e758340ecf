"""The oracle's measurement models: the reference visual model (scipy) and the stacking of rows; the
plain-array models (vertical, gravity, zero rate) are the package's (`mekf.measurements`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.backends.mekf.measurements import (correlated_noise_scale, gravity_model, vertical_model,
                                                      zero_rate_model)
from uareme_fusion.backends.mekf.state import I3, MF, N_STATE, TH
from uareme_fusion.rotations import nearest_symmetric

__all__ = ["correlated_noise_scale", "gravity_model", "stack", "vertical_model", "visual_model", "zero_rate_model"]


def visual_model(R_wc: np.ndarray, R_wm: np.ndarray, R_cm: np.ndarray, cov_rad2: np.ndarray, relabel: bool = True):
    """The solver's rotation `R_cm` (3, 3) with covariance `cov_rad2` (3, 3, rad^2, right
    perturbation) as a measurement of `R_cm = R_wc^T R_wm`, its Manhattan labelling resolved
    against the prediction (`relabel`; False: as labelled, e.g. by `backends.labelling_track`):
    `(residual (3,) rad, R (3, 3) rad^2, H (3, 12))`."""
    R_cm_pred = R_wc.T @ R_wm
    if relabel:
        R_cm, P_sym = nearest_symmetric(R_cm, R_cm_pred)  # as VisualRotation.symmetric_to
    else:
        P_sym = I3
    # Log of a product of rotations: scipy may skip its orthogonalisation (assume_valid).
    r = Rotation.from_matrix(R_cm_pred.T @ R_cm, assume_valid=True).as_rotvec()
    H = np.zeros((3, N_STATE))
    H[:, TH] = -R_cm_pred.T
    H[:, MF] = I3
    cov_rad2 = np.asarray(cov_rad2, float)
    R_vis = P_sym.T @ (0.5 * (cov_rad2 + cov_rad2.T)) @ P_sym
    return r, R_vis, H


def stack(blocks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One measurement from several `(residual, R, H)` blocks (None entries skipped): residuals and
    H stacked, R block-diagonal."""
    blocks = [b for b in blocks if b is not None]
    if len(blocks) == 1:
        return blocks[0]
    R_all = np.zeros((3 * len(blocks), 3 * len(blocks)))
    for i, b in enumerate(blocks):
        R_all[3 * i:3 * i + 3, 3 * i:3 * i + 3] = b[1]
    return np.concatenate([b[0] for b in blocks]), R_all, np.vstack([b[2] for b in blocks])
