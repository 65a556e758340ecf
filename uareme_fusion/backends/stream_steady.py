"""How much a stream's visual rotations vary about what they share, seen through the image motion.

A frame's visual covariance says how far its rotation may be from the truth. Much of that error is the
view's own (the network's normals of one scene, its segments), and frames that see the same scene share
it: the real EuRoC V1_01 micro drone stands still, its learned-normal rotations are 5 deg off in tilt with
a std of 9.9 deg per axis, and yet after one constant alignment they err by 0.65 deg. What is shared is
no error a constant alignment leaves; what varies is. The variation is observable without a reference:
the image rotation between frames (`VisualRotation.R_cp`, from tracked features, independent of the
Manhattan labelling and of the solver's errors) carries each earlier rotation to the current frame, and
what the carried rotations and the frame's own disagree by is the change of their errors (plus the
image motion's own error, which can only make the variation look larger).

    X_k = R_mc_k P_k^T,  P_k = R_cp_1^T ... R_cp_k^T      (constant over the stream if the errors were)
    v = max(mean over all pairs j < k of |Log(X_j^T X_k)|^2, the newest frame's against the older half) / 6

(rad^2 per axis: |e_k - e_j|^2 has the mean 2 * 3 v for errors of per-axis variance v about their shared
part; `StreamVariation`). A frame's steady share is what the frames before it do not show varying,
`steady_share`: C - v I within C (`types.steady_within`), once `MIN_PAIRS` pairs are seen; before that,
and where the stream has no image rotations, nothing is said (None). An error fixed in the camera turns
with it in the world, where the alignment acts, and so shows as variation when the camera turns: the
steady share is what a constant alignment can remove.

Measured (real, bench realdata's cue-set rotations; the carried rotations' half mean-square difference
against the reference's, deg per axis at lags 1 / 10 / 30 frames): EuRoC learned normals 0.18 / 0.26 /
0.37 against 0.18 / 0.27 / 0.39; ICL kt3 learned normals 0.53 / 1.44 / 3.21 against 0.52 / 1.35 / 2.92;
ICSL lines 0.22 / 0.52 / 1.13 against 0.10 / 0.16 / 0.22 (there the image motion's own error, 0.44 deg
a frame, dominates: the variation is overstated, the steady share understated, and the calibration's
steady part is kept where it is the larger, `SteadyPart`).
"""

from __future__ import annotations

import numpy as np

from ..rotations import nearest_symmetric
from ..types import VisualRotation, steady_within

MIN_PAIRS = 10
"""Before this many pairs the variation is not said (a steady share from a few frames would be a guess)."""
FAR_FRAMES = 1.0
"""The far variation (a frame against the older half of its chain) is averaged over about this many frames
(exponentially; 1: the previous frame's alone). One frame's sample is mostly its own error, and so it is
the more conservative the less it is averaged: real ICL kt3 learned normals, single, aligned NEES 5.65 /
6.05 / 7.12 averaged over 1 / 3 / 10 frames (errors wandering faster than the stream so far has shown)."""


class StreamVariation:
    """The per-axis variance (rad^2) of a stream's visual errors about their shared part (module docstring).

    Over every pair of frames of each unbroken chain of image rotations: the mean of |e_k - e_j|^2 / 2 over
    all pairs is the mean of |e_k - mean e|^2, what a constant alignment leaves. An error that wanders shows
    at long lags first, and the stream so far has seen shorter ones than the alignment of the whole stream
    will: so v is the larger of the mean over all pairs and the (averaged) mean of each frame against the
    older half of its chain (real ICL kt3 learned normals, errors wandering 0.5 deg at one frame, 4.5 at
    60: aligned NEES 11.2 from all pairs alone, 5.7 with the far pairs). Each pair's squared angle is
    taken as 3 - tr(X_j^T X_k) (4 sin^2 of half the angle: the angle's square to 0.1 % at 6 deg), so a
    frame costs O(1): the chain keeps the running sums of its X_j."""

    def __init__(self, min_pairs: int = MIN_PAIRS, far_frames: float = FAR_FRAMES):
        self.min_pairs, self.far_frames = int(min_pairs), float(far_frames)
        self._prefix: list[np.ndarray] = [np.zeros((3, 3))]
        """Sums of the current chain's (image rotations unbroken) first j X's, j = 0 .. its length."""
        self._P = np.eye(3)
        self._R_cm: np.ndarray | None = None
        """The previous frame's `R_cm` as labelled along the chain."""
        self._sum, self._pairs = 0.0, 0
        self._far = self._far_weight = 0.0

    @property
    def variance_rad2(self) -> float | None:
        """v (rad^2 per axis), None before `min_pairs` pairs."""
        if self._pairs < self.min_pairs:
            return None
        v = self._sum / (6.0 * self._pairs)
        return max(v, self._far / self._far_weight) if self._far_weight > 0 else v

    def update(self, visual: VisualRotation | None) -> float | None:
        """Take the next frame's visual rotation (None: the chain restarts) and return the variation the
        frames before it show (`variance_rad2` before this frame: its own error judges nothing of itself)."""
        known = self.variance_rad2
        if visual is None or not visual.is_finite():
            self._restart()
            return known
        if self._R_cm is None or not visual.has_image_rotation():
            self._restart()
            R_cm = visual.R_cm
        else:
            R_cm, _ = nearest_symmetric(visual.R_cm, visual.R_cp @ self._R_cm)  # R_cm_k ~ R_cp R_cm_k-1
            self._P = self._P @ visual.R_cp.T
        X = R_cm.T @ self._P.T
        n = len(self._prefix) - 1
        self._sum += 3.0 * n - float(np.sum(self._prefix[-1] * X))  # sum_j 3 - tr(X_j^T X)
        self._pairs += n
        if n >= 2:
            m = n // 2 + 1  # the older half of the chain
            a = 1.0 / self.far_frames
            self._far = (1.0 - a) * self._far + a * (3.0 * m - float(np.sum(self._prefix[m] * X))) / (6.0 * m)
            self._far_weight = (1.0 - a) * self._far_weight + a
        self._prefix.append(self._prefix[-1] + X)
        self._R_cm = R_cm
        return known

    def _restart(self) -> None:
        self._prefix, self._P, self._R_cm = [np.zeros((3, 3))], np.eye(3), None


def steady_share(cov_rad2: np.ndarray, variance_rad2: float) -> np.ndarray:
    """The part of `cov_rad2` (3, 3) that varies by no more than `variance_rad2` per axis leaves shared:
    `C - v I` within `C` (`types.steady_within`; zero where the stream varies by C or more)."""
    return steady_within(cov_rad2, cov_rad2 - variance_rad2 * np.eye(3))
