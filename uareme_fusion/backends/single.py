"""The paper's single-frame ablation: each frame solved alone, initialised from the last one.

There is no gravity here: the world frame is the Manhattan frame as labelled on the first frame
(`R_wm = I`, so `R_wc = R_cm^T`), z up when the first view was roughly upright.
"""

from __future__ import annotations

import numpy as np

from ..types import Estimate, Status, VisualRotation, visual_R_wc_covariance
from .base import Backend


class SingleFrame(Backend):
    """`R_wc = R_cm^T` per frame; frames without a visual rotation repeat the last estimate."""

    name = "single"

    def __init__(self, missing_variance_rad2: float = 1.0):
        self.missing_variance_rad2 = missing_variance_rad2
        self._last: Estimate | None = None

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        if visual is None:
            if self._last is None:
                est = Estimate(t_s, np.eye(3), self.missing_variance_rad2 * np.eye(3),
                               Status.VISUAL_MISSING | Status.NOT_INITIALISED)
            else:
                est = Estimate(t_s, self._last.R_wc, self._last.cov, Status.VISUAL_MISSING, R_wm=np.eye(3))
        else:
            if self._last is not None:
                # Keep the labelling nearest the last frame (the solver was initialised from it).
                visual = visual.symmetric_to(self._last.R_wc.T)
            # (R_cm Exp(delta))^T = R_cm^T Exp(-R_cm delta): the right error of R_wc is -R_cm delta.
            est = Estimate(t_s, visual.R_cm.T, visual_R_wc_covariance(visual), R_wm=np.eye(3))
        self._last = est
        return est

    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        return None if self._last is None else self._last.R_wc.T
