"""The oracle's measurement models: the reference visual model (scipy) and the stacking of rows; the
plain-array models (gravity, zero rate, vertical) are the production ones.

Measurement models of `Mekf`: pure functions returning residual, noise and H.

Each model compares a measurement with its prediction from the nominal state and returns
`(residual (3,), noise, H (3, 12))` with `residual ~ H dx + noise` for the error state `dx` (right
perturbations, `state.py`). The gravity and zero-rate models take plain arrays and scalars and
return an isotropic variance, so the compiled kernels (`kernels.py`) call the same functions.
- visual: the solver's `R_cm` measures `R_wc^T R_wm` (residual `Log(R_cm_pred^T R_cm)`);
- vertical: "the Manhattan z axis is world up" (`e_z - R_wm^T up`);
- gravity: the accelerometer direction measures up in the camera frame (`z - R_wc^T up`);
- zero rate: at rest the mean gyro reading measures the bias (`g_mean - b_c`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from uareme_fusion.rotations import nearest_symmetric
from uareme_fusion.backends.mekf.measurements import (correlated_noise_scale, gravity_model, vertical_measurement,
                                                      zero_rate_model)
from uareme_fusion.backends.mekf.state import I3, MF, N_STATE, TH

__all__ = ["correlated_noise_scale", "gravity_model", "stack", "vertical_distance2", "vertical_model", "visual_model",
           "zero_rate_model"]


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


def vertical_model(R_wm: np.ndarray, std_rad: float, max_rad: float):
    """`vertical_measurement` as `(residual (3,), R (3, 3) rad^2, H (3, 12))`, or None when m's z is
    farther than `max_rad` from up."""
    ok, r, var, H = vertical_measurement(R_wm, std_rad, max_rad)
    return (r, var * I3, H) if ok else None


def vertical_distance2(R_wm: np.ndarray, P_m: np.ndarray, std_rad: float, max_rad: float) -> float | None:
    """Squared Mahalanobis distance of "the Manhattan z axis is world up" (`vertical_model`) for a
    Manhattan frame `R_wm` whose error (right perturbation) has covariance `P_m` (3, 3, rad^2); None
    when that pseudo-measurement does not apply (m's z farther than `max_rad` from up). A frame
    that fails it contradicts gravity: the vertical pseudo-measurement would tilt the camera."""
    model = vertical_model(R_wm, std_rad, max_rad)
    if model is None:
        return None
    r, R, H = model
    H_m = H[:, MF]
    return float(r @ np.linalg.solve(H_m @ P_m @ H_m.T + R, r))


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
