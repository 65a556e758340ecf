"""The scene alignment of `Mekf`: the Manhattan frame initialised from a frame, and the test that
decides, frame by frame, that the camera has been ignored long enough to re-initialise it.

The world is z-up from the accelerometer with an IMU; the Manhattan frame `R_wm` is learned from the
first frame (labelled nearest up) and re-initialised after persistent disagreement
(`reinit_after_disagreement_s`, `visual_only_reinit_after_s`) or repeated gating
(`reinit_after_rejections`). See docs/design.md "Backends".
"""

from __future__ import annotations

import numpy as np

from ...rotations import angle_between
from ...types import VisualRotation
from . import status_bits
from .measurements import vertical_distance2
from .state import MF, N_STATE, TH, orthonormal


def ignored_too_long(filt, t_s: float, visual: VisualRotation) -> bool | None:
    """Whether the camera has been ignored long enough to re-initialise from `visual`, decided once
    per frame before the update runs; `filt` is a `Mekf`. A frame disagrees when its
    `R_cm`, labelled nearest the prediction, is further from it than the prediction's and its own
    covariance allow (d^2 over `disagreement_chi2` and angle over `disagreement_min_deg`): the gate
    then rejects it, or the Huber weight lets it move the estimate little, and persistent disagreement is drift the
    other flags do not show. Such a frame is flagged `VISUAL_IGNORED`; after
    `reinit_after_disagreement_s` (s) of them in a row, True (re-initialise). None: fuse the frame
    as usual (it agrees, or, the motion measured by a gyro or the image rotation, the gate and Huber
    weight handle it). False: skip it, with the constant-rate model, where fusing a large innovation
    would also corrupt the model's rate and spin the estimate away; the filter coasts. A non-finite
    frame changes nothing."""
    if not visual.is_finite():
        return None
    cfg = filt.config
    # During a run, the covariance of its start: coasting grows P, and must not let the wrong
    # rotations in as a jump.
    P = filt.P if filt.disagree_since_s is None else filt._disagree_P
    angle, d2 = filt.visual_distance(visual, P)
    # With a modelled motion (constant rate) a gated-out frame is a disagreement too: the filter coasts
    # through both alike. A measured one (gyro, image rotation) fuses them under the gate and Huber weight.
    measured = filt.motion.measures_motion
    chi2 = cfg.disagreement_chi2 if measured else min(cfg.disagreement_chi2, cfg.visual_gate_chi2)
    if not (angle > np.radians(cfg.disagreement_min_deg) and not d2 <= chi2):
        filt.disagree_since_s = filt._disagree_R_cm = None
        return None
    # Without an IMU, a run re-initialises only on frames that agree with each other (the camera
    # turned, or the filter drifted): two wrong minima in a row point different ways.
    previous, filt._disagree_R_cm = filt._disagree_R_cm, visual.R_cm
    consistent = measured or (
        previous is not None and float(angle_between(previous, visual.R_cm)) < 0.5 * angle)
    filt.flags |= status_bits.VISUAL_IGNORED
    filt._counters["visual_ignored"] += 1
    if filt.disagree_since_s is None:
        filt.disagree_since_s, filt._disagree_P = t_s, filt.P.copy()
    limit_s = cfg.reinit_after_disagreement_s if measured else cfg.visual_only_reinit_after_s
    if t_s - filt.disagree_since_s >= limit_s and consistent:
        return True
    return None if measured else False


def initialise_manhattan(filt, visual: VisualRotation, R_wm_ref: np.ndarray | None = None) -> bool:
    """`R_wm = R_wc R_cm`, labelled nearest `R_wm_ref` (3, 3; identity: m's z nearest up), with
    its covariance from the camera's and the measurement's: `dtheta_m = R_cm^T dtheta_c + delta`.
    The first frame with an IMU is refused (returns False, state kept) when its z axis is near
    up but fails the vertical pseudo-measurement's gate (`visual_gate_chi2`): it contradicts the
    accelerometer's tilt, and the pseudo-measurement would tilt the camera to it. A
    re-initialisation is not gated: then the filter's own tilt may be the wrong one. `filt` is a `Mekf`."""
    cfg = filt.config
    R_wm_ref = np.eye(3) if R_wm_ref is None else R_wm_ref
    visual = visual.symmetric_to(filt.R_wc.T @ R_wm_ref)
    R_wm = orthonormal(filt.R_wc @ visual.R_cm)
    T = np.eye(N_STATE)
    T[MF, MF] = 0.0
    T[MF, TH] = visual.R_cm.T
    P = T @ filt.P @ T.T
    P[MF, MF] += visual.cov
    if filt.motion.uses_imu and not filt.manhattan_initialised:
        d2 = vertical_distance2(R_wm, P[MF, MF], cfg.manhattan_vertical_std_rad, cfg.manhattan_vertical_max_rad)
        if d2 is not None and not d2 <= cfg.visual_gate_chi2:
            return False
    filt.R_wm = R_wm
    filt.P = 0.5 * (P + P.T)
    filt.manhattan_initialised = True
    filt.rejections = 0
    return True
