"""GTSAM sliding-window smoother: the paper's multi-frame factor graph (Sec. 3.2) and a gyro-aided mode.

Variables. One `Rot3` per frame, `X(k) = R_wc` at frame k (camera to world, z up in gyro mode).
The paper writes its graph over the single-frame rotations; with `R_wc = R_wm @ R_cm^T` and an
isotropic smoothness noise the two parametrisations give exactly the same cost (the prior residual
changes by a rotation, `Log(Z^-1 R)` for `R_wc` equals `-R_cm Log(R_cm_meas^T R_cm)`, and its
covariance is rotated with it). `R_wc` is chosen because gyro preintegration (`AHRSFactor`) and the
gravity factor (`AttitudeFactorRot3`) are written for a body-to-navigation rotation.

GTSAM's `Rot3` tangent convention is the project's: `retract(R, xi) = R @ Exp(xi)` (right
perturbation; checked in tests/backends/test_smoother.py), and `Marginals.marginalCovariance(X(k))` is the
covariance of that `xi` in rad^2. So the `Estimate.cov` returned here is the right-perturbation
covariance of `R_wc`, as docs/design.md requires.

Paper mode (`mode: paper`), exactly the paper's graph: `BatchFixedLagSmoother` over the last
`window_frames` frames; per frame a `PriorFactorRot3` on `X(k)` at `R_cm^T` with the visual
covariance rotated to `R_cm @ cov @ R_cm^T` and a Huber(`visual_huber_k`) kernel (paper eq. 9, f^z); an
identity `BetweenFactorRot3` with isotropic `between_std_rad` between consecutive frames (f^s); the
oldest frame's marginal prior (f^p) is what the fixed-lag smoother leaves when it marginalises.
The world is the Manhattan frame as labelled on the first frame: `R_wm = I`.
Two departures when the frames carry the image rotation since the previous frame (`VisualRotation.R_cp`,
`uses_image_motion`; docs/departures.md): f^s is that rotation, `X(j)^-1 X(k) = R_cp^T` from the latest
frame `j` with a visual rotation, with a rate bias `C(k)` estimated in the window
(`smoother_image_motion.py`: the identity could not follow a handheld camera, real TUM fr1 rpy eval
RGB 44.6 deg ARE against `single`'s 19.0, 15.7 with it), and those frames' f^z use
`image_motion_visual_huber_k`; frames are labelled by the labelling track (`labelling_track.py`, as
`single`), not nearest the smoother's own estimate. Without `R_cp` the graph is the paper's.

Gyro-aided mode (`mode: gyro`): the between factors are `AHRSFactor`s from gyro preintegration
(`PreintegratedAhrsMeasurements`) with one gyro-bias variable `B(k)` per frame linked by a random
walk; an `AttitudeFactorRot3` per frame from the mean accelerometer direction since the previous
frame, with a noise inflated by how far |a| is from gravity and by the samples' spread: while the gyro
says still (`still_rate_rad_s`) only by the mean's standard error (vibration averages out: weighed by the
samples' RMS, the quiet accelerometer of a static drone with running motors, real EuRoC V1_01, lost to
the gyro bias: tilt 2.8-3.8 deg against the IMU alone's 1.78, now 0.8-0.9). The world is
gravity aligned, so `R_wm` is no longer the identity: it is a variable `M` kept in the window
(its timestamp is refreshed every frame), and each visual rotation enters as a
`BetweenFactorRot3(M, X(k), R_cm^T)` (the measurement `R_mc = R_wm^T R_wc`). `R_wm` gets a prior at
the identity that pins the world's yaw (a gauge: world x is the Manhattan x axis) and lets its tilt
move by `manhattan_vertical_std_rad` (in a building the Manhattan axis nearest up is vertical). On the
first frame the visual rotation is relabelled so that its z axis is the Manhattan axis nearest the
measured up. The Manhattan frame is constant (a building), not a vehicle.

Frames without a visual rotation add no prior; the graph carries on along the between factors. An
optimiser failure (a GTSAM exception or a non-finite result) is logged with the frame time and the
window restarts from the last good estimate (`Status.OPTIMISER_FAILED`).
"""

from __future__ import annotations

import enum
import logging
from typing import ClassVar

import gtsam
import numpy as np
from gtsam.symbol_shorthand import M, X
from pydantic import ConfigDict, Field, field_validator

from ..rotations import is_rotation, manhattan_symmetries
from ..types import Estimate, Status, VisualRotation, visual_R_wc_covariance, visual_R_wc_steady
from .base import Backend
from .imu_noise import GyroNoiseConfig
from .labelling_track import LabellingTrack
from .mekf.source_trust import STILL_RATE_RAD_S
from .smoother_image_motion import ImageMotionFactors
from .visual_noise_share import VisualNoiseShare

try:  # BatchFixedLagSmoother moved from gtsam_unstable into gtsam in 4.3/5.0.
    from gtsam import BatchFixedLagSmoother
except ImportError:  # pragma: no cover - depends on the installed gtsam
    from gtsam_unstable import BatchFixedLagSmoother

log = logging.getLogger(__name__)

MANHATTAN_KEY = M(0)


class SmootherMode(str, enum.Enum):
    """Which between-frame and gravity factors the graph uses."""

    PAPER = "paper"
    """Identity between factors, no IMU, `R_wm = I` (the paper's graph)."""
    GYRO = "gyro"
    """Gyro preintegration between frames, accelerometer gravity factors, gravity-aligned world."""


class SmootherConfig(GyroNoiseConfig):
    """Parameters of `Smoother`; defaults are the paper's values (configs/paper.yaml, section `smoother`)."""

    model_config = ConfigDict(extra="forbid")
    renamed_keys: ClassVar[dict[str, str]] = {
        "huber_k": "visual_huber_k",
        "gyro_bias_walk_rad_s2_sqrt_hz": "gyro_bias_rw_rad_s2_sqrt_hz",
        "gyro_bias_prior_sigma_rad_s": "gyro_bias_initial_std_rad_s",
        "between_sigma_rad": "between_std_rad",
        "accel_sigma_rad": "accel_std_rad",
        "world_yaw_sigma_rad": "world_yaw_std_rad",
        "manhattan_tilt_sigma_rad": "manhattan_vertical_std_rad",
        "visual_huber_sigma": "visual_huber_k",
    }
    """Old key -> new key: an old key in a configuration file is an error naming the new one."""

    mode: SmootherMode = SmootherMode.PAPER
    window_frames: int = Field(30, ge=2, le=10000)
    """Frames kept in the sliding window (the paper's n)."""
    visual_huber_k: float | None = Field(0.1, ge=1e-3, le=1e6)
    """Huber threshold k on the Mahalanobis distance d of the visual residual (GTSAM's Huber on the
    whitened residual's norm; the EKF's key of the same name and meaning: weight k/d beyond k); None for a
    plain Gaussian prior. The paper's 0.1 (the EKF's default is 2.0) down-weights nearly every frame."""
    between_std_rad: float = Field(0.1, ge=1e-6, le=10.0)
    """Isotropic std of the identity smoothness factor, rad (the paper's lambda = std^2)."""
    missing_variance_rad2: float = Field(1.0, ge=1e-12, le=100.0)
    """Variance reported per axis before the first visual rotation."""
    visual_noise_share_frames: float = Field(30.0, ge=0, le=1e6)
    """Paper mode: frames over which the independent share of the visual covariance is averaged
    (`backends/visual_noise_share.py`); the visual factors carry that share, the rest is added to
    the reported covariance (0 = off). Real ICSL corridor, RGB only: ARE 2.178 -> 2.143 deg against
    `single`'s 2.141 (NEES 2.90 -> 3.13); ICL kt3 0.289 unchanged; simulated walks without IMU
    1.966 / 1.920 -> 1.959 / 1.913."""
    visual_persistence_lag_frames: int = Field(10, ge=0, le=1000)
    """Paper mode: the lag (frames) at which the persistent visual error's correlation is read from the image
    rotations, to report only what of it the window's estimate still carries (`persistent_error_left.py`);
    0: all of it."""
    image_motion_visual_huber_k: float | None = Field(1.345, ge=1e-3, le=1e6)
    """Paper mode: `visual_huber_k` of a frame whose between factor comes from its image rotation
    (`smoother_image_motion.py`). Tied that tightly to its neighbours, a frame weighed as by the paper's
    0.1 (nearly every frame down-weighted) lets the chain of image rotations drift away from accurate
    frames (real ICSL corridor_more, learned normals + lines: ARE 3.81 against `single`'s 1.44); 1.345
    (the usual 95 % efficiency) follows them. None: Gaussian."""
    image_rotation_bias_initial_std_rad_s: float = Field(1e-3, ge=1e-6, le=100.0)
    """Paper mode: prior std of the image rotations' rate bias at a window's start, rad/s
    (`smoother_image_motion.py`), for a camera of known K. Real TUM fr1 rpy train, depth normals (the
    image rotations' std fitted there): 0.2 with the walk 0.1 let the window's visual priors, whose
    errors persist for seconds, turn the chain (ARE 5.60 deg); 1e-3 / 1e-4 4.55, no bias at all the
    same; eval 3.85 -> 3.79 against `single`'s 3.71. A K estimated from the scene scales every image
    rotation: `SCENE_K_IMAGE_ROTATION_BIAS`."""
    image_rotation_bias_rw_rad_s2_sqrt_hz: float = Field(1e-4, ge=1e-9, le=100.0)
    """Paper mode: random-walk density of that bias, rad/s^2/sqrt(Hz)."""
    # Gyro-aided mode: gyro noise from `GyroNoiseConfig`; the smoother's bias prior default is wider.
    gyro_bias_rw_rad_s2_sqrt_hz: float = Field(1e-4, ge=1e-9, le=1.0)
    """Gyro bias random-walk density, rad/s^2/sqrt(Hz) (> 0: a gtsam sigma)."""
    gyro_bias_initial_std_rad_s: float = Field(0.03, ge=1e-6, le=10.0)
    """Prior std of the gyro bias on the first frame, rad/s. Real EuRoC V1_01 micro (z bias 0.076), cue
    sets normals / lines / both: 0.02 gave ARE 1.01 / 0.87 / 0.63 deg against `single`'s 0.65 / 0.72 /
    1.16 (a yaw drift of the unlearnt bias), 0.03 0.80 / 0.71 / 0.63 with NEES 0.85 / 1.04 / 1.52;
    0.05 0.57 / 0.52 / 0.61 but NEES 0.62 / 0.70 / 1.37; 0.1 made the window indeterminate (23 restarts)."""
    accel_std_rad: float = Field(0.02, ge=1e-6, le=10.0)
    """Std of the gravity direction from the mean accelerometer reading when the camera is still, rad.
    Real EuRoC V1_01 micro (static drone), normals / lines / both: 0.03 gave NEES 0.85 / 1.04 / 1.52 and
    tilt 0.82 / 0.91 / 1.04 deg, 0.02 NEES 1.06 / 1.19 / 1.66 and tilt 0.77 / 0.83 / 0.93 (IMU alone 1.78)."""
    accel_inflation_rad_per_m_s2: float = Field(0.5, ge=0, le=100.0)
    """Added to `accel_std_rad` per m/s^2 of | |a_mean| - g |, and of the samples' RMS spread while the
    platform turns (`still_rate_rad_s`; still: the mean's standard error, spread / sqrt(N) / g rad)."""
    still_rate_rad_s: float = Field(STILL_RATE_RAD_S, ge=0, le=100.0)
    """Gyro mode: below this bias-corrected rate (rad/s, the EKF's `source_trust.STILL_RATE_RAD_S`) the
    platform counts as still and the accelerometer's spread as noise or vibration, which averages out of
    the mean (its standard error); above it the spread inflates the gravity factor as the platform's own
    acceleration. Real EuRoC V1_01 micro (a static drone, motors shaking it 0.2-1.8 m/s^2 RMS): weighed by
    the spread there, tilt 2.8-3.8 deg against the IMU alone's 1.78."""
    gravity_huber_k: float | None = Field(1.345, ge=1e-3, le=1e6)
    """Huber threshold on the whitened gravity residual; None for Gaussian."""
    gravity_m_s2: float = Field(9.81, ge=1.0, le=100.0)
    manhattan_vertical_std_rad: float = Field(0.02, ge=1e-6, le=10.0)
    """How far the Manhattan z axis may lean from world up (std, rad; gyro mode): the EKF's key of the same name."""
    world_yaw_std_rad: float = Field(1e-3, ge=1e-6, le=10.0)
    """Prior std fixing the world's yaw (a gauge) through `R_wm` (gyro mode), rad."""
    R_ci: list[list[float]] = Field(default_factory=lambda: np.eye(3).tolist())
    """Camera-from-IMU rotation (3x3): `gyro_c = R_ci @ gyro_i`."""
    imu_time_offset_s: float = Field(0.0, ge=-3600.0, le=3600.0)
    """Camera clock minus IMU clock: a sample stamped `t` measures the camera time `t + offset`
    (`t_cam = t_imu + imu_time_offset_s`, as `SourceInfo.imu_time_offset_s`)."""

    @field_validator("R_ci")
    @classmethod
    def _check_rotation(cls, value):
        if not is_rotation(value):
            raise ValueError("R_ci must be a 3x3 rotation matrix (orthonormal rows, det +1)")
        return value


SCENE_K_IMAGE_ROTATION_BIAS = {"image_rotation_bias_initial_std_rad_s": 0.2, "image_rotation_bias_rw_rad_s2_sqrt_hz": 0.1}
"""The paper smoother's rate-bias settings for a source whose K is estimated from the scene
(`pipeline.stages.backend_for_run`): the focal error turns the image rotations by a steady rate (with the
camera's translation, 0.39 deg per frame on real ICSL corridor_more), which the bias must follow.

Open (issue 30, real ICSL corridor_more, learned normals + lines, smoother against `single` 1.446 deg,
paired 95 %): +0.033 (+0.016 .. +0.057). The frames are precise there (per-frame part 0.2-0.6 deg) and
the image rotations err by 0.3-0.7 deg per axis, persistently about the camera's y axis while it turns
(0.23 deg per frame on average, up to 2.7), under a std of 1.3: no white std fits that. Replayed
(tools/visual_only_replay.py's cache of main 05cab9f's rotations), none of these fixes the row without
costing the others (normals / lines rows: -0.031 / -1.168 now): rate-bias walk 0.3 / 1 / 3 (from 0.1):
+0.03 (+0.01 .. +0.05) / +0.01 (+0.00 .. +0.03), lines -1.12 / +0.005 (-0.001 .. +0.011) but normals
+0.005, lines -0.99; window 10 or 60 frames: unchanged; `image_motion_visual_huber_k` 100: unchanged;
image-rotation std x2 / x4: +0.00 .. +0.02 / +0.00 .. +0.01, lines -0.98 at x4; the share of the whole
covariance (as the mekf): +0.010 (+0.004 .. +0.017), lines -1.07; that with the walk 2: +0.003 (-0.000 ..
+0.005), normals +0.003, lines -0.99.
Unbiased image rotations of the same rms (synthetic, from the reference): +0.001 (-0.015 .. +0.020)."""


class OptimiserFailure(RuntimeError):
    """The smoother's optimisation raised or returned a non-finite estimate."""


def _robust(kernel_k: float | None, base: gtsam.noiseModel.Base) -> gtsam.noiseModel.Base:
    if kernel_k is None:
        return base
    return gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(kernel_k), base)


FRAME_PART_FLOOR = 1e-3
"""The per-frame part of a visual covariance as fused is kept above this fraction of the whole's
largest eigenvalue in every direction (a steady part may take all of the covariance along an axis)."""


def _frame_part(cov: np.ndarray, steady: np.ndarray | None) -> np.ndarray:
    """`cov - steady` (rad^2), eigenvalues floored at `FRAME_PART_FLOOR` of `cov`'s largest; `cov` without."""
    if steady is None:
        return cov
    val, vec = np.linalg.eigh(0.5 * ((cov - steady) + (cov - steady).T))
    val = np.maximum(val, FRAME_PART_FLOOR * float(np.linalg.eigvalsh(cov)[-1]))
    return (vec * val) @ vec.T


def label_up_as_z(R_cm: np.ndarray, up_c: np.ndarray) -> np.ndarray:
    """The symmetric relabelling `R_cm @ P` whose Manhattan z axis is nearest `up_c` (camera frame)."""
    candidates = R_cm @ manhattan_symmetries()  # (24, 3, 3)
    # Manhattan z in the camera is column 2; among the ties, keep the one closest to R_cm itself.
    score = candidates[:, :, 2] @ up_c + 1e-6 * np.einsum("ij,gij->g", R_cm, candidates)
    return candidates[int(np.argmax(score))]


class Smoother(Backend):
    """Sliding-window factor-graph smoother over camera attitudes (see module docstring).

    `Smoother(config)` builds the variant that `config.mode` names, once: `PaperSmoother` (the
    paper's graph) or `GyroSmoother` (gyro-aided, `backends/smoother_gyro.py`); this base holds the
    window, the optimisation and the failure handling, and the variants the factors they differ in.
    Estimates carry `R_wc` (camera to world) and the smoother's marginal covariance of its right
    perturbation (rad^2); `R_wm` is the identity in paper mode and estimated in gyro mode, where
    `gyro_bias_rad_s` is the bias of the latest frame in the IMU frame (estimated in the camera frame).
    """

    def __new__(cls, config: SmootherConfig | None = None):
        variant = cls
        if cls is Smoother:
            if (config or SmootherConfig()).mode is SmootherMode.GYRO:
                from .smoother_gyro import GyroSmoother

                variant = GyroSmoother
            else:
                variant = PaperSmoother
        return super().__new__(variant)

    def __init__(self, config: SmootherConfig | None = None):
        self.config = config or SmootherConfig()
        self._R_ci = np.asarray(self.config.R_ci, dtype=float)
        self._between_noise = gtsam.noiseModel.Isotropic.Sigma(3, self.config.between_std_rad)
        self._smoother: BatchFixedLagSmoother | None = None
        self._k = -1  # index of the latest frame in the graph
        self._t_frame = float("nan")
        self._last: Estimate | None = None  # last successfully optimised estimate
        self._R_wm = np.eye(3)
        self._bias = np.zeros(3)
        self._dropped_imu = 0
        self._noise_share = VisualNoiseShare(self.config.visual_noise_share_frames
                                             if self.config.mode is SmootherMode.PAPER else 0.0, of_frame_part=True,
                                             persistence_lag_frames=self.config.visual_persistence_lag_frames)
        self.track = LabellingTrack()
        """Paper mode: the stream's labelling (`labelling_track.py`, as `single`'s), turned by the image
        rotations; gyro mode labels nearest the gyro-propagated estimate instead."""
        self._k_visual: int | None = None  # latest frame in the window with a visual rotation
        self.rejected_nonfinite = 0
        """Visual rotations with a non-finite rotation or covariance, not fused."""
        self._t_visual = float("nan")  # its time, s
        self._image_motion = ImageMotionFactors(self.config.image_rotation_bias_initial_std_rad_s,
                                                self.config.image_rotation_bias_rw_rad_s2_sqrt_hz)
        self._reset_interval()

    # ----------------------------------------------------------------------------- variant hooks
    def _reset_interval(self) -> None:
        """Start collecting the IMU of the next frame interval (nothing in the paper's graph)."""

    def _predicted_R_wc(self, visual: VisualRotation | None = None) -> np.ndarray:
        """`R_wc` (3, 3) predicted at the next frame (paper: the last estimate turned by `visual`'s image
        rotation when it has one, `R_wc = R_wc_p R_cp^T`)."""
        if visual is not None and visual.has_image_rotation():
            return self._last.R_wc @ visual.R_cp.T
        return self._last.R_wc

    def _labelled(self, t_s: float, visual: VisualRotation, R_wc_pred: np.ndarray) -> VisualRotation:
        """`visual` in the labelling the graph fuses (paper: the labelling track's, `LabellingTrack.label`)."""
        return self.track.label(t_s, visual)

    def _visual_factor(self, k: int, visual: VisualRotation, noise) -> gtsam.NonlinearFactor:
        """f^z of paper eq. 9: the single-frame rotation as a robust prior on X(k) (`noise`: `_add_visual`)."""
        return gtsam.PriorFactorRot3(X(k), gtsam.Rot3(visual.R_cm.T), noise)

    def _add_motion_factors(self, graph, values, stamps, k: int, t_s: float, visual: VisualRotation | None) -> None:
        """f^s of paper eq. 9 between the frame and the previous one: the image rotation `R_cp` since the
        latest frame with a visual rotation (`X(j)^-1 X(k) = R_cp^T`, isotropic `R_cp_std_rad`) when the
        frame has one and that frame is still in the window; else the paper's identity with `between_std_rad`."""
        j = self._k_visual
        if (visual is not None and visual.has_image_rotation() and j is not None
                and k - j < self.config.window_frames - 1):
            self._image_motion.add(graph, values, stamps, j, k, t_s - self._t_visual, t_s - self._t_frame, visual)
        else:
            graph.add(self._smoothness_factor(k))
            self._image_motion.add_walk(graph, values, stamps, k, t_s - self._t_frame)

    def _window_stamps(self, stamps, k: int) -> None:
        """Timestamps of variables kept in the window besides X(k) (none in the paper's graph)."""

    def _start_priors(self, graph, values, stamps, t_s: float, visual: VisualRotation) -> VisualRotation:
        """Priors of the first frame besides its visual factor; returns the visual rotation as labelled
        for it (the paper's: as the solver gave it, the labelling track starts there; the world is that
        Manhattan frame)."""
        self.track.start(t_s, visual)
        self._image_motion.start(graph, values, stamps, 0)
        return visual

    def _restart_priors(self, graph, values, stamps, k: int) -> None:
        """Priors a restarted window needs besides X(k) (paper: the image rotations' rate bias)."""
        self._image_motion.start(graph, values, stamps, k)

    def _world_and_bias(self, values) -> tuple[np.ndarray, np.ndarray | None]:
        """`(R_wm (3, 3), gyro bias (3,) rad/s camera frame, or None)` from the optimised values (paper:
        the image rotations' rate bias is kept, not reported)."""
        self._image_motion.take(values, self._k)
        return np.eye(3), None

    # ----------------------------------------------------------------------------- shared factors
    def _add_visual(self, graph, k: int, t_s: float, visual: VisualRotation) -> None:
        """The frame's factor, robust, with its per-frame covariance (`VisualRotation.cov_frame()`, floored:
        `_frame_part`) as one of `R_wc` times the independent share of the previous frames (paper mode;
        gyro mode: the whole covariance); then the share of the per-frame part updated with the frame
        (labelled as fused) and the persistent part, the steady one whole, reported with the estimate
        (`visual_noise_share.py`, `of_frame_part`; nothing in gyro mode). Measured against the whole
        covariance, a steady floor read as persistent error: real ICSL corridor, RGB normals+lines, NEES
        28.7 against `single`'s 3.05 (the reported covariance under the steady part), 3.44 now."""
        R_wc_cov = visual_R_wc_covariance(visual)
        fused = _frame_part(R_wc_cov, visual_R_wc_steady(visual)) if self._noise_share.enabled else R_wc_cov
        fused = self._noise_share.share * fused
        noise = gtsam.noiseModel.Gaussian.Covariance(fused)
        graph.add(self._visual_factor(k, visual, _robust(self._visual_huber_k(visual), noise)))
        if self._noise_share.enabled:
            self._noise_share.take(t_s, visual, R_wc_cov, float(np.trace(fused)))

    def _visual_huber_k(self, visual: VisualRotation) -> float | None:
        """The Huber threshold of `visual`'s factor (paper: `image_motion_visual_huber_k` when its between
        factor is its image rotation, else the paper's `visual_huber_k`)."""
        if visual.has_image_rotation():
            return self.config.image_motion_visual_huber_k
        return self.config.visual_huber_k

    def _smoothness_factor(self, k: int) -> gtsam.NonlinearFactor:
        return gtsam.BetweenFactorRot3(X(k - 1), X(k), gtsam.Rot3(), self._between_noise)

    # ----------------------------------------------------------------------------- frames
    def predicted_R_cm(self, t_s: float) -> np.ndarray | None:
        """`R_cm` (3, 3) of the latest estimate (paper: it initialises the next frame's solver); in
        gyro mode propagated by the gyro preintegrated since that frame. None before the first visual
        rotation."""
        if self._last is None:
            return None
        return self._predicted_R_wc().T @ self._R_wm

    def process_frame(self, t_s: float, visual: VisualRotation | None) -> Estimate:
        """Add frame `t_s` (its visual rotation, or None) to the window, optimise, and return the
        estimate of `R_wc` with its marginal covariance (right perturbation, rad^2). A visual rotation
        whose rotation or covariance is not finite is not fused (`Status.VISUAL_REJECTED`, counted in
        `rejected_nonfinite`); its image rotation still ties the frame to the previous one."""
        status = Status.OK if visual is not None else Status.VISUAL_MISSING
        usable = visual is not None and visual.is_finite()
        if visual is not None and not usable:
            self.rejected_nonfinite += 1
            status |= Status.VISUAL_REJECTED
        if self._dropped_imu:
            status |= Status.IMU_DROPPED
            self._dropped_imu = 0
        if self._last is None:
            if not usable:
                self._reset_interval()
                return Estimate(t_s, np.eye(3), self.config.missing_variance_rad2 * np.eye(3),
                                status | Status.NOT_INITIALISED)
            return self._start_window(t_s, visual, status)

        k = self._k + 1
        graph, values, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        R_wc_pred = self._predicted_R_wc(visual)
        try:
            if usable:
                visual = self._labelled(t_s, visual, R_wc_pred)
                self._add_visual(graph, k, t_s, visual)
            self._add_motion_factors(graph, values, stamps, k, t_s, visual)
            values.insert(X(k), gtsam.Rot3(R_wc_pred))
            stamps[X(k)] = float(k)
            self._window_stamps(stamps, k)
            self._optimise(graph, values, stamps)
            self._k, self._t_frame = k, t_s
            est = self._estimate(t_s, status)
            if visual is not None:
                self._k_visual, self._t_visual = k, t_s
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:
            log.warning("smoother optimisation failed at t=%.6f s (%s); window restarted from the last "
                        "good estimate", t_s, exc)
            est = self._restart_window(t_s, k, R_wc_pred, status | Status.OPTIMISER_FAILED)
        self._reset_interval()
        self._last = est
        return est

    def _new_smoother(self) -> BatchFixedLagSmoother:
        # Timestamps are frame indices; keys older than k - lag are marginalised, so lag = window - 1.
        return BatchFixedLagSmoother(float(self.config.window_frames - 1), gtsam.LevenbergMarquardtParams())

    def _start_window(self, t_s: float, visual: VisualRotation, status: Status) -> Estimate:
        """First visual rotation: X(0) (and M, B(0) in gyro mode) with their priors."""
        self._smoother = self._new_smoother()
        graph, values, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        visual = self._start_priors(graph, values, stamps, t_s, visual)
        self._add_visual(graph, 0, t_s, visual)
        values.insert(X(0), gtsam.Rot3(self._R_wm @ visual.R_cm.T))
        stamps[X(0)] = 0.0
        self._smoother.update(graph, values, stamps)
        self._k, self._t_frame, self._k_visual, self._t_visual = 0, t_s, 0, t_s
        est = self._estimate(t_s, status)
        self._reset_interval()
        self._last = est
        return est

    def _restart_window(self, t_s: float, k: int, R_wc_pred: np.ndarray, status: Status) -> Estimate:
        """After a failure: a fresh window holding X(k) at the last good estimate (propagated by the
        gyro in gyro mode) with its covariance; this frame's measurements are dropped."""
        last = self._last
        cov = last.cov + self.config.between_std_rad**2 * np.eye(3)
        self._smoother = self._new_smoother()
        graph, values, stamps = gtsam.NonlinearFactorGraph(), gtsam.Values(), {}
        graph.add(gtsam.PriorFactorRot3(X(k), gtsam.Rot3(R_wc_pred), gtsam.noiseModel.Gaussian.Covariance(cov)))
        values.insert(X(k), gtsam.Rot3(R_wc_pred))
        stamps[X(k)] = float(k)
        self._restart_priors(graph, values, stamps, k)
        self._k_visual = None  # the earlier frames left with the old window
        try:
            self._smoother.update(graph, values, stamps)
            self._k, self._t_frame = k, t_s
            return self._estimate(t_s, status)
        except (RuntimeError, ValueError, np.linalg.LinAlgError) as exc:  # pragma: no cover - defensive
            log.error("smoother restart failed at t=%.6f s (%s); holding the last estimate", t_s, exc)
            self._smoother, self._last = None, None
            return Estimate(t_s, R_wc_pred, cov, status | Status.NOT_INITIALISED, R_wm=self._R_wm)

    def _optimise(self, graph, values, stamps) -> None:
        self._smoother.update(graph, values, stamps)

    def _estimate(self, t_s: float, status: Status) -> Estimate:
        """Latest frame's `R_wc` and its marginal covariance (right perturbation, rad^2)."""
        values = self._smoother.calculateEstimate()
        R_wc = values.atRot3(X(self._k)).matrix()
        cov = gtsam.Marginals(self._smoother.getFactors(), values).marginalCovariance(X(self._k))
        R_wm, bias = self._world_and_bias(values)
        if not (np.all(np.isfinite(R_wc)) and np.all(np.isfinite(cov)) and np.all(np.isfinite(R_wm))):
            raise OptimiserFailure("non-finite estimate")
        self._R_wm = R_wm
        if bias is not None:
            self._bias = bias
        cov = 0.5 * (cov + cov.T)
        return Estimate(t_s, R_wc, cov + self._noise_share.settle(cov), status, R_wm=R_wm.copy(),
                        gyro_bias_rad_s=None if bias is None else self._R_ci.T @ bias)


class PaperSmoother(Smoother):
    """The paper's graph (Sec. 3.2): visual priors and smoothness factors (from the image rotations when
    the frames carry them); IMU ignored."""

    name = "smoother"
    uses_image_motion = True  # the labelling track and the between factors
