"""The paper's single-frame ablation: each frame solved alone, initialised from the stream's track.

Each frame's estimate is its own visual rotation; only its Manhattan labelling (one of 24) comes from the
stream: the one nearest a covariance-weighted track of the frames (`labelling_track.LabellingTrack`), so
that a few wrong frames do not walk the labelling to a neighbouring one. The track's rotation also
starts the next frame's solve (a start, not an anchor: the solver's `jump_margin`).

There is no gravity here: the world frame is the Manhattan frame as labelled on the first frame
(`R_wm = I`, so `R_wc = R_cm^T`), z up when the first view was roughly upright.
"""

from __future__ import annotations

import numpy as np

from ..types import Estimate, Status, VisualRotation, visual_R_wc_covariance
from .base import Backend
from .labelling_track import LabellingTrack, LabellingTrackConfig


class SingleFrame(Backend):
    """`R_wc = R_cm^T` per frame; frames without a visual rotation repeat the last estimate."""

    name = "single"
    uses_image_motion = True  # the labelling track

    def __init__(self, missing_variance_rad2: float = 1.0, labelling: LabellingTrackConfig | None = None):
        self.missing_variance_rad2 = missing_variance_rad2
        self._last: Estimate | None = None
        self.track = LabellingTrack(labelling)

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        if visual is None:
            if self._last is None:
                est = Estimate(t_s, np.eye(3), self.missing_variance_rad2 * np.eye(3),
                               Status.VISUAL_MISSING | Status.NOT_INITIALISED)
            else:
                est = Estimate(t_s, self._last.R_wc, self._last.cov, Status.VISUAL_MISSING, R_wm=np.eye(3))
        else:
            visual = self.track.label(t_s, visual)
            # (R_cm Exp(delta))^T = R_cm^T Exp(-R_cm delta): the right error of R_wc is -R_cm delta.
            est = Estimate(t_s, visual.R_cm.T, visual_R_wc_covariance(visual), R_wm=np.eye(3))
        self._last = est
        return est

    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        prediction = self.track.predicted(t_s)
        return None if prediction is None else prediction[0]
