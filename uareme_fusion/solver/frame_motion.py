"""The camera's rotation between consecutive frames of a stream, from the image motion (a visual gyro).

Corners of the previous frame (OpenCV `goodFeaturesToTrack`) are tracked into the next (pyramidal
Lucas-Kanade), at `FrameMotionConfig.width_px`; the tracks that fit one essential matrix (RANSAC,
`findEssentialMat`) give the rotation as the closest rotation taking their bearings in the previous
camera to those in the next (Kabsch, a rotation-only fit: a handheld or vehicle camera moves little between
frames against the depth it sees, and the essential matrix's own rotation is unstable when it barely
moves). Real TUM fr1 rpy training frames (the first 200; handheld, up to 175 deg/s): error 0.35 deg mean,
0.71 p95, 1.32 at most against the mocap (whose own clock is 25-35 ms off; frame steps 2 deg mean).

Used by the stream's Manhattan labelling (`backends/labelling_track.py`): a run of wrong frames can walk
the labelling only as far as the image says the camera turned.

Convention: `R_cp` maps the previous frame's camera coordinates (p) to this frame's (c): a direction
`d_p` seen before is `R_cp @ d_p` now, and `R_cm = R_cp @ R_pm`. Its std (rad, per axis) is of the left
perturbation `R_cp_true = Exp(eps) R_cp`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


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
    min_std_rad: float = float(np.radians(0.5))
    """Floor on the rotation's std per axis (the fit's own statistics ignore the camera's translation and
    the rolling shutter): 0.5 deg, above the 0.31 deg mean error measured on TUM."""
    max_gap_s: float = 0.5
    """Frames further apart than this are not tracked across (a stream that stopped)."""


@dataclass(frozen=True)
class FrameStep:
    """The rotation from the previous frame's camera to this one's (`R_cp`) and its std per axis (rad)."""

    R_cp: np.ndarray
    std_rad: float
    inliers: int


class FrameMotion:
    """`step(t_s, rgb, K) -> FrameStep | None` for each frame of a stream in order (None for the first
    frame, after a gap, a change of size or intrinsics, or when the images do not tell)."""

    def __init__(self, config: FrameMotionConfig | None = None):
        self.config = config or FrameMotionConfig()
        self._previous: tuple[float, np.ndarray, np.ndarray] | None = None
        """(t_s, grey image at the tracking width, its K) of the previous frame."""

    def step(self, t_s: float, rgb: np.ndarray | None, K: np.ndarray | None) -> FrameStep | None:
        if rgb is None or K is None:
            self._previous = None
            return None
        grey, K_small = self._small(rgb, np.asarray(K, float))
        previous, self._previous = self._previous, (t_s, grey, K_small)
        if (previous is None or not 0.0 < t_s - previous[0] <= self.config.max_gap_s
                or previous[1].shape != grey.shape or not np.allclose(previous[2], K_small)):
            return None
        return self._rotation(previous[1], grey, K_small)

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
        E, mask = cv2.findEssentialMat(a, b, K, cv2.RANSAC, 0.999, cfg.ransac_threshold_px)
        inliers = mask[:, 0].astype(bool) if E is not None and mask is not None else np.zeros(len(a), bool)
        if inliers.sum() < cfg.min_inliers:
            return None
        K_inv = np.linalg.inv(K)
        bearing_p, bearing_c = (_bearings(p[inliers], K_inv) for p in (a, b))
        U, _, Vt = np.linalg.svd(bearing_c.T @ bearing_p)  # Kabsch: R_cp minimising sum |c - R_cp p|^2
        R_cp = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        residual = np.linalg.norm(bearing_c - bearing_p @ R_cp.T, axis=1)
        std = max(cfg.min_std_rad, float(np.sqrt(np.mean(residual ** 2) / len(residual))))
        return FrameStep(R_cp, std, int(inliers.sum()))


def _bearings(points_px: np.ndarray, K_inv: np.ndarray) -> np.ndarray:
    rays = np.c_[points_px, np.ones(len(points_px))] @ K_inv.T
    return rays / np.linalg.norm(rays, axis=1, keepdims=True)
