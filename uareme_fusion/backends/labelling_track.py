"""Which of the 24 Manhattan labellings a stream's frame gets: the one nearest a track of the frames,
each weighted by its own covariance, not the one nearest the previous frame.

A frame's solve `R_cm` is known only up to the 24 relabellings `R_cm P` (`rotations.manhattan_symmetries`).
Labelled nearest the previous frame alone, one wrong frame (a wrong minimum 25-45 deg off, real on TUM
fr1 rpy) hands its error to the next and a run of them walks the labelling to a neighbouring one: from
then on every frame is 90 deg off its world. The track is a rotation with a covariance: between frames its
covariance grows by the camera's possible motion (`LabellingTrackConfig.rate_std_rad_s`: handheld 100 deg/s,
a constant-rotation model), and each frame, relabelled nearest it, moves it by a Kalman update with the
frame's own covariance; a frame that disagrees with it beyond the chi-square gate is labelled but does
not move it. When the frame carries the camera's rotation since the previous frame from the image motion
(`VisualRotation.R_cp`, `solver/frame_motion.py`: 0.3 deg mean error on TUM), the track is turned by it
and widens by its std instead: a run of wrong frames then moves it only as far as the image says the
camera turned. So a confident frame sets the labelling and a wide one (a blurred or textureless frame, the
capped covariance of a frame without evidence) barely moves it.

Convention: the track's covariance is of `delta` in `R_cm_true = R_cm @ Exp(delta)` (rad^2), as
`VisualRotation.cov`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import exp_so3, log_so3
from ..types import VisualRotation


@dataclass(frozen=True)
class LabellingTrackConfig:
    """Parameters of `LabellingTrack` (units in the names)."""

    rate_std_rad_s: float = float(np.radians(100.0))
    """Standard deviation of the camera's angular rate per axis (rad/s): the track's covariance grows by
    (rate_std_rad_s dt)^2 per axis over dt seconds. 100 deg/s: a handheld camera turned fast."""
    gate_chi2: float = 16.27
    """A frame whose Mahalanobis distance squared to the track (with both covariances) exceeds this does
    not move the track (chi-square, 3 degrees of freedom, 99.9 %)."""
    restart_after_rejected: int = 5
    """After this many consecutive frames beyond the gate the track restarts at the frame (in the labelling
    nearest it, with the frame's covariance): evidence that keeps disagreeing wins over a track whose
    image rotations drifted (an image rotation biased by a focal length estimated from the scene)."""
    max_gap_s: float = 1.0
    """Frames further apart than this (a stream that stopped) predict over this at most: the labelling
    is kept, the track is as wide as a second of turning allows."""


class LabellingTrack:
    """`label(t_s, visual)` relabels each frame of a stream nearest the track and updates the track."""

    def __init__(self, config: LabellingTrackConfig | None = None):
        self.config = config or LabellingTrackConfig()
        self.R_cm: np.ndarray | None = None
        """The track's rotation (None before the first frame)."""
        self.cov = np.zeros((3, 3))
        self.t_s = float("nan")
        self.rejected = 0
        """Frames that disagreed with the track beyond the gate (labelled, not fused)."""
        self.restarts = 0
        """Times the track restarted at a frame after `restart_after_rejected` consecutive rejections."""
        self._rejected_run = 0

    def start(self, t_s: float, visual: VisualRotation) -> None:
        """Restart the track at `visual` as it is labelled (a backend's first frame or re-initialisation)."""
        self.R_cm, self.cov, self.t_s, self._rejected_run = np.array(visual.R_cm, float), np.asarray(visual.cov, float), t_s, 0

    def predicted(self, t_s: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The track's (R_cm, cov) predicted to `t_s`; None before the first frame."""
        if self.R_cm is None:
            return None
        dt = min(max(t_s - self.t_s, 0.0), self.config.max_gap_s) if np.isfinite(t_s - self.t_s) else 0.0
        return self.R_cm, self.cov + (self.config.rate_std_rad_s * dt) ** 2 * np.eye(3)

    def _moved(self, t_s: float, visual: VisualRotation) -> tuple[np.ndarray, np.ndarray]:
        """The track predicted to `visual`'s frame: turned by its image rotation `R_cp` when it has one
        (`R_cm = R_cp R_pm`; an isotropic left perturbation is the same on the right), else `predicted`."""
        if not visual.has_image_rotation():
            return self.predicted(t_s)
        return visual.R_cp @ self.R_cm, self.cov + visual.R_cp_std_rad ** 2 * np.eye(3)

    def label(self, t_s: float, visual: VisualRotation) -> VisualRotation:
        """`visual` with the labelling nearest the track; the track then takes it in (first frame: it
        starts there), unless it is beyond the gate (then, the `restart_after_rejected`-th such frame in a
        row restarts it there) or its covariance is not finite. A non-finite rotation is returned as it is."""
        if not np.isfinite(visual.R_cm).all():
            return visual
        prediction = self.predicted(t_s)
        if prediction is None:
            self.start(t_s, visual)
            return visual
        R_pred, P = self._moved(t_s, visual)
        visual = visual.symmetric_to(R_pred)
        self.R_cm, self.cov, self.t_s = R_pred, P, t_s
        C = np.asarray(visual.cov, float)
        if not np.all(np.isfinite(C)):
            return visual
        r = log_so3(R_pred.T @ visual.R_cm)
        S = P + C
        if float(r @ np.linalg.solve(S, r)) > self.config.gate_chi2:
            self.rejected += 1
            self._rejected_run += 1
            if self._rejected_run >= self.config.restart_after_rejected:
                self.start(t_s, visual)
                self.restarts += 1
            return visual
        self._rejected_run = 0
        gain = np.linalg.solve(S, P).T  # P S^-1 (P and S symmetric)
        self.R_cm = R_pred @ exp_so3(gain @ r)
        I_KH = np.eye(3) - gain
        self.cov = I_KH @ P @ I_KH.T + gain @ C @ gain.T  # Joseph form
        return visual
