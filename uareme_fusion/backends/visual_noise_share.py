"""How much of a visual rotation's error is new in each frame, from the frames themselves.

A solver's covariance says how far one frame's rotation may be from the truth. Over a stream that
error is not independent from frame to frame: the same scene seen again (the same segments, the
same network textures) errs the same way. On the real ICSL corridor (learned normals and segments,
depth-normal rotations as the reference) consecutive frames' errors differ by 0.65 deg while each
frame's std is 1.34 deg per axis: nearly all of the error persists. A filter that takes each frame
as an independent measurement averages what cannot be averaged: it leans on its motion model, lags
the real (handheld) motion and reports a covariance shrunk below the frames' own.

So the visual covariance `C` of each frame is split into an independent share `lam C`, fused as a
measurement, and a persistent share `(1 - lam) C` that the filter cannot remove: it is added to the
covariance the backend reports (a "consider" term: the estimate carries the current frame's
persistent error). `lam` comes from the measurements' second differences, which cancel the
persistent error and a constant-rate motion:

    D_k = Log(R_k-1^T R_k) - r_k Log(R_k-2^T R_k-1),   r_k = dt_k / dt_k-1   (rad, the frames' `R_mc`)

What is left in `D_k` is the independent error and the motion a constant rate does not predict. A
handheld camera shakes: its angle takes a random walk between frames (variance `q dt`, `q` rad^2/s
summed over the axes) that the depth reference follows as well (ICSL: RGB and depth second
differences correlate 0.61; lam from |D|^2 alone, 0.05, was that shake). The two are told apart by
how consecutive `D`s correlate (independent error: -2/3; shake: -1/2; a drifting rate: +1/4):

    E |D_k|^2       = lam (tr C_k + (1 + r_k)^2 tr C_k-1 + r_k^2 tr C_k-2) + q (dt_k + r_k^2 dt_k-1)
    E D_k . D_k-1   = -lam ((1 + r_k) tr C_k-1 + r_k (1 + r_k-1) tr C_k-2) - q r_k dt_k-1

`w_k (D_k . D_k-1)` added to `|D_k|^2`, `w_k = (dt_k + r_k^2 dt_k-1) / (r_k dt_k-1)`, cancels `q`;
lam is the ratio of the averages of that sum and of its expectation per unit lam (each `D` capped at
`MAX_SAMPLE` times its expected |D|^2; no sample when the four covariances differ by more than
`SAME_VIEW_RATIO`), over the last `frames` frames (exponentially), raised by `CONFIDENCE_SIGMAS`
standard errors and clipped to [`min_share`, 1]. Measured lam: ICSL-more at the floor (|D|^2 alone
read 0.05 there), ICL kt3 (rendered) 0.1-0.7, simulated maps drawn afresh each frame ~1, a simulated
shake of 0.5 deg per frame over persistent errors < 0.03 (|D|^2 alone: 0.07).

Until `MIN_SAMPLES` samples are in (`settled`), lam is the floor: a filter that does not yet know
whether the frames' errors are independent takes them as `single` does (fused as independent, the
real corridor's first frames made both filters trail `single`), and the EKF forgets the rate between
such frames (their differences are the frames' full error, not motion). When lam rises above the
highest value it had, the share it gains moves from the reported persistent term into the filter's
own covariance (`rise_R_wc_covariance`), so that the reported covariance does not drop (NEES of a
simulated walk at the end of the start: 2490 without). The filters gate and Huber-weigh a frame on
its full covariance (the EKF adds the persistent error its state carries, which is another view's
after the view changed), and fuse lam C: with lam C in the gate, a wrong rate once made the EKF
reject every later frame of a real lines-only stream and run away (ARE 42 deg).
"""

from __future__ import annotations

import numpy as np

from ..rotations import log_so3
from ..types import VisualRotation, visual_R_wc_covariance


MAX_SAMPLE = 10.0
"""Cap on one second difference: |D|^2 at most this many times its expected value under lam = 1 (a
frame off by far more than its covariance, a wrong minimum or a relabelling, counts like a tenfold
noisy one, not without bound)."""


CONFIDENCE_SIGMAS = 2.0
"""lam is the average raised by this many standard errors (module docstring)."""
SAME_VIEW_RATIO = 4.0
"""Four frames whose covariance traces differ by more than this give no sample: the view changed
(a frame with too few segments, a capped unobservable axis), and one frame's error says nothing of the
others'."""

MIN_SAMPLES = 30
"""Samples (four frames in a row each) before lam leaves the floor: the default averaging horizon
(module docstring)."""


class VisualNoiseShare:
    """The running independent share `lam` of the frames' visual covariances (module docstring)."""

    def __init__(self, frames: float, min_share: float = 0.001):
        """`frames`: the averaging horizon (0: off, `share` stays 1); `min_share` the floor of lam."""
        self.frames, self.min_share = float(frames), float(min_share)
        self.share = self.min_share if self.enabled else 1.0
        self._top = self.share  # the highest share so far
        self._rise = 0.0  # how far the latest update raised the share above the highest before
        self._history: list[tuple[float, np.ndarray, float]] = []
        self._mean, self._outer = np.zeros(2), np.zeros((2, 2))  # averages of (noise, per_share), its outer product
        self._weight = 0.0
        self._count = 0

    @property
    def enabled(self) -> bool:
        return self.frames > 0

    @property
    def settled(self) -> bool:
        """lam is estimated (`MIN_SAMPLES` samples in), or the share is off (stays 1)."""
        return not self.enabled or self._count >= MIN_SAMPLES

    def update(self, t_s: float, visual: VisualRotation | None) -> float:
        """Take the frame at `t_s` (its visual rotation labelled as the backend fuses it, or None:
        the chain of consecutive frames restarts) and return the current `share`."""
        self._rise = 0.0
        if not self.enabled:
            return self.share
        if visual is None:
            self._history.clear()
            return self.share
        if not is_covariance(visual.cov):  # the frame says nothing here
            return self.share
        self._history = (self._history + [(float(t_s), visual.R_cm.T, float(np.trace(visual.cov)))])[-4:]
        if len(self._history) < 4:
            return self.share
        t, R, c = zip(*self._history)
        dt = np.diff(t)
        if not (np.all(dt > 0) and min(c) > 0) or max(c) > SAME_VIEW_RATIO * min(c):
            return self.share
        self._add_sample(dt, R, c)
        self._estimate()
        return self.share

    def _add_sample(self, dt: np.ndarray, R, c) -> None:
        """The sample of four frames (steps `dt` (3,) s, `R_mc`, covariance traces rad^2) into the
        exponential averages (module docstring)."""
        r, r_prev = dt[2] / dt[1], dt[1] / dt[0]
        steps = [log_so3(R[k].T @ R[k + 1]) for k in range(3)]
        expected = c[3] + (1.0 + r) ** 2 * c[2] + r**2 * c[1]
        expected_prev = c[2] + (1.0 + r_prev) ** 2 * c[1] + r_prev**2 * c[0]
        D = _capped(steps[2] - r * steps[1], expected)
        D_prev = _capped(steps[1] - r_prev * steps[0], expected_prev)
        shake = dt[2] + r * r * dt[1]
        w = shake / (r * dt[1])
        # E[noise] = lam * per_share: the shake cancels (w times the cross term's -q r dt_k-1).
        noise = float(D @ D + w * (D @ D_prev))
        per_share = expected - w * ((1.0 + r) * c[2] + r * (1.0 + r_prev) * c[1])
        x = np.array([noise, per_share])
        a = min(1.0 / self.frames, 1.0)
        self._mean = (1.0 - a) * self._mean + a * x
        self._outer = (1.0 - a) * self._outer + a * np.outer(x, x)
        self._weight = (1.0 - a) * self._weight + a
        self._count += 1

    def _estimate(self) -> None:
        """lam from the averages (a ratio of averages), raised by `CONFIDENCE_SIGMAS` standard errors
        (from the spread of the residuals): the filter leaves the plain one (lam = 1) only as far as
        the frames show it."""
        mean, outer = self._mean / self._weight, self._outer / self._weight
        if self._count < MIN_SAMPLES or not mean[1] < 0:  # too few, or covariances too unlike
            return
        a = min(1.0 / self.frames, 1.0)
        n_eff = min(self._count, (2.0 - a) / a)
        lam = mean[0] / mean[1]
        residual = np.array([1.0, -lam])  # of noise - lam per_share
        error = np.sqrt(max(residual @ outer @ residual, 0.0) / n_eff) / -mean[1]
        self.share = float(np.clip(lam + CONFIDENCE_SIGMAS * error, self.min_share, 1.0))
        self._rise = max(self.share - self._top, 0.0)
        self._top = max(self._top, self.share)

    def take(self, t_s: float, visual: VisualRotation | None) -> np.ndarray | None:
        """`update` with the frame, then the persistent covariance of it to report with the estimate
        (`persistent_R_wc_covariance`); None when the frame has no rotation or no covariance (`is_covariance`)."""
        self.update(t_s, visual)
        if visual is None or not is_covariance(visual.cov):
            return None
        return self.persistent_R_wc_covariance(visual)

    def persistent_R_wc_covariance(self, visual: VisualRotation) -> np.ndarray:
        """(1 - lam) times `visual`'s covariance as one of `R_wc` (rad^2, right perturbation)."""
        return (1.0 - self.share) * visual_R_wc_covariance(visual)

    def rise_R_wc_covariance(self, visual: VisualRotation) -> np.ndarray:
        """How far the latest update raised lam above its highest value so far, times `visual`'s
        covariance as one of `R_wc` (rad^2): taken from the persistent term, the filter adds it to
        its own covariance (module docstring)."""
        return self._rise * visual_R_wc_covariance(visual)


def _capped(D: np.ndarray, expected: float) -> np.ndarray:
    """`D` shortened to |D|^2 <= `MAX_SAMPLE` * `expected` (rad^2)."""
    d2 = float(D @ D)
    return D if d2 <= MAX_SAMPLE * expected else D * np.sqrt(MAX_SAMPLE * expected / d2)


def is_covariance(cov: np.ndarray) -> bool:
    """Finite, symmetric and positive definite (3, 3)."""
    return bool(np.all(np.isfinite(cov)) and np.allclose(cov, cov.T) and np.linalg.eigvalsh(cov)[0] > 0)
