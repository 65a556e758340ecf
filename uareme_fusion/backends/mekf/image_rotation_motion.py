"""`ImageRotationMotion`: the visual-only EKF propagated by the image rotation between frames, a visual gyro.

Without an IMU the constant-rate model guesses the camera's motion between frames; a handheld camera
turns up to 175 deg/s and changes its rate every frame, so the guess is wrong by degrees and the filter
leans on each frame's absolute rotation, errors and all. Frames of a stream carry the camera's rotation
since the previous frame from the image motion (`VisualRotation.R_cp`, `solver/frame_motion.py`: tracked
corners, 0.35 deg mean error on TUM fr1 rpy), so a frame is predicted by it (`R_wc = R_wc_p R_cp^T`,
its std as process noise: `kernel_image_rotation.py`) and the absolute rotation corrects that
prediction, as with a gyro. A frame without an image rotation (the first, too few tracks) is predicted
by the constant-rate model, whose rate the image rotations keep measured.

The image rotation spans the previous frame that had a visual rotation (`FrameMotion` tracks from the
frame the solver last answered for); frames without one in between were predicted by the rate: the
state before them is kept, and the next image rotation starts from it.

A frame predicted by its image rotation that disagrees with the prediction is fused under the gate and
the Huber weight, as with a gyro, and the filter re-initialises after `reinit_after_disagreement_s` of
such frames (`scene.py`, `measures_motion`): the motion is measured, not the model's, so a large
innovation does not spin the estimate away. A frame predicted by the rate is treated as the
constant-rate model's (a stream without image rotations runs as `ConstantRateMotion`).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...types import VisualRotation
from ..visual_error_persistence import VisualErrorPersistence
from .compiled import image_rotation_predict
from .config import MekfMode
from .motion import ConstantRateMotion


_NO_COV = np.zeros((3, 3))
_NO_COV.setflags(write=False)


class ImageRotationMotion(ConstantRateMotion):
    """Visual only: between frames the image rotation `R_cp` when the frame has one (module docstring),
    else the constant-rate model; the world is the first Manhattan frame (`ConstantRateMotion`)."""

    waits_for_frame = True

    def __init__(self, mode: MekfMode = MekfMode.VISUAL_ONLY):
        super().__init__(mode)
        self.persistence: VisualErrorPersistence | None = None
        """The stream's learned correlation time of its visual errors (`image_rotation_error_persistence_lag_frames`;
        made at the first frame, from the filter's config)."""
        self.measures_motion = False
        """Whether the current frame was predicted by its image rotation (else by the rate, and `scene.py`
        treats it as the constant-rate model's)."""
        self._before_gap: tuple | None = None
        """(t_state, R_wc, R_wm, P, omega_c) before the frames without a visual rotation since the last one
        with: where the next image rotation starts."""

    def propagate_to(self, filt, t_s: float, visual: VisualRotation | None = None) -> None:
        """To the frame at `t_s` (s) with its visual rotation; None: a frame without one, or a prediction
        asked before the frame (by the rate, the state before it kept for the frame's image rotation)."""
        if not filt.initialised:
            return
        if visual is None:
            if t_s > filt.t_state:
                if self.persistence is not None:
                    self.persistence.update(t_s, None)  # a frame without a rotation: the chain breaks
                if self._before_gap is None:
                    self._before_gap = (filt.t_state, filt.R_wc.copy(), filt.R_wm.copy(), filt.P.copy(),
                                        filt.omega_c.copy())
                self.measures_motion = False
                self.predict_by_rate(filt, t_s)
            return
        before, self._before_gap = self._before_gap, None
        if not visual.has_image_rotation():
            self.measures_motion = False
            if t_s > filt.t_state:
                self.predict_by_rate(filt, t_s)
            return
        if before is not None:
            filt.t_state, filt.R_wc, filt.R_wm, filt.P, filt.omega_c = before
        self.measures_motion = t_s > filt.t_state
        if self.measures_motion:
            self.predict_by_image(filt, t_s, visual.R_cp, float(visual.R_cp_std_rad) ** 2)

    def predict_by_image(self, filt, t_s: float, R_cp: np.ndarray, var_rad2: float) -> None:
        """The prediction to `t_s` (s) by the image rotation `R_cp` of variance `var_rad2` (rad^2 per axis)
        (`kernel_image_rotation.image_rotation_predict`)."""
        image_rotation_predict(filt, t_s, R_cp, var_rad2, filt.config.rate_rw_rad_s2_sqrt_hz**2)

    def visual_noise_scale(self, filt) -> float:
        """Predicted by its image rotation, a frame's visual error has an independent share `lam`
        (`VisualNoiseShare`) and a persistent one, `1 - lam`, that lasts `image_rotation_error_correlation_s`
        (`tau`): a frame `dt` s after the previous visual update holds `dt / tau` of an independent look
        at the persistent error, so the covariance fused is `(lam + (1 - lam) max(1, tau / dt)) C`. With the
        time learned from the stream (`image_rotation_error_persistence_lag_frames`), the whole error is
        Gauss-Markov of that time: `C (1 + rho) / (1 - rho)`, `rho = exp(-dt / tau)`, the variance of a
        mean of such looks per look. Predicted by the rate: `ConstantRateMotion`'s."""
        share = super().visual_noise_scale(filt)
        tau_s = self.correlation_s(filt)
        t_prev = filt.t_visual_s
        if not self.measures_motion or tau_s <= 0 or t_prev is None or not filt.t_state > t_prev:
            return share
        if self.persistence is not None:
            rho = np.exp(-(filt.t_state - t_prev) / tau_s)
            return (1.0 + rho) / (1.0 - rho)
        return share + (1.0 - share) * max(1.0, tau_s / (filt.t_state - t_prev))

    def persistent_cov(self, filt) -> np.ndarray:
        """Predicted by its image rotation with a correlation time, the filter averages the persistent error
        over it (`visual_noise_scale`), and its own covariance says how well: nothing is added. Else
        `ConstantRateMotion`'s (the frame's persistent share, which the filter carries)."""
        if self.measures_motion and self.correlation_s(filt) > 0:
            return _NO_COV
        return super().persistent_cov(filt)

    def correlation_s(self, filt) -> float:
        """How long the persistent share of a frame's visual error lasts, s: learned from the stream
        (`visual_error_persistence.py`) when `image_rotation_error_persistence_lag_frames` is set, else
        `image_rotation_error_correlation_s`."""
        if self.persistence is None:
            return filt.config.image_rotation_error_correlation_s
        return self.persistence.tau_s

    def observe_visual(self, filt, t_s: float, visual: VisualRotation) -> None:
        """The frame's labelled rotation and image rotation into the learned correlation time (after its
        update: a frame's own error does not set its weight)."""
        cfg = filt.config
        if self.persistence is None and cfg.image_rotation_error_persistence_lag_frames > 1:
            self.persistence = VisualErrorPersistence(cfg.image_rotation_error_persistence_lag_frames,
                                                      cfg.image_rotation_error_persistence_frames,
                                                      cfg.image_rotation_error_persistence_max_s)
        if self.persistence is not None:
            self.persistence.update(t_s, visual)

    def predicted_R_wc(self, filt, t_s: float) -> np.ndarray:
        """`R_wc` (3, 3) predicted to `t_s` (s) by the rate, the state left where it is: the frame's image
        rotation, which comes with its visual rotation, predicts it (`propagate_to`)."""
        dt = t_s - filt.t_state if filt.initialised and t_s > filt.t_state else 0.0
        return filt.R_wc @ Rotation.from_rotvec(filt.omega_c * dt).as_matrix()

    def _restart(self, filt, visual: VisualRotation) -> None:
        super()._restart(filt, visual)
        self._before_gap = None
        if self.persistence is not None:
            self.persistence.update(filt.t_state, None)  # a new labelling: the chain restarts
