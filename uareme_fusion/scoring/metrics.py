"""Attitude error metrics against ground truth (docs/design.md "Evaluation protocol"), on plain arrays.

ARE (degrees, paper eq. 10) after one constant chordal alignment of the estimated `R_wc` to the true `R_wc`
(the paper's protocol); tilt error (degrees) between estimated and true up in the camera frame, with no
alignment; NEES of the reported covariance (right perturbation of `R_wc`, rad^2) after the same
alignment, or after a rotation about up only for backends that know gravity, so that their
absolute tilt is scored as it is.
"""

from __future__ import annotations

import numpy as np

from ..rotations import align_constant, align_yaw, are_deg, nees, tilt_error_deg, up_in_camera
from .statistics import error_stats

JUMP_DEG = 10.0
"""An ARE above this is a globally inconsistent frame (a wrong Manhattan labelling or local minimum);
a frame-to-frame rotation wrong by more than this is a jump."""
GAUGE_VARIANCE_RAD2 = 1e-12
"""Variances at most this are gauge directions (world yaw fixed at initialisation), left out of NEES."""


def attitude_errors(R_wc_est: np.ndarray, cov_rad2: np.ndarray, valid: np.ndarray, R_wc_true: np.ndarray,
                    yaw_only_nees: bool = False) -> dict:
    """Per-frame `are_deg`, `tilt_deg`, `nees` and `step_deg` (N,), NaN where `valid` is False;
    `step_deg` is the error of the rotation since the previous valid frame (`step_errors_deg`).

    `R_wc_est`, `R_wc_true` (N, 3, 3) camera-to-world; `cov_rad2` (N, 3, 3); `valid` (N,) bool (e.g.
    initialised frames whose ground truth is known).
    """
    n = len(R_wc_est)
    valid = np.asarray(valid, bool)
    are, tilt, ne = (np.full(n, np.nan) for _ in range(3))
    if valid.any():
        R_est, R_true = R_wc_est[valid], R_wc_true[valid]
        A = align_constant(R_est, R_true)
        are[valid] = are_deg(A @ R_est, R_true, align=False)
        tilt[valid] = tilt_error_deg(up_in_camera(R_est), up_in_camera(R_true))
        A_nees = align_yaw(R_est, R_true) if yaw_only_nees else A
        ne[valid] = nees(A_nees @ R_est, R_true, cov_rad2[valid], gauge_variance_rad2=GAUGE_VARIANCE_RAD2)
    step = np.full(n, np.nan)
    step[valid] = step_errors_deg(R_wc_est[valid], R_wc_true[valid])
    return {"are_deg": are, "tilt_deg": tilt, "nees": ne, "step_deg": step, "valid": valid}


def step_errors_deg(R_wc_est: np.ndarray, R_wc_true: np.ndarray) -> np.ndarray:
    """Angle (deg) between the estimated and the true rotation from each frame to the next,
    `(R_est[k-1]^T R_est[k])^T (R_true[k-1]^T R_true[k])`; NaN for the first frame. Needs no
    alignment: a jump of the estimate between two frames shows here whatever its ARE."""
    out = np.full(len(R_wc_est), np.nan)
    if len(R_wc_est) > 1:
        step_est = np.swapaxes(R_wc_est[:-1], 1, 2) @ R_wc_est[1:]
        step_true = np.swapaxes(R_wc_true[:-1], 1, 2) @ R_wc_true[1:]
        out[1:] = are_deg(step_est, step_true, align=False)
    return out


def error_summary(errors: dict) -> dict:
    """The eval summary: `are_deg` {mean, median, max}, `tilt_deg` {mean, rmse, p95, max}, `nees` {mean},
    `frames_are_over_10deg` (frames whose ARE is above `JUMP_DEG`), `frame_jumps_over_10deg`
    (frame-to-frame rotations wrong by more than `JUMP_DEG`, `step_errors_deg`) and `frames_scored`,
    as plain floats for JSON (empty dicts with no valid frame)."""
    ok = errors["valid"]
    a, t, ne = errors["are_deg"][ok], errors["tilt_deg"][ok], errors["nees"][ok]
    if not ok.any():
        return {"frames_scored": 0, "are_deg": {}, "tilt_deg": {}, "nees": {}, "frames_are_over_10deg": 0,
                "frame_jumps_over_10deg": 0}
    return {"frames_scored": int(ok.sum()),
            "are_deg": error_stats(a, ("mean", "median", "max")),
            "tilt_deg": error_stats(t, ("mean", "rmse", "p95", "max")),
            "nees": error_stats(ne, ("mean", "median")),
            **jump_counts(errors)}


def jump_counts(errors: dict) -> dict:
    """`frames_are_over_10deg` and `frame_jumps_over_10deg` of `attitude_errors` output."""
    ok = errors["valid"]
    return {"frames_are_over_10deg": int(np.sum(errors["are_deg"][ok] > JUMP_DEG)),
            "frame_jumps_over_10deg": int(np.sum(np.nan_to_num(errors["step_deg"][ok]) > JUMP_DEG))}
