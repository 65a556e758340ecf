"""How much of a visual rotation's error is new in each frame, from the frames themselves.

A solver's covariance says how far one frame's rotation may be from the truth. Over a stream that
error is not independent from frame to frame: the same scene seen again (the same segments, the
same network textures) errs the same way. On the real ICSL corridor (learned normals and segments,
depth-normal rotations as the reference) consecutive frames' errors differ by 0.65 deg while each
frame's std is 1.34 deg per axis: nearly all of the error persists. A filter that takes each frame
as an independent measurement averages what cannot be averaged: it leans on its motion model, lags
the real (handheld) motion and reports a covariance shrunk below the frames' own (`mekf` and
`smoother` ARE 2.18 deg against `single`'s 2.14, NEES 4.55 against 3.13).

So the visual covariance `C` of each frame is split into an independent share `lam C`, fused as a
measurement, and a persistent share `(1 - lam) C` that the filter cannot remove: it is added to the
covariance the backend reports (a "consider" term: the estimate carries the current frame's
persistent error). `lam` comes from the measurements' second differences, which cancel the
persistent error and a constant-rate motion:

    D_k = Log(R_k-1^T R_k) - (dt_k / dt_k-1) Log(R_k-2^T R_k-1)     (rad, the frames' `R_mc`)
    E |D_k|^2 = lam (tr C_k + (1 + r)^2 tr C_k-1 + r^2 tr C_k-2) + (what the motion changes),
    r = dt_k / dt_k-1.

`lam_k = |D_k|^2 / (tr C_k + (1 + r)^2 tr C_k-1 + r^2 tr C_k-2)` (capped at `MAX_SAMPLE`; none when
the three covariances differ by more than `SAME_VIEW_RATIO`) is averaged over the last
`frames` frames (exponentially; lam = 1 before three frames are seen), raised by `CONFIDENCE_SIGMAS`
standard errors and clipped to [`min_share`, 1]. A change of motion reads as independent error, so
the estimate errs towards lam = 1, the plain filter. With `of_frame_part` (the smoother) and an image rotation
between the frame and the previous one (`VisualRotation.R_cp`), the sample is instead the two frames'
rotation against it, whitened by their per-frame covariances plus its own and net of its own share
(`_image_rotation_sample`): the image rotation cancels any motion, which second differences read as
independent error on a handheld camera (real ICSL corridor_more, learned normals + lines, scene K: lam 1,
the smoother +0.03 (+0.01 .. +0.04) deg against `single`; read against the image rotations lam at its floor,
+0.00 (-0.00 .. +0.00); TUM, EuRoC, ICSL corridor and kt3 within 0.04 deg, every NEES in [1, 6]). Measured
with second differences: ICSL-more lam 0.05, ICL kt3 (rendered)
about 0.35, simulated maps drawn afresh each frame 1 (the filters unchanged there). The filters gate
and Huber-weigh a frame on its full covariance, and fuse lam C: with lam C in the gate, a wrong rate
once made the EKF reject every later frame of a real lines-only stream and run away (ARE 42 deg).
"""

from __future__ import annotations

import numpy as np

from ..rotations import log_so3
from ..types import (VisualRotation, chained_image_rotation, steady_within, visual_R_wc_covariance,
                     visual_R_wc_steady)
from .persistent_error_left import PersistentErrorLeft, whitened_change


MAX_SAMPLE = 10.0
"""Cap on one frame's ratio |D|^2 / E|D|^2: a frame off by far more than its covariance (a wrong
minimum, a relabelling) moves the average like a tenfold noisy one, not without bound."""


CONFIDENCE_SIGMAS = 2.0
"""lam is the average raised by this many standard errors (module docstring)."""
SAME_VIEW_RATIO = 4.0
"""Three frames whose covariance traces differ by more than this give no sample: the view changed
(a frame with too few segments, a capped unobservable axis), and one frame's error says nothing of the
others'."""


def _steady_or_zero(visual: VisualRotation) -> np.ndarray:
    steady = visual_R_wc_steady(visual)
    return np.zeros((3, 3)) if steady is None else steady


class VisualNoiseShare:
    """The running independent share `lam` of the frames' visual covariances (module docstring)."""

    def __init__(self, frames: float, min_share: float = 0.05, of_frame_part: bool = False,
                 persistence_lag_frames: int = 0):
        """`frames`: the averaging horizon (0: off, `share` stays 1); `min_share` the floor of lam;
        `of_frame_part`: lam is the share of each frame's per-frame part (`VisualRotation.cov_frame()`,
        the covariance less its steady calibration part), and the steady part is persistent as a whole
        (`take`); else of the whole covariance. `persistence_lag_frames` > 0 (with `of_frame_part`): the
        persistent per-frame part is reported as far as the estimate still carries it, its correlation read
        at that lag (`persistent_error_left.py`, `settle`); 0: whole."""
        self.frames, self.min_share = float(frames), float(min_share)
        self.of_frame_part = bool(of_frame_part)
        self.left = (PersistentErrorLeft(persistence_lag_frames, self.frames)
                     if persistence_lag_frames > 0 and of_frame_part and self.enabled else None)
        """The estimate's share of the persistent per-frame part (None: all of it)."""
        self._persistent_parts = (np.zeros((3, 3)), np.zeros((3, 3)))  # ((1 - lam) frame part, steady part)
        self.share = 1.0
        self.persistent_cov = np.zeros((3, 3))
        """(1 - lam) times the last finite frame's covariance as one of `R_wc` (rad^2, right
        perturbation): the error the filter cannot average, reported with the estimate (`take`); with
        `of_frame_part`, (1 - lam) times its per-frame part plus its whole steady part. Without it, a
        frame's steady part (`VisualRotation.cov_steady`) is persistent too and never less than whole:
        what of it (1 - lam) C does not hold (`types.steady_within`) is added. Else, where the steady
        part is most of C and lam floored (`min_share`) above the per-frame part's share, (1 - lam) C
        fell under the steady part and the estimate's per-frame part, scored after a constant
        alignment, was what little the fused share left: real ICSL corridor (scene K, steady part 98 %
        of C), visual-only mekf NEES 6.33 / 6.26 (RGB normals+lines / lines; single 3.79) -> 1.34 / 1.34,
        ARE unchanged (0.32); corridor_more 2.39 / 1.93 -> 2.27 / 1.79, ARE unchanged (1.45 / 2.16)."""
        self._history: list[tuple[float, np.ndarray, float]] = []  # (t_s, R_mc, tr cov) of the last frames
        self._sum = self._sum2 = self._weight = 0.0
        self._count = 0

    @property
    def enabled(self) -> bool:
        return self.frames > 0

    def update(self, t_s: float, visual: VisualRotation | None) -> float:
        """Take the frame at `t_s` (its visual rotation labelled as the backend fuses it, or None:
        the chain of consecutive frames restarts) and return the current `share`."""
        self._take_frame(t_s, visual)
        return self.share

    def take(self, t_s: float, visual: VisualRotation | None, R_wc_cov: np.ndarray | None = None,
             fused_trace_rad2: float | None = None) -> None:
        """`update` with the frame, then `persistent_cov` from it (kept as it was when the frame has no
        rotation or no finite covariance). `R_wc_cov`: `visual_R_wc_covariance(visual)` when the caller
        has it already; `fused_trace_rad2`: the trace of the covariance the frame was fused with (for
        `left`; None: the share before the frame times its per-frame part)."""
        share = self.share
        if self._take_frame(t_s, visual):
            R_wc_cov = visual_R_wc_covariance(visual) if R_wc_cov is None else R_wc_cov
            steady = visual_R_wc_steady(visual)
            if self.of_frame_part:
                steady = np.zeros((3, 3)) if steady is None else steady
                frame_part = R_wc_cov - steady
                self._persistent_parts = ((1.0 - self.share) * frame_part, steady)
                if self.left is not None:
                    fused = share * np.trace(frame_part) if fused_trace_rad2 is None else fused_trace_rad2
                    self.left.observe(visual, frame_part, float(fused), self.share)
                self.persistent_cov = self.left_fraction * self._persistent_parts[0] + steady
            elif steady is None:
                self.persistent_cov = (1.0 - self.share) * R_wc_cov
            else:
                persistent = (1.0 - self.share) * R_wc_cov
                self.persistent_cov = persistent + steady - steady_within(persistent, steady)

    @property
    def left_fraction(self) -> float:
        """The estimate's share of the persistent per-frame part (`persistent_error_left.py`; 1 without `left`)."""
        return 1.0 if self.left is None else self.left.fraction

    def settle(self, P_rad2: np.ndarray) -> np.ndarray:
        """`persistent_cov` once the frame `take` took is fused and the estimate's marginal is `P_rad2`
        (rad^2): its persistent per-frame part scaled by what the estimate still carries (`left`)."""
        if self.left is not None:
            self.left.settle(P_rad2)
            frame_part, steady = self._persistent_parts
            self.persistent_cov = self.left.fraction * frame_part + steady
        return self.persistent_cov

    def _take_frame(self, t_s: float, visual: VisualRotation | None) -> bool:
        """`update`'s work; whether `visual` is a rotation with a finite covariance."""
        if visual is None:
            self._history.clear()
            if self.left is not None:
                self.left.restart()
            return False
        if not np.all(np.isfinite(visual.cov)):  # not a covariance: the frame says nothing here
            return False
        if self.enabled:
            self._update_share(float(t_s), visual)
        return True

    def _update_share(self, t_s: float, visual: VisualRotation) -> None:
        """`share` with the frame (a finite covariance) as the newest of the last three: its sample read against
        the image rotation from the previous frame where the smoother's share has one, else from second
        differences."""
        cov = visual.cov_frame() if self.of_frame_part else visual.cov
        self._history = (self._history + [(t_s, visual.R_cm.T, float(np.trace(cov)), visual)])[-3:]
        sample = self._image_rotation_sample() if self.of_frame_part else None
        if sample is None:
            sample = self._second_difference_sample()
        if sample is None:
            return
        self._average(min(sample, MAX_SAMPLE))

    def _image_rotation_sample(self) -> float | None:
        """D^T M^-1 D against its expectation were the errors independent, D the last two frames' rotation
        against the image rotation between them (which cancels any motion; `persistent_error_left.py`'s whitened
        sample at lag 1); None without an image rotation."""
        if len(self._history) < 2 or self._history[-1][3].R_cp is None:
            return None
        (t0, R0, _, v0), (t1, R1, _, v1) = self._history[-2:]
        if not t1 > t0 or not np.isfinite(v1.R_cp_std_rad):
            return None
        C0, C1 = (visual_R_wc_covariance(v) - _steady_or_zero(v) for v in (v0, v1))
        change = whitened_change(R0, C0, R1, C1, chained_image_rotation([v1.R_cp]), v1.R_cp_std_rad**2)
        return None if change is None else change[0] / change[1]

    def _second_difference_sample(self) -> float | None:
        """|D|^2 of the last three frames' second difference against its expectation were the errors
        independent (module docstring); None without three frames of about the same view."""
        if len(self._history) < 3:
            return None
        (t0, R0, c0, _), (t1, R1, c1, _), (t2, R2, c2, _) = self._history
        if not (t1 > t0 and t2 > t1 and min(c0, c1, c2) > 0) or max(c0, c1, c2) > SAME_VIEW_RATIO * min(c0, c1, c2):
            return None
        r = (t2 - t1) / (t1 - t0)
        D = log_so3(R1.T @ R2) - r * log_so3(R0.T @ R1)
        expected = c2 + (1.0 + r) ** 2 * c1 + r**2 * c0
        return float(D @ D / expected)

    def _average(self, sample: float) -> None:
        # Exponential average over `frames`, its start-up bias removed (the first sample counts fully),
        # raised by `CONFIDENCE_SIGMAS` standard errors: the filter leaves lam = 1 only when the
        # frames show it (independent errors average to 1, and half the time to below it).
        a = min(1.0 / self.frames, 1.0)
        self._sum = (1.0 - a) * self._sum + a * sample
        self._sum2 = (1.0 - a) * self._sum2 + a * sample * sample
        self._weight = (1.0 - a) * self._weight + a
        self._count += 1
        mean = self._sum / self._weight
        var = max(self._sum2 / self._weight - mean * mean, 0.0)
        n_eff = min(self._count, (2.0 - a) / a)
        upper = mean + CONFIDENCE_SIGMAS * np.sqrt(var / n_eff)
        self.share = float(np.clip(upper, self.min_share, 1.0))
