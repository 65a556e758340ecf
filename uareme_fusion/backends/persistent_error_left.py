"""How much of the frames' persistent visual error an estimate that averages frames still carries.

`visual_noise_share.py` splits each frame's visual covariance `C` into an independent share `lam C` and a
persistent share `(1 - lam) C`, and a backend reports the persistent share with its estimate. "Persistent"
is read at a lag of one frame; over a smoother's window the error decorrelates (real TUM fr1 rpy, learned
normals: 1 - rho = 0.08 / 0.64 / 0.90 at lags 1 / 10 / 30 frames, `tools/error_decorrelation.py`), so an
estimate that averages the window's frames carries only part of it, and the whole share overstated the
error: the real TUM smoother's NEES was 0.78 (error 18 % below `single`'s, covariance the frames').

Model: the persistent error p_k is a first-order Gauss-Markov process of correlation `phi` per frame,
and the estimate follows the frames as a Kalman filter of gain g_k = tr P_k / tr R_k (the latest state's
marginal P_k against the frame's fused covariance R_k = lam C: for the latest state a fixed-lag smoother's
marginal is the filter's posterior, P = (1 - K) P^- = K R). Its share of p, eps_k = (1 - g) eps_k-1 + g p_k,
has the variance `fraction` a_k of Var p, with c_k = Cov(eps_k, p_k) / Var p:

    a_k = (1 - g)^2 a_k-1 + 2 g (1 - g) phi c_k-1 + g^2,    c_k = (1 - g) phi c_k-1 + g    (a = c = 1 at start)

`phi` comes from the frames' rotations against the image rotations between them (`VisualRotation.R_cp`)
over `lag_frames` frames, which cancel the motion but not the error:

    D_k = Log((R_cp chain k-L..k)^T R_mc,k-L^T R_mc,k),    M = C_k-L + C_k + drift I,
    E[D^T M^-1 D] - tr(M^-1 drift) = (1 - (1 - lam) phi^L) (3 - tr(M^-1 drift))        (`whitened_change`)

C the frames' per-frame covariances, drift the chain's variance per axis (the sum of the image rotations'
stated variances); averaged over the stream (ratio of exponential averages over `frames`). Where the image
rotations drift more than the frames err, D reads more decorrelation than there is (real ICSL corridor_more at
lag 10: 1.32 against 0.73 from the truth); the drift term takes their stated variance out. Whitened by M, not
normalised by traces: |D|^2 against the covariances' traces read next to no decorrelation on TUM (phi 0.99,
NEES 0.84). Measured (REAL, the paper smoother, `tools/visual_only_replay.py`):
TUM fr1 rpy eval NEES 0.78 -> 1.11 (learned normals), 1.49 -> 1.59 (depth); every other sequence within 0.1.
"""

from __future__ import annotations

import numpy as np

from ..rotations import log_so3
from ..types import VisualRotation, chained_image_rotation

MAX_SAMPLE = 10.0
"""Cap on one sample as a multiple of its expectation were the errors independent: a relabelled or wrong frame
counts as a tenfold noisy one, not without bound (as `visual_noise_share.MAX_SAMPLE`)."""


class PersistentErrorLeft:
    """The fraction of the frames' persistent error an estimate following them carries (module docstring)."""

    def __init__(self, lag_frames: int, frames: float):
        """`lag_frames`: the lag L (frames) at which `phi` is read; `frames`: its averaging horizon (frames)."""
        self.lag_frames, self.frames = int(lag_frames), float(frames)
        self.phi = 1.0
        """Correlation per frame of the persistent error (1 until the frames show less)."""
        self.fraction = 1.0
        """a_k: the estimate's share of the persistent error's variance (1: all of it)."""
        self._c = 1.0
        self._history: list[tuple[np.ndarray, np.ndarray | None, float, np.ndarray]] = []
        """(R_mc, R_cp, its variance per axis rad^2, the per-frame covariance) of the last `lag_frames` + 1 frames."""
        self._num = self._den = 0.0
        self._fused_trace = float("nan")  # tr R of the frame not yet settled (NaN: none)

    def observe(self, visual: VisualRotation, frame_part_rad2: np.ndarray, fused_trace_rad2: float,
                share: float) -> None:
        """Take a frame: `visual` labelled as fused, `frame_part_rad2` its per-frame covariance as one of
        `R_wc` (3, 3), `fused_trace_rad2` the trace of the covariance fused (lam C), `share` the current lam."""
        var = float(visual.R_cp_std_rad) ** 2 if visual.R_cp is not None else float("nan")
        entry = (visual.R_cm.T, visual.R_cp, var, frame_part_rad2)
        self._history = (self._history + [entry])[-(self.lag_frames + 1):]
        self._fused_trace = float(fused_trace_rad2)
        if len(self._history) == self.lag_frames + 1:
            self._sample(float(share))

    def restart(self) -> None:
        """A frame without a rotation: the chain of image rotations restarts."""
        self._history.clear()

    def settle(self, P_rad2: np.ndarray) -> float:
        """Step `fraction` with the estimate's marginal `P_rad2` (3, 3) after the frame `observe` took (once
        per frame; later calls return it unchanged)."""
        if not (np.isfinite(self._fused_trace) and self._fused_trace > 0):
            return self.fraction
        g = float(np.clip(np.trace(P_rad2) / self._fused_trace, 0.0, 1.0))
        a, c, phi = self.fraction, self._c, self.phi
        self.fraction = (1.0 - g) ** 2 * a + 2.0 * g * (1.0 - g) * phi * c + g * g
        self._c = (1.0 - g) * phi * c + g
        self._fused_trace = float("nan")
        return self.fraction

    def _sample(self, share: float) -> None:
        """`phi` with the sample of the last `lag_frames` + 1 frames (none where an image rotation is missing)."""
        (R0, _, _, C0), *rest = self._history
        chain = chained_image_rotation(R_cp for _, R_cp, _, _ in rest)  # R_mc,0^T R_mc,L up to the errors
        if chain is None or not all(np.isfinite(var) for _, _, var, _ in rest):
            return
        R1, C1 = rest[-1][0], rest[-1][3]
        change = whitened_change(R0, C0, R1, C1, chain, sum(var for _, _, var, _ in rest))
        if change is None:
            return
        sample, expected = change
        a = min(1.0 / self.frames, 1.0)
        self._num = (1.0 - a) * self._num + a * min(sample, MAX_SAMPLE * expected)
        self._den = (1.0 - a) * self._den + a * expected
        rho_lag = 1.0 - self._num / self._den if self._den > 0 else 1.0  # (1 - lam) phi^L
        if share >= 1.0:
            return
        self.phi = float(np.clip(max(rho_lag, 0.0) / (1.0 - share), 0.0, 1.0) ** (1.0 / self.lag_frames))


def whitened_change(R_mc0: np.ndarray, C0: np.ndarray, R_mc1: np.ndarray, C1: np.ndarray, chain: np.ndarray,
                    drift_rad2: float) -> tuple[float, float] | None:
    """How much two frames' errors differ, read against the image rotations between them: (D^T M^-1 D less the
    chain's own share, its expectation were the errors independent), D = Log(chain^T R_mc0^T R_mc1) (rad),
    M = chain^T C0 chain + C1 + drift I its covariance then; `C0`, `C1` the frames' per-frame covariances as ones
    of `R_wc` (rad^2), `chain` the chained image rotations (`types.chained_image_rotation`), `drift_rad2` their
    variance per axis. The ratio is 1 - rho for the errors' correlation rho (module docstring). None when M is
    singular."""
    drift = drift_rad2 * np.eye(3)
    try:
        M_inv = np.linalg.inv(chain.T @ C0 @ chain + C1 + drift)
    except np.linalg.LinAlgError:
        return None
    D = log_so3(chain.T @ R_mc0.T @ R_mc1)
    own = float(np.trace(M_inv @ drift))
    return max(float(D @ M_inv @ D) - own, 0.0), max(3.0 - own, 1e-9)
