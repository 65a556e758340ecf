"""How long a visual rotation's error persists, from the frames and their image rotations.

A frame's absolute rotation `V_k` (`R_wc` from its `R_cm`) errs by `e_k`; its image rotation `R_cp`
(`solver/frame_motion.py`) measures the motion since the previous frame far better. Chained over `L`
frames, the image rotations predict `V_k` from `V_k-L`, and the lagged difference

    d_k(L) = Log(R_cp,k ... R_cp,k-L+1  V_k-L^T V_k)  (rad)

is `e_k - e_k-L` plus the chain's error (variance `sum sigma_cp^2` per axis). Its mean square
`S(L) = 2 var(e) (1 - rho^L)` for a Gauss-Markov error of frame-to-frame correlation `rho`: white errors
(`rho = 0`) give `S(L) = S(1)`, persistent ones `S(L) -> L S(1)`. The ratio `S(L) / S(1)` (the chain's
variance taken off each) is `(1 - rho^L) / (1 - rho)`, solved for `rho`, and the correlation time is
`tau = -dt / ln rho` (s, `dt` the mean frame interval). The squares are averaged exponentially over
`frames` frames, each capped at `MAX_SAMPLE` times what the frames' covariances and the chain say (a wrong
minimum moves the average like a tenfold noisy frame, not without bound); `tau` is 0 until
`MIN_SAMPLES` lag-`L` differences are seen, and at most `max_s`.
"""

from __future__ import annotations

import numpy as np

from ..rotations import log_so3
from ..types import VisualRotation


MAX_SAMPLE = 10.0
"""Cap on one squared difference, in units of its expected value from the covariances (module docstring)."""
MIN_SAMPLES = 30
"""Lag-`L` differences seen before `tau` leaves 0."""


def correlation_from_ratio(ratio: float, lag_frames: int) -> float:
    """`rho` in [0, 1) with `(1 - rho^L) / (1 - rho) = ratio` (1 at `rho = 0`, `L` as `rho -> 1`)."""
    L = int(lag_frames)
    if not ratio > 1.0:
        return 0.0
    if ratio >= L:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if (1.0 - mid**L) / (1.0 - mid) < ratio:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


class VisualErrorPersistence:
    """The running correlation time `tau_s` of a stream's visual errors (module docstring)."""

    def __init__(self, lag_frames: int, frames: float = 100.0, max_s: float = 2.0):
        """`lag_frames`: `L` (0: off, `tau_s` stays 0); `frames`: the averaging horizon; `max_s`: cap, s."""
        self.lag_frames, self.frames, self.max_s = int(lag_frames), float(frames), float(max_s)
        self.tau_s = 0.0
        self._history: list[tuple[float, np.ndarray, float, np.ndarray, float]] = []
        """(t_s, V = R_cm^T, tr cov, R_cp, var_cp per axis) of the last `L + 1` frames of an unbroken chain."""
        self._avg = np.zeros(5)  # weight, S(1), chain(1), S(L), chain(L)
        self._count = 0
        self._dt_sum = 0.0
        self._dt_n = 0

    @property
    def enabled(self) -> bool:
        return self.lag_frames > 1

    def update(self, t_s: float, visual: VisualRotation | None) -> float:
        """Take the frame at `t_s` (its visual rotation labelled as the backend fuses it; None or one
        without an image rotation breaks the chain) and return the current `tau_s` (s)."""
        if not self.enabled:
            return self.tau_s
        if visual is None or not visual.is_finite() or not visual.has_image_rotation():
            self._history.clear()
            return self.tau_s
        entry = (float(t_s), visual.R_cm.T, float(np.trace(visual.cov)), visual.R_cp,
                 float(visual.R_cp_std_rad) ** 2)
        if self._history and not entry[0] > self._history[-1][0]:
            self._history.clear()
        self._history = (self._history + [entry])[-(self.lag_frames + 1):]
        if len(self._history) < 2:
            return self.tau_s
        self._dt_sum += self._history[-1][0] - self._history[-2][0]
        self._dt_n += 1
        s1, c1 = self._lagged(1)
        if len(self._history) <= self.lag_frames:
            return self.tau_s
        sL, cL = self._lagged(self.lag_frames)
        a = min(1.0 / self.frames, 1.0)
        self._avg = (1.0 - a) * self._avg + a * np.array([1.0, s1, c1, sL, cL])
        self._count += 1
        if self._count >= MIN_SAMPLES:
            self.tau_s = self._tau()
        return self.tau_s

    def _lagged(self, lag: int) -> tuple[float, float]:
        """(capped |d(lag)|^2, the chain's variance 3 sum sigma_cp^2), rad^2, ending at the newest frame."""
        t_k, V_k, c_k, _, _ = self._history[-1]
        _, V_0, c_0, _, _ = self._history[-1 - lag]
        chain = np.eye(3)
        chain_var = 0.0
        for _, _, _, R_cp, var in self._history[-lag:]:
            chain = R_cp @ chain
            chain_var += 3.0 * var
        d = log_so3(chain @ V_0.T @ V_k)
        return min(float(d @ d), MAX_SAMPLE * (c_k + c_0 + chain_var)), chain_var

    def _tau(self) -> float:
        w, s1, c1, sL, cL = self._avg
        first = (s1 - c1) / w
        if not first > 0:
            return 0.0
        ratio = max(sL - cL, 0.0) / w / first
        rho = correlation_from_ratio(ratio, self.lag_frames)
        dt = self._dt_sum / max(self._dt_n, 1)
        if rho <= 0.0:
            return 0.0
        if rho >= 1.0:
            return self.max_s
        return float(min(-dt / np.log(rho), self.max_s))
