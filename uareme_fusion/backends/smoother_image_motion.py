"""The paper smoother's between-frame factors from the image rotations (`VisualRotation.R_cp`,
`solver/frame_motion.py`): the camera's rotation since the previous frame with a visual rotation,
measured from the image motion, as a "visual gyro" with a rate bias estimated in the window.

Without an IMU the paper's smoothness factor `f^s` (eq. 9) is an identity with a fixed std: it cannot
follow a handheld camera (TUM fr1 rpy turns 0.3 deg and more per frame) and it drags every frame
towards the previous one. The image rotation says how the camera turned: `X(j)^-1 X(k) = R_cp^T`
(`X = R_wc`, `j` the latest frame with a visual rotation). It is not unbiased: fitted as a pure
rotation, the image motion of a translating camera (a corridor walked along: ICSL corridor_more,
0.39 deg per frame about the camera's y axis against the depth reference) or of a focal length
estimated from the scene turns it by a steady rate that a chain of 30 frames turns into 12 deg.
So it enters as gyro preintegration does (`AHRSFactor` over a `PreintegratedAhrsMeasurements` of the
one "sample" `omega = Log(R_cp^T) / dt`, its covariance `R_cp_std_rad^2` per frame), with a rate bias
`C(k)` (rad/s, camera frame) per frame linked by a random walk and held near 0 by a prior at the
start: the window's visual priors estimate the bias, the image rotations carry the frame-to-frame
detail. `R_cp`'s perturbation is on the left (`Exp(eps) R_cp`); isotropic, it is the same on the
right of `R_cp^T`, as the factor takes it.
"""

from __future__ import annotations


import gtsam
import numpy as np
from gtsam.symbol_shorthand import C, X

from ..rotations import log_so3
from ..types import VisualRotation


class ImageMotionFactors:
    """The image-rotation factors and the rate-bias chain `C(k)` of a paper-mode window (module docstring).

    `bias_initial_std_rad_s`: prior std of the rate bias at a window's start; `bias_rw_rad_s2_sqrt_hz`:
    its random-walk density; `min_dt_s`: the shortest frame interval used for a rate."""

    def __init__(self, bias_initial_std_rad_s: float, bias_rw_rad_s2_sqrt_hz: float, min_dt_s: float = 1e-3):
        self.bias_initial_std_rad_s = bias_initial_std_rad_s
        self.bias_rw_rad_s2_sqrt_hz = bias_rw_rad_s2_sqrt_hz
        self.min_dt_s = min_dt_s
        self.bias_rad_s = np.zeros(3)
        """The latest frame's estimated rate bias of the image rotations (camera frame, rad/s)."""

    def start(self, graph, values, stamps, k: int) -> None:
        """A window's first frame `k` (or its restart): the bias `C(k)` with its prior at the last estimate."""
        noise = gtsam.noiseModel.Isotropic.Sigma(3, self.bias_initial_std_rad_s)
        graph.add(gtsam.PriorFactorVector(C(k), self.bias_rad_s, noise))
        values.insert(C(k), self.bias_rad_s)
        stamps[C(k)] = float(k)

    def add(self, graph, values, stamps, j: int, k: int, dt_s: float, frame_dt_s: float,
            visual: VisualRotation) -> None:
        """`X(j) -> X(k)` from `visual.R_cp` measured over `dt_s` seconds, biased by `C(j)`; the bias random
        walk `C(k-1) -> C(k)` over the frame interval `frame_dt_s`."""
        dt = max(float(dt_s), self.min_dt_s)
        params = gtsam.PreintegratedRotationParams()
        # GTSAM's discrete covariance is gyroscopeCovariance * dt: the frame's R_cp_std_rad^2.
        params.setGyroscopeCovariance(float(visual.R_cp_std_rad) ** 2 / dt * np.eye(3))
        pim = gtsam.PreintegratedAhrsMeasurements(params, self.bias_rad_s)
        pim.integrateMeasurement(log_so3(np.asarray(visual.R_cp, float).T) / dt, dt)
        graph.add(gtsam.AHRSFactor(X(j), X(k), C(j), pim))
        self.add_walk(graph, values, stamps, k, frame_dt_s)

    def add_walk(self, graph, values, stamps, k: int, frame_dt_s: float) -> None:
        """The bias random walk `C(k-1) -> C(k)` alone (a frame without an image rotation)."""
        sigma = self.bias_rw_rad_s2_sqrt_hz * np.sqrt(max(float(frame_dt_s), self.min_dt_s))
        graph.add(gtsam.BetweenFactorVector(C(k - 1), C(k), np.zeros(3), gtsam.noiseModel.Isotropic.Sigma(3, sigma)))
        values.insert(C(k), self.bias_rad_s)
        stamps[C(k)] = float(k)

    def take(self, values, k: int) -> None:
        """The bias of frame `k` from the optimised values."""
        self.bias_rad_s = np.asarray(values.atVector(C(k)), dtype=float)
