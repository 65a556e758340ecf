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

A frame's absolute rotation errs the same way for seconds (the same walls, the same network's view of
them); against the precise image rotations that error is not averaged away but followed. It is a state,
the visual bias (`MekfConfig.image_rotation_visual_bias_std_rad`): a Gauss-Markov rotation that the visual
residual sees in the Manhattan frame's error block (`R_cm = R_wc^T R_wm`, `H = [.., I, ..]`; without an IMU
the world is the first Manhattan frame, so `R_wm` holds only the bias, shrinking back to the identity),
predicted with each image rotation (`visual_bias_predict`). The frames are then fused whole, and the
attitude's covariance carries what the bias leaves unknown. With an accelerometer without gyro
(`gravity_only.py`) the world is gravity's, and `R_wm` holds the bias and the scene's lean from gravity,
both shrinking back to the relabelling (walls vertical): the camera's tilt is the accelerometer's, carried
between its windows by the image rotations.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ...rotations import nearest_symmetric
from ...types import VisualRotation
from .compiled import image_rotation_predict
from .config import MekfMode
from .motion import ConstantRateMotion
from .state import MF, TH


_NO_COV = np.zeros((3, 3))
_NO_COV.setflags(write=False)


class ImageRotationMotion(ConstantRateMotion):
    """Visual only: between frames the image rotation `R_cp` when the frame has one (module docstring),
    else the constant-rate model; the world is the first Manhattan frame (`ConstantRateMotion`)."""

    waits_for_frame = True

    def __init__(self, mode: MekfMode = MekfMode.VISUAL_ONLY):
        super().__init__(mode)
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
        t_before_s = filt.t_state
        if self.measures_motion:
            self.predict_by_image(filt, t_s, visual.R_cp, float(visual.R_cp_std_rad) ** 2)
            if self.has_bias(filt):
                visual_bias_predict(filt, t_s - t_before_s, bias_std_rad(filt.config, visual),
                                    filt.config.image_rotation_visual_bias_correlation_s)

    def predict_by_image(self, filt, t_s: float, R_cp: np.ndarray, var_rad2: float) -> None:
        """The prediction to `t_s` (s) by the image rotation `R_cp` of variance `var_rad2` (rad^2 per axis)
        (`kernel_image_rotation.image_rotation_predict`)."""
        image_rotation_predict(filt, t_s, R_cp, var_rad2, filt.config.rate_rw_rad_s2_sqrt_hz**2)

    @staticmethod
    def bias_on(filt) -> bool:
        """Whether the frames' persistent error is a state (`image_rotation_visual_bias_std_rad`), with or
        without an accelerometer (`gravity_only.py`): with one, the camera's tilt is the accelerometer's
        carried by the image rotations, and the frames' persistent error goes to the bias, not to the tilt.
        Real TUM fr1 rpy, mekf, the Kinect's accelerometer, tilt after the alignment, training / evaluation
        frames: bias off 2.10 / 2.60 deg (depth normals), 2.49 / 3.48 (learned); on, with the accelerometer
        weighted as it errs (`accel_only_noise_rad_sqrt_s` 0.015), 1.48 / 1.33 and 1.74 / 2.32; without the
        accelerometer 1.91 / 2.34 and 3.53 / 9.77. The bias on with the still sensor's 0.001 gave NEES 93-153."""
        return filt.config.image_rotation_visual_bias_std_rad > 0

    def has_bias(self, filt) -> bool:
        """Whether the current frame is fused against the visual bias state: the bias is on (`bias_on`) and the
        frame was predicted by its image rotation (`measures_motion`). A frame without one is fused by the
        constant-rate model's rule, its independent share (a stream without image rotations: SYNTHETIC
        persistent errors, tests/backends/test_visual_noise_share.py)."""
        return self.measures_motion and self.bias_on(filt)

    def visual_noise_scale(self, filt) -> float:
        """With the visual bias a state (`has_bias`), the filter carries the persistent error and each frame
        is fused with its whole covariance (1); else `ConstantRateMotion`'s (its independent share)."""
        return 1.0 if self.has_bias(filt) else super().visual_noise_scale(filt)

    def persistent_cov(self, filt) -> np.ndarray:
        """With the visual bias a state, the attitude's covariance holds it: nothing is added. Else
        `ConstantRateMotion`'s (the frame's persistent share, which the filter carries)."""
        return _NO_COV if self.has_bias(filt) else super().persistent_cov(filt)

    def predicted_R_wc(self, filt, t_s: float) -> np.ndarray:
        """`R_wc` (3, 3) predicted to `t_s` (s) by the rate, the state left where it is: the frame's image
        rotation, which comes with its visual rotation, predicts it (`propagate_to`)."""
        dt = t_s - filt.t_state if filt.initialised and t_s > filt.t_state else 0.0
        return filt.R_wc @ Rotation.from_rotvec(filt.omega_c * dt).as_matrix()

    def _restart(self, filt, visual: VisualRotation) -> None:
        super()._restart(filt, visual)
        # The frame's bias is the Manhattan block's error and part of the attitude's; with an accelerometer the
        # Manhattan block starts from the world's tilt prior instead (`gravity_only.world_tilt_prior`).
        if self.bias_on(filt) and not filt.gravity_only.active:
            var, R_cw = bias_std_rad(filt.config, visual) ** 2, filt.R_wc.T
            filt.P[MF, MF] = var * np.eye(3)
            filt.P[TH, MF] = var * R_cw
            filt.P[MF, TH] = var * R_cw.T
            filt.P[TH, TH] += var * np.eye(3)  # R_cw (var I) R_cw^T
        self._before_gap = None


def bias_std_rad(cfg, visual: VisualRotation) -> float:
    """The visual bias's steady std for a frame, rad per axis: `image_rotation_visual_bias_std_rad`, at most
    `image_rotation_visual_bias_max_share` of the frame's own variance (a precise frame's error cannot
    persist beyond it)."""
    own_var = float(np.trace(visual.cov)) / 3.0
    return float(np.sqrt(min(cfg.image_rotation_visual_bias_std_rad**2, cfg.image_rotation_visual_bias_max_share * own_var)))


def visual_bias_predict(filt, dt_s: float, std_rad: float, correlation_s: float) -> None:
    """The visual bias (the Manhattan frame's error block, visual only) predicted over `dt_s` (s) as a
    Gauss-Markov rotation of steady std `std_rad` (rad per axis) and correlation time `correlation_s` (s):
    `R_wm <- G Exp(rho Log(G^T R_wm))` for `G` the relabelling nearest `R_wm` (the identity unless the world
    was relabelled), `P[MF, :] *= rho`, `P[:, MF] *= rho`, `P[MF, MF] +=
    std^2 (1 - rho^2) I`, `rho = exp(-dt / tau)`."""
    rho = float(np.exp(-dt_s / correlation_s))
    G = nearest_symmetric(np.eye(3), filt.R_wm)[0]
    filt.R_wm = G @ Rotation.from_rotvec(rho * Rotation.from_matrix(G.T @ filt.R_wm).as_rotvec()).as_matrix()
    P = filt.P.copy()
    P[MF, :] *= rho
    P[:, MF] *= rho
    P[MF, MF] += std_rad**2 * (1.0 - rho**2) * np.eye(3)
    filt.P = P
