"""Attitude error metrics against ground truth (docs/design.md "Evaluation protocol"), on plain arrays.

ARE (degrees, paper eq. 10) after one constant chordal alignment of the estimated `R_wc` to the true `R_wc`
(the paper's protocol); tilt error (degrees) between estimated and true up in the camera frame, with no
alignment; NEES of the reported covariance (right perturbation of `R_wc`, rad^2) after the same
alignment, or after a rotation about up only for backends that know gravity, so that their
absolute tilt is scored as it is, against the whole covariance.

After the constant alignment the NEES is of what the alignment leaves: a covariance with a steady part
(`Estimate.cov_steady`: one calibration error shared by every frame, fixed in the camera) is scored by
`aligned_covariance`, its per-frame part plus what of the shared error the alignment cannot remove (all of
it where the camera turns a lot, none where it stands still). Without a steady part it is the covariance
as reported.
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
                    yaw_only_nees: bool = False, cov_steady_rad2: np.ndarray | None = None) -> dict:
    """Per-frame `are_deg`, `tilt_deg`, `nees` and `step_deg` (N,), NaN where `valid` is False;
    `step_deg` is the error of the rotation since the previous valid frame (`step_errors_deg`).

    `R_wc_est`, `R_wc_true` (N, 3, 3) camera-to-world; `cov_rad2` (N, 3, 3); `valid` (N,) bool (e.g.
    initialised frames whose ground truth is known); `cov_steady_rad2` (N, 3, 3) the steady part of each
    covariance (NaN or None: none), scored as the module docstring says.
    """
    n = len(R_wc_est)
    valid = np.asarray(valid, bool)
    are, tilt, ne = (np.full(n, np.nan) for _ in range(3))
    if valid.any():
        R_est, R_true = R_wc_est[valid], R_wc_true[valid]
        A = align_constant(R_est, R_true)
        are[valid] = are_deg(A @ R_est, R_true, align=False)
        tilt[valid] = tilt_error_deg(up_in_camera(R_est), up_in_camera(R_true))
        if yaw_only_nees:  # absolute tilt: the whole covariance
            ne[valid] = nees(align_yaw(R_est, R_true) @ R_est, R_true, cov_rad2[valid],
                             gauge_variance_rad2=GAUGE_VARIANCE_RAD2)
        else:
            cov = cov_rad2[valid] if cov_steady_rad2 is None else aligned_covariance(
                R_est, cov_rad2[valid], np.nan_to_num(np.asarray(cov_steady_rad2, float)[valid]))
            ne[valid] = nees(A @ R_est, R_true, cov, gauge_variance_rad2=GAUGE_VARIANCE_RAD2)
    step = np.full(n, np.nan)
    step[valid] = step_errors_deg(R_wc_est[valid], R_wc_true[valid])
    return {"are_deg": are, "tilt_deg": tilt, "nees": ne, "step_deg": step, "valid": valid}


VIEW_OVERLAP_DEG = 60.0
"""The angle (deg) between two optical axes at which two views share nothing: about a camera's horizontal
field of view (the ICSL Xtion 61.6 deg, TUM's Kinect 63.5 deg). A steady error is taken to be shared by two
frames as much as their views overlap (`view_overlap`)."""


def view_overlap(R_wc: np.ndarray, R_wc_other: np.ndarray | None = None,
                 overlap_deg: float = VIEW_OVERLAP_DEG) -> np.ndarray:
    """(N, M) in [0, 1]: how much the views of `R_wc` (N, 3, 3) and `R_wc_other` (M, 3, 3; None: `R_wc`) have
    in common, from t = the angle between their optical axes / `overlap_deg` (clipped to [0, 1]):
    1 - 3 t^2 + 2 t^3, which is 1 for the same view, 0 for views that share nothing and flat at both ends, so
    that the jitter of a still camera's estimates (tenths of a degree) is no change of view."""
    axes = R_wc[:, :, 2]
    other = axes if R_wc_other is None else R_wc_other[:, :, 2]
    t = np.clip(np.degrees(np.arccos(np.clip(axes @ other.T, -1.0, 1.0))) / overlap_deg, 0.0, 1.0)
    return 1.0 - 3.0 * t**2 + 2.0 * t**3


_OVERLAP_ROWS = 1024
"""Rows of `view_overlap` computed at once in `aligned_covariance`."""
_MEAN_FRAMES = 2000
"""`aligned_covariance` takes the alignment's mean over every k-th frame, at most this many (a long run's
cost stays linear in its length)."""


def aligned_covariance(R_wc_est: np.ndarray, cov_rad2: np.ndarray, cov_steady_rad2: np.ndarray) -> np.ndarray:
    """Covariance (N, 3, 3, rad^2, right perturbation of `R_wc`) of each frame's error after one constant
    alignment of the N estimates, when `cov_steady_rad2` of each `cov_rad2` is an error shared by the
    frames that see the same view: frame k errs by `delta_k = L_k z_k + w_k` (L_k the symmetric square
    root of its steady part, w_k its own error, of covariance cov - steady), z_k unit errors correlated
    as the views overlap (`view_overlap`: a camera standing still shares all of its steady error, two views
    that see nothing in common none). The alignment takes out the mean error in the world, mean_j R_j L_j
    z_j (to first order), and what is left is scored: `cov - steady` plus the covariance of
    `L_k z_k - R_k^T mean_j R_j L_j z_j`."""
    val, vec = np.linalg.eigh(0.5 * (cov_steady_rad2 + np.swapaxes(cov_steady_rad2, 1, 2)))
    L = (vec * np.sqrt(np.maximum(val, 0.0))[:, None, :]) @ np.swapaxes(vec, 1, 2)
    M = R_wc_est @ L  # each frame's steady error in the world
    j = slice(None, None, -(-len(M) // _MEAN_FRAMES))  # the mean over j from at most _MEAN_FRAMES frames
    flat, R_j = M[j].reshape(-1, 9), R_wc_est[j]
    T = np.concatenate([view_overlap(R_wc_est[i:i + _OVERLAP_ROWS], R_j) @ flat
                        for i in range(0, len(M), _OVERLAP_ROWS)]).reshape(-1, 3, 3) / len(flat)
    # Cov(M_k z_k, mean_j M_j z_j) = M_k T_k^T
    MT = M @ np.swapaxes(T, 1, 2)
    world = M @ np.swapaxes(M, 1, 2) - MT - np.swapaxes(MT, 1, 2) + MT.mean(axis=0)
    out = cov_rad2 - cov_steady_rad2 + np.swapaxes(R_wc_est, 1, 2) @ world @ R_wc_est
    return 0.5 * (out + np.swapaxes(out, 1, 2))


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
