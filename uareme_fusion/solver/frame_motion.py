"""The camera's rotation between consecutive frames of a stream, from the image motion (a visual gyro).

Corners of the previous frame (OpenCV `goodFeaturesToTrack`) are tracked into the next (pyramidal
Lucas-Kanade), at `FrameMotionConfig.width_px`; the tracks that fit one essential matrix (RANSAC,
`findEssentialMat`) give the rotation as the closest rotation taking their bearings in the previous
camera to those in the next (Kabsch, a rotation-only fit: a handheld camera moves little between frames
against the depth it sees, and the essential matrix's own rotation is unstable when it barely moves: on
real TUM fr1 rpy, 180 deg off on over a tenth of the frames). Real TUM fr1 rpy training frames (the first
200; handheld, up to 175 deg/s): error 0.35 deg mean, 0.71 p95, 1.32 at most against the mocap (whose own
clock is 25-35 ms off; frame steps 2 deg mean); all 515 steps, with the translation test below: 0.45 deg mean.

A camera walked past near walls (real ICSL corridor_more, turning a corner a metre from a wall) sees the
translation's parallax as large as the rotation's flow, and the rotation-only fit takes part of the turn
for it: over the corner's 90 deg (frames 161..221, the depth reference) it measured 50 (drift over 30
frames 12.1 deg mean against that reference). Then the rotation-only fit leaves residuals the essential
matrix explains: when their rms exceeds `translation_residual_ratio` times the tracks' distances to their
epipolar planes and the essential matrix's rotation (`recoverPose`) lies within
`translation_max_offset_residuals` rms residuals of the rotation-only one (not one of its degenerate
flips), that rotation is taken: ICSL corridor_more drift over 30 frames 12.1 -> 4.4 deg (the corner 83
deg; taken on 86 % of its frames), TUM fr1 rpy train 3.8 -> 3.6 against the mocap (taken on 17 %).

Used by the stream's Manhattan labelling (`backends/labelling_track.py`: a run of wrong frames can walk
the labelling only as far as the image says the camera turned), the visual-only EKF's prediction
(`backends/mekf/image_rotation_motion.py`) and the smoother's between-frame factors.

Convention: `R_cp` maps the previous frame's camera coordinates (p) to this frame's (c): a direction
`d_p` seen before is `R_cp @ d_p` now, and `R_cm = R_cp @ R_pm`. Its std (rad, per axis) is of the left
perturbation `R_cp_true = Exp(eps) R_cp`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.spatial.transform import Rotation


@dataclass(frozen=True)
class FrameMotionConfig:
    """Parameters of `FrameMotion` (units in the names)."""

    width_px: int = 240
    """Images are tracked at this width (the aspect kept). On TUM (640x480) 240 px and 150 corners cost
    5.1 ms of CPU per frame for the accuracy of 320 px and 300 corners (7.3 ms)."""
    max_corners: int = 150
    min_inliers: int = 30
    """Fewer tracks fitting one motion than this (a blank, black or blurred frame): no rotation."""
    ransac_threshold_px: float = 1.0
    """At `width_px`."""
    std_base_rad: float = float(np.radians(0.13))
    """The rotation's std per axis is `std_base_rad + std_per_step * |step| + std_per_residual * rms`, with
    `|step|` the rotation's angle (rad) and `rms` the rms angle (rad) between the tracks' bearings and the
    rotated previous ones (what the rotation does not explain: translation, rolling shutter, tracking
    noise). Fitted by maximum likelihood on the real TUM fr1 rpy training frames against the mocap (NEES
    per axis 0.99 there; real ICSL corridor_more against its depth reference 0.81): 0.13 deg ..."""
    std_per_step: float = 0.03
    """... plus 3 % of the step (dimensionless) ..."""
    std_per_residual: float = 0.48
    """... plus 0.48 times the rms residual (dimensionless); times `scene_K_std_scale` at a K from the scene."""
    scene_K_std_scale: float = 3.0
    """The std's factor (dimensionless) when the frames' K was estimated from the scene (`step(..., K_from_scene=
    True)`): the focal length a few per cent off (real ICSL corridor_more 578.5 px against 537.6), the principal
    point assumed at the centre, and the image rotations' errors then share a bias that a chain of them adds up
    (real ICSL corridor_more against its depth reference: NEES per axis 0.96 per frame, 2.0 chained over 10 frames,
    2.9 over 30). The visual-only EKF propagated by them, its paired ARE against `single` (95 % interval), ICSL
    corridor_more, RGB normals+lines / RGB normals: factor 1 +0.06 (+0.01 .. +0.11) / -0.25 (-0.46 .. -0.01),
    1.7 (sqrt 2.9) +0.02 (+0.00 .. +0.05) / -0.15, 2 +0.02 (-0.00 .. +0.04) / -0.12, 3 +0.01 (-0.00 .. +0.02) /
    -0.08 (-0.13 .. -0.01); ICSL corridor, 3: +0.00 (-0.00 .. +0.00) / -0.02 (-0.03 .. -0.01)."""
    translation_residual_ratio: float = 3.0
    """The essential matrix's rotation replaces the rotation-only fit when the fit's rms residual exceeds
    this many times the tracks' rms distance (angle) to their epipolar planes (module docstring) ..."""
    translation_max_offset_residuals: float = 3.0
    """... and the two rotations differ by less than this many of the fit's rms residuals."""
    max_gap_s: float = 0.5
    """Frames further apart than this are not tracked across (a stream that stopped)."""


@dataclass(frozen=True)
class FrameStep:
    """The rotation from the previous frame's camera to this one's (`R_cp`) and its std per axis (rad)."""

    R_cp: np.ndarray
    std_rad: float
    inliers: int


class FrameMotion:
    """`step(t_s, rgb, K, K_from_scene) -> FrameStep | None` for each frame of a stream in order (None for the first
    frame, after a gap, a change of size or intrinsics, or when the images do not tell)."""

    def __init__(self, config: FrameMotionConfig | None = None):
        self.config = config or FrameMotionConfig()
        self._previous: tuple[float, np.ndarray, np.ndarray] | None = None
        """(t_s, grey image at the tracking width, its K) of the previous frame."""

    def step(self, t_s: float, rgb: np.ndarray | None, K: np.ndarray | None,
             K_from_scene: bool = False) -> FrameStep | None:
        """`K_from_scene`: `K` was estimated from the images, not given (the std's `scene_K_std_scale`)."""
        if rgb is None or K is None:
            self._previous = None
            return None
        grey, K_small = self._small(rgb, np.asarray(K, float))
        previous, self._previous = self._previous, (t_s, grey, K_small)
        if (previous is None or not 0.0 < t_s - previous[0] <= self.config.max_gap_s
                or previous[1].shape != grey.shape or not np.allclose(previous[2], K_small)):
            return None
        step = self._rotation(previous[1], grey, K_small)
        if step is None or not K_from_scene:
            return step
        return dataclasses.replace(step, std_rad=step.std_rad * self.config.scene_K_std_scale)

    def _small(self, rgb: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        grey = rgb if rgb.ndim == 2 else cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
        scale = min(1.0, self.config.width_px / grey.shape[1])
        if scale < 1.0:
            grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        K_small = K.copy()
        K_small[:2] *= scale
        return grey, K_small

    def _rotation(self, before: np.ndarray, after: np.ndarray, K: np.ndarray) -> FrameStep | None:
        cfg = self.config
        corners = cv2.goodFeaturesToTrack(before, cfg.max_corners, 0.01, 7)
        if corners is None or len(corners) < cfg.min_inliers:
            return None
        tracked, found, _ = cv2.calcOpticalFlowPyrLK(before, after, corners, None, winSize=(21, 21), maxLevel=3)
        found = found[:, 0] == 1
        a, b = corners[found, 0].astype(np.float64), tracked[found, 0].astype(np.float64)
        if len(a) < cfg.min_inliers:
            return None
        try:
            E, mask = cv2.findEssentialMat(a, b, K, cv2.RANSAC, 0.999, cfg.ransac_threshold_px)
            inliers = mask[:, 0].astype(bool) if E is not None and mask is not None else np.zeros(len(a), bool)
        except cv2.error:  # degenerate tracks (a camera at rest, noiseless ones): OpenCV's solver refuses them
            E, inliers = None, np.ones(len(a), bool)  # the rotation-only fit on every track, no translation
        if inliers.sum() < cfg.min_inliers:
            return None
        K_inv = np.linalg.inv(K)
        bearing_p, bearing_c = (_bearings(p[inliers], K_inv) for p in (a, b))
        U, _, Vt = np.linalg.svd(bearing_c.T @ bearing_p)  # Kabsch: R_cp minimising sum |c - R_cp p|^2
        R_cp = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        rms = float(np.sqrt(np.mean(np.linalg.norm(bearing_c - bearing_p @ R_cp.T, axis=1) ** 2)))
        if E is not None:
            R_cp = self._with_translation(R_cp, rms, E[:3], a[inliers], b[inliers], K, bearing_p, bearing_c)
        std = cfg.std_base_rad + cfg.std_per_step * float(Rotation.from_matrix(R_cp).magnitude()) + cfg.std_per_residual * rms
        return FrameStep(R_cp, std, int(inliers.sum()))

    def _with_translation(self, R_cp: np.ndarray, rms: float, E: np.ndarray, a: np.ndarray, b: np.ndarray,
                          K: np.ndarray, bearing_p: np.ndarray, bearing_c: np.ndarray) -> np.ndarray:
        """The essential matrix's rotation in place of the rotation-only `R_cp` (rms residual `rms`, rad)
        when the tracks (pixels `a` -> `b`, bearings) show a translation (module docstring), else `R_cp`."""
        cfg = self.config
        _, R_e, t, _ = cv2.recoverPose(E, a, b, K)
        normals = np.cross(t[:, 0], bearing_p @ R_e.T)  # of the epipolar planes, in this camera
        length = np.linalg.norm(normals, axis=1)
        if not np.all(length > 0):
            return R_cp
        epipolar_rms = float(np.sqrt(np.mean((np.sum(bearing_c * normals, axis=1) / length) ** 2)))
        offset = float(Rotation.from_matrix(R_e @ R_cp.T).magnitude())
        if rms > cfg.translation_residual_ratio * epipolar_rms and offset < cfg.translation_max_offset_residuals * rms:
            return R_e
        return R_cp


def _bearings(points_px: np.ndarray, K_inv: np.ndarray) -> np.ndarray:
    rays = np.c_[points_px, np.ones(len(points_px))] @ K_inv.T
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)
