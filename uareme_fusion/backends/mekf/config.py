"""`MekfConfig`: noise model, robustness and input settings of `Mekf` (SI units, radians).

Presets are YAML files in `uareme_fusion/configs/` (`load_config("vehicle", MekfConfig)`).
"""

from __future__ import annotations

import enum
from typing import ClassVar

import numpy as np
from pydantic import ConfigDict, Field, field_validator

from ...rotations import is_rotation
from ..imu_noise import GyroNoiseConfig


class MekfMode(str, enum.Enum):
    """Which inputs the filter uses. `auto`: visual + IMU when IMU samples arrived before the first
    frame, else visual only."""

    AUTO = "auto"
    VISUAL_IMU = "visual_imu"
    IMU_ONLY = "imu_only"
    VISUAL_ONLY = "visual_only"


class GyroSampling(str, enum.Enum):
    """What a gyro sample stamped t_k measures: the rate at t_k (`instant`, integrated with the
    trapezoid rule) or the mean rate over (t_{k-1}, t_k] (`interval`, as many IMUs output)."""

    INSTANT = "instant"
    INTERVAL = "interval"


class MekfConfig(GyroNoiseConfig):
    """Noise model and robustness settings of `Mekf`; SI units and radians, unit in every name. The
    gyro noise fields (`gyro_noise_rad_s_sqrt_hz`, `gyro_bias_rw_rad_s2_sqrt_hz`,
    `gyro_bias_initial_std_rad_s`) come from `GyroNoiseConfig`, shared with the smoother."""

    model_config = ConfigDict(extra="forbid")
    renamed_keys: ClassVar[dict[str, str]] = {
        "manhattan_yaw_rw_rad_sqrt_s": "manhattan_yaw_rw_rad_per_sqrt_s",
        "manhattan_tilt_rw_rad_sqrt_s": "manhattan_tilt_rw_rad_per_sqrt_s",
        "visual_huber_sigma": "visual_huber_k",
        "image_rotation_error_correlation_s": "image_rotation_visual_bias_correlation_s",
        "image_rotation_error_persistence_lag_frames": "image_rotation_visual_bias_std_rad",
        "image_rotation_error_persistence_frames": "image_rotation_visual_bias_correlation_s",
        "image_rotation_error_persistence_max_s": "image_rotation_visual_bias_correlation_s",
    }
    """Old key -> new key: an old key in a configuration file is an error naming the new one."""

    mode: MekfMode = MekfMode.AUTO
    gyro_rate_noise_sqrt_s: float = Field(0.0, ge=0, le=1.0)
    """Relative gyro error (scale factor, axis misalignment, timing) as a white-noise density, sqrt(s):
    the attitude variance grows by `(this * |omega|)^2` per second of rotation at `|omega|` (0 = off),
    so the filter leans on the accelerometer more while the camera turns fast."""
    gyro_sampling: GyroSampling = GyroSampling.INSTANT
    gyro_range_rad_s: float = Field(34.9, ge=0.1, le=1000.0)
    """Gyro full scale, rad/s (34.9 = 2000 deg/s); readings at or beyond it are flagged."""
    unknown_rate_std_rad_s: float = Field(2.0, ge=1e-3, le=100.0)
    """Angular-rate uncertainty assumed over IMU gaps and saturated samples, rad/s: the attitude
    variance grows by (this * duration)^2 instead of integrating garbage."""
    imu_gap_limit_s: float = Field(0.1, ge=1e-4, le=60.0)
    """A step between IMU samples (or to a frame) longer than this is a gap, s."""
    reorder_window_s: float = Field(0.02, ge=0, le=10.0)
    """IMU samples arriving out of order by less than this are put back in place, s."""
    accel_tilt_noise_rad_sqrt_s: float = Field(0.02, ge=1e-6, le=10.0)
    """Accelerometer direction noise density, rad*sqrt(s): one update over T seconds of averaged
    samples has std `this / sqrt(T)` per tilt axis before inflation."""
    accel_update_period_s: float = Field(0.04, ge=1e-4, le=10.0)
    """Accelerometer samples are averaged (in a common camera frame) over this long per update, s."""
    accel_lowpass_tau_s: float = Field(0.0, ge=0, le=600.0)
    """Time constant of each of two cascaded first-order low-pass stages (second-order roll-off)
    applied to the accelerometer in an almost-inertial frame (the camera frame carried along by the
    gyro), s; 0 = off (each update uses only its own period's mean). Translational accelerations
    average out over it (velocity stays bounded), so seconds suit handheld IMU-only use; each update
    then measures the filtered direction."""
    accel_norm_scale: float = Field(0.05, ge=1e-4, le=100.0)
    """Relative deviation of |mean a| from gravity (dimensionless) at which the update's variance
    doubles: variance factor `1 + (dev / this)^2`."""
    accel_innovation_scale_rad: float = Field(0.05, ge=1e-4, le=10.0)
    """Angle between measured and predicted up at which the update's variance doubles, rad:
    variance factor `1 + (angle / this)^2` (continuous, no timeouts)."""
    accel_downweight_flag_ratio: float = Field(2.0, gt=1, le=1e6)
    """ACCEL_DOWNWEIGHTED is set when the inflated std exceeds this many times the nominal one."""
    accel_only_window_s: float = Field(0.2, ge=1e-3, le=10.0)
    """An accelerometer without gyro (visual-only model, `gravity_only.py`): each frame averages its
    samples over this window (handheld shaking averages out), turned to the frame's time with the
    model's rate, s. Tuned on the TUM fr1 rpy training frames (mekf, depth normals: tilt 2.96 deg
    without, 1.86 with; learned normals 7.09 -> 1.85; a 0.1 s window ending at the frame: 2.52), before the
    handheld noise density and the visual bias beside the accelerometer (`accel_only_noise_rad_sqrt_s`)."""
    accel_only_lookahead_s: float = Field(0.1, ge=0, le=10.0)
    """...the window ends this long after the frame: a run feeds the samples that far ahead (a replay
    of a recording; live, the estimate would wait this long), s. 0: the window ends at the frame."""
    accel_only_turn_samples: bool = True
    """...turn each sample to the frame's time with the model's rate (the rate error enters H)."""
    accel_only_noise_rad_sqrt_s: float = Field(0.015, ge=1e-6, le=10.0)
    """...its direction noise density, rad*sqrt(s): std `this / sqrt(window)` per tilt axis before
    inflation (and times `sqrt(window / frame step)` for the overlap of successive windows). A handheld
    camera's accelerometer reads its accelerations as well as gravity: the Kinect's 0.2 s mean direction
    errs 2.7 deg on the real TUM fr1 rpy training frames with the true rotation known (3.9 on the
    evaluation frames), not the 0.13 deg of a still sensor's 0.001 (pass that for one). Tuned on the
    training frames (mekf with the visual bias, tilt after the alignment; without the accelerometer depth
    normals 1.91 deg, learned 3.53): 0.001 2.52 / 2.53 deg (NEES 93 / 91), 0.0075 1.63 / 1.69 (NEES 7.6 /
    4.5), 0.01 1.53 / 1.64 (6.3 / 3.4), 0.015 1.48 / 1.74 (5.5 / 2.8), 0.02 1.50 / 1.95 (5.2 / 2.8)."""
    accel_only_innovation_scale_rad: float = Field(0.3, ge=1e-4, le=10.0)
    """...angle between measured and predicted up at which its variance doubles, rad (without a gyro
    the prediction is the camera's, which errs more than a gyro-carried one)."""
    accel_only_shake_m_s2: float = Field(3.0, gt=0, le=100.0)
    """...rms deviation of the window's samples from their mean at which its variance doubles, m/s^2
    (a shaking camera: variance factor `1 + (rms / this)^2`)."""
    accel_range_m_s2: float = Field(156.9, gt=1.0, le=10000.0)
    """Accelerometer full scale per axis, m/s^2 (156.9 = 16 g): a window holding a sample at or beyond
    it gives no gravity update (accelerometer without gyro)."""
    rest_gyro_max_rad_s: float = Field(0.0, ge=0, le=10.0)
    """Rest detection for the zero-rate bias update (0 = off): an accelerometer-update period is at
    rest when its mean gyro reading and the rms deviation of its gyro samples from that mean are both
    below this, rad/s (vqf uses 2 deg/s = 0.035)."""
    rest_accel_max_m_s2: float = Field(0.5, gt=0, le=100.0)
    """...and the rms deviation of its accelerometer samples from their mean is below this, m/s^2."""
    rest_min_duration_s: float = Field(1.5, ge=0, le=3600.0)
    """Rest must have lasted this long before the mean gyro reading measures the bias, s."""
    rest_rate_std_rad_s: float = Field(5e-4, ge=1e-9, le=10.0)
    """Residual angular rate allowed at rest (micro-motion), added to the gyro white noise of the
    period's mean in the zero-rate update's std, rad/s."""
    initial_tilt_std_rad: float = Field(0.03, ge=1e-6, le=10.0)
    """Tilt std after initialisation from the first accelerometer samples, rad."""
    init_accel_window_s: float = Field(0.05, ge=1e-4, le=60.0)
    """Accelerometer samples averaged for the initial tilt, s."""
    manhattan_yaw_rw_rad_per_sqrt_s: float = Field(0.0, ge=0, le=10.0)
    """Random walk of the Manhattan frame's yaw about world up, rad/sqrt(s) (0 in a building; a
    vehicle's turns need about 0.5)."""
    manhattan_tilt_rw_rad_per_sqrt_s: float = Field(0.0, ge=0, le=10.0)
    """Random walk of the Manhattan frame's tilt, rad/sqrt(s) (vehicle body sway)."""
    manhattan_vertical_std_rad: float = Field(0.02, ge=1e-6, le=10.0)
    """How far the Manhattan z axis may lean from world up (std, rad): a pseudo-measurement applied
    with each visual update ("walls are vertical"); skipped when m's z is far from up."""
    manhattan_vertical_max_rad: float = Field(0.35, gt=0, le=3.15)
    """The vertical pseudo-measurement is skipped when m's z is farther than this from up, rad."""
    rate_rw_rad_s2_sqrt_hz: float = Field(3.0, ge=1e-6, le=1000.0)
    """Visual-only constant-rate model: angular-rate random walk, rad/s^2/sqrt(Hz)."""
    rate_initial_std_rad_s: float = Field(1.0, ge=1e-6, le=100.0)
    """Visual-only: prior std of the angular rate, rad/s."""
    visual_only_image_rotation: bool = True
    """Visual only: a frame carrying the image rotation since the previous frame (`VisualRotation.R_cp`,
    `solver/frame_motion.py`) is predicted by it, its std the process noise (a visual gyro:
    `image_rotation_motion.py`); others by the constant-rate model. False: the constant-rate model always."""
    image_rotation_visual_bias_std_rad: float = Field(0.05, ge=0.0, le=1.0)
    """Visual only, a frame predicted by its image rotation: the frames' persistent error as a state, a
    Gauss-Markov rotation of this steady std per axis (rad) in the Manhattan frame's error block, which the
    visual residual sees (`image_rotation_motion.visual_bias_predict`); each frame is then fused with its
    whole covariance (0: off, the Manhattan frame fixed and only the frame's independent share fused,
    `visual_noise_share_frames`). Networks' normals err more and longer
    (`pipeline.stages.LEARNED_NORMALS_VISUAL_BIAS`); with an accelerometer without gyro too, its tilt then the
    accelerometer's and the image rotations' (`ImageRotationMotion.bias_on`).
    Real TUM fr1 rpy, depth normals+lines, no IMU (replay of the branch, before the steady part of nees14):
    train ARE 4.94 -> 4.08 deg (NEES 2.73 -> 4.04), eval 3.78 -> 3.51 (single 3.71; NEES 1.42 -> 2.98); ICL kt3
    depth 0.11 -> 0.12 (NEES 1.72 -> 1.53). `bench realdata` on main since: TUM eval depth 3.51, NEES 4.46."""
    image_rotation_visual_bias_correlation_s: float = Field(3.0, gt=0.0, le=600.0)
    """The visual bias's correlation time, s (`image_rotation_visual_bias_std_rad`)."""
    image_rotation_visual_bias_max_share: float = Field(0.25, gt=0.0, le=1e6)
    """The visual bias's variance is at most this share of each frame's own (`tr(cov) / 3`), dimensionless:
    a frame as precise as ICL kt3's (0.1 deg) cannot err by a 3 deg bias. Real kt3, mekf NEES at 0.5 / 0.25
    / 0.1: RGB normals+lines 0.75 / 1.02 / 1.30, depth 1.23 / 1.53 / 1.80; TUM train depth 2.91 / 4.04 / 6.11."""
    visual_error_correlation_s: float = Field(0.0, ge=0, le=600.0)
    """How long a visual rotation's error persists, s: a network (or a scene's lines) seen again
    errs the same way, so frames closer than this are not independent. An update `dt` s after the
    previous visual one counts as `dt / this` of an independent measurement: its covariance is
    multiplied by `max(1, this / dt)` (0 = frames independent). Off in the presets: on the rendered
    bus (learned normals, 30 fps) 0.3 s helps the handheld preset (tilt p95 1.21 -> 0.44 deg) and a
    network biased by 3 deg (3.03 -> 0.73, vehicle), but costs where the network is unbiased (other
    seeds, normals only: 1.29 -> 2.45, 0.53 -> 2.68)."""
    gyro_bias_visual_correlation_s: float = Field(0.0, ge=0, le=600.0)
    """With an IMU: how long a visual rotation's error persists as the gyro bias sees it, s. A frame
    `dt` s after the previous visual one moves the bias by `min(1, dt / this)` of the gain its rotation
    rows have, the attitude by all of it; the rows stacked with it (vertical, a due accelerometer period)
    keep theirs (a partial update: the Joseph form keeps the covariance that of the gain used; 0 = the
    Kalman gain). Frames of the same scene err the same way for a while; taken as independent, a handheld
    camera's first second of frames taught the bias their drift: the rendered demo room (SYNTHETIC, learned
    normals, 15 fps) learned -5.8 deg/s on y (true 0) and turned it into tilt over the frames without image
    evidence. Handheld preset 0.3 s (`bench realdata`, `uareme-fusion demo`): real EuRoC V1_01 micro (mekf
    with its IMU, learned normals+lines) ARE 0.80 -> 0.70 deg (single 0.81, -0.11 [-0.18, -0.02]), tilt 0.71
    -> 0.65, NEES 1.70 -> 1.27; lines only 0.79 -> 0.93 (single 0.72, +0.21 [-0.07, +0.50]); demo room tilt
    2.79 -> 1.43, ARE 10.6 -> 2.45 (vision alone 1.17 / 1.97, IMU alone 3.04 / 4.16); simulated handheld walks
    with independent frame errors (`bench mekf`) ARE 0.19 -> 0.36 (single 1.57), NEES 2.93 -> 3.31. 0.5 / 1.0
    s: EuRoC 0.67 / 0.65, room 1.55 / 1.68. The bias's gain on every stacked row: EuRoC 0.72, tilt 0.79, room
    1.24. The correlation on the whole visual covariance instead (`visual_error_correlation_s` 0.5): EuRoC 0.69,
    room 1.56, but lines only 1.66 (the frames over-state their covariance, NEES 0.04, and the yaw waited on the
    bias) and, without an IMU, ICSL corridor 0.32 -> 0.39."""
    visual_noise_share_frames: float = Field(30.0, ge=0, le=1e6)
    """Visual-only mode: frames over which the independent share of the visual covariance is
    averaged (`backends/visual_noise_share.py`); only that share is fused, the rest is added to the
    reported covariance (0 = off: every frame's error independent). Real ICSL corridor, RGB only:
    ARE 2.176 -> 2.149 deg against `single`'s 2.141 (NEES 4.55 -> 3.19); ICL kt3 0.282 -> 0.284 (single
    0.289); simulated walks without IMU 2.123 / 2.043 -> 2.124 / 2.048."""
    visual_trust_frames: float = Field(30.0, ge=0, le=1e6)
    """With an IMU: frames over which the camera's vertical is matched against a quiet accelerometer's
    while the camera is still (`source_trust.py`): a camera whose vertical keeps erring the same way
    has the vertical pseudo-measurement loosened and only the independent share of its tilt covariance
    fused (0 = off); the share is learned over `frames` blocks of 10 still frames. Real EuRoC V1_01 micro
    (static drone, learned normals, `eval`, handheld preset): tilt 1.39 -> 0.85 deg, NEES 25.9 -> 4.6
    (IMU alone on the same frames 1.78) with the blocks and the preset's gyro-bias prior; simulated bus
    seed 0 p95 0.49 -> 0.50, max 0.94 -> 0.71. The share on the yaw too cost the yaw (`bench realdata`,
    EuRoC RGB normals, mekf: ARE 0.89 against `single`'s 0.65; tilt only 0.62, tilt 0.73 either way)."""
    visual_trust_min_share: float = Field(0.05, gt=0, le=1.0)
    """Floor of the independent share of the visual covariance that is fused (dimensionless)."""
    visual_gate_chi2: float = Field(16.27, gt=0, le=1e6)
    """Mahalanobis gate on the 3-dof visual residual (16.27 = chi-square 99.9 %)."""
    visual_huber_k: float = Field(2.0, ge=1e-3, le=1e6)
    """Huber threshold k on the Mahalanobis distance d of the visual residual (dimensionless; the
    smoother's key of the same name and meaning): beyond it the visual covariance is scaled by d/k (the
    Huber weight k/d)."""
    reinit_after_rejections: int = Field(8, ge=1, le=1000000)
    """Consecutive gated-out frames after which the Manhattan frame is re-initialised."""
    reinit_after_disagreement_s: float = Field(1.0, ge=0.0, le=3600.0)
    """Seconds (camera clock) of frames in a row whose visual rotation disagrees with the prediction
    (`disagreement_chi2`: rejected, or accepted only with a small Huber weight) after which the filter
    re-initialises from the frame's rotation. Each such frame carries `Status.VISUAL_IGNORED`, so no
    estimate drifts away from the camera while every flag is clear."""
    visual_only_reinit_after_s: float = Field(0.0, ge=0.0, le=3600.0)
    """With the constant-rate model (no IMU, no image rotation: `visual_only_image_rotation`; the image
    rotation, a measured motion, takes `reinit_after_disagreement_s`),
    `reinit_after_disagreement_s` (s; a gated-out frame disagrees too): the camera is
    the only evidence, and while the filter ignores it it coasts on a rate that may be the wrong one, so
    it re-initialises as soon as two disagreeing frames agree with each other (0). Real ICSL
    corridor_more, lines only, against single's 3.30 deg: 0.1 s 4.17, 0.05 s 3.64, 0 3.17 (2.77 without
    the two-frame agreement, which a simulated walk with wrong minima needs); kt3, ICSL, EuRoC (no IMU)
    unchanged."""
    disagreement_chi2: float = Field(25.0, gt=0.0, le=1e12)
    """A frame disagrees when the Mahalanobis d^2 of predicted against visual `R_cm` (after the
    24-fold symmetry), with the prediction's and the visual covariance (no correlation or
    share scaling), exceeds this (3 dof; 25: p ~ 1.7e-5) ..."""
    disagreement_min_deg: float = Field(2.0, ge=0.0, le=180.0)
    """... and the angle between them exceeds this, deg (an over-confident visual covariance alone
    does not make a small difference a disagreement)."""
    R_ci: list[list[float]] = Field(default_factory=lambda: np.eye(3).tolist())
    """Camera-from-IMU rotation (`v_c = R_ci v_i`), 3x3 row-major."""
    imu_time_offset_s: float = Field(0.0, ge=-3600.0, le=3600.0)
    """Camera clock minus IMU clock, s: `t_cam = t_imu + imu_time_offset_s` (as `SourceInfo`)."""
    gravity_m_s2: float = Field(9.81, ge=1.0, le=100.0)
    """Magnitude of gravity, m/s^2."""
    record_imu_estimates: bool = False
    """Keep `R_wc` after every IMU sample (see `Mekf.imu_trajectory`)."""

    @field_validator("R_ci")
    @classmethod
    def _rotation(cls, value):
        if not is_rotation(value):
            raise ValueError(f"must be a 3x3 rotation matrix, got {value}")
        return value

