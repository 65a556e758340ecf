"""The time offset between a ground-truth clock and the camera clock, estimated from the estimates.

    est = estimate_time_offset(t_s, R_wc_est, truth)     # truth: drivers.base.GroundTruth
    est.offset_s, est.are_deg_at_offset, est.are_deg_at_zero

The offset follows `--gt-time-offset-s`: seconds ADDED to the ground-truth stamps to put them on the
camera's clock, so the frame at camera time t is scored against the reference at t - offset of the
reference's own clock. It is the offset that minimises the mean ARE (paper eq. 10, after the constant
alignment, recomputed for each candidate) of camera-to-world estimates against the reference slerped at
the shifted times, over a grid of `step_s`, refined by a parabola through the best grid point and its
two neighbours. Frames whose Manhattan labelling differs from the others' (a stream that switched axes:
a constant error of 90 or 120 deg that no offset changes) are first relabelled to the labelling nearest
the reference (`relabel_to_reference`), and frames still wrong by more than `outlier_deg` at offset 0
are left out, so that the figure measures the clock, not the labelling. A camera turning at w rad/s
whose reference is late by dt is wrong by about w dt, so on a fast sequence (TUM fr1 rpy: 0.5-1.5
rad/s) a few tens of ms show as degrees. The interval is a moving-block bootstrap over the frames.

Estimate it on frames kept for training only (TUM fr1 rpy: the train split), and use it elsewhere as a
fixed dataset default (`formats.tum.TUM_RGBD_GT_TIME_OFFSET_S`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..rotations import align_constant, angle_between, are_deg, nearest_symmetric
from .paired_difference import block_starts

DEFAULT_SEARCH_S = 0.1
"""Candidates run over +-this (s)."""
DEFAULT_STEP_S = 0.001
OUTLIER_DEG = 15.0
"""Frames wrong by more than this after relabelling (at offset 0) do not enter the estimate."""


def _swap(R: np.ndarray) -> np.ndarray:
    return np.swapaxes(R, -1, -2)


def relabel_to_reference(R_wc_est: np.ndarray, R_wc_true: np.ndarray, iterations: int = 5) -> np.ndarray:
    """`R_wc_est` (N, 3, 3) with each frame's world axes relabelled (`P R_wc`, P one of the 24 Manhattan
    symmetries) to the labelling nearest `R_wc_true` under one constant alignment: the alignment that
    puts most frames within `OUTLIER_DEG` is taken among those of 24 frames spread over the sequence,
    then labels and alignment are refined in turn."""
    R_est, R_true = np.asarray(R_wc_est, float), np.asarray(R_wc_true, float)

    def labelled(A):
        # A P R_est ~ R_true  <=>  R_est^T P^T ~ (A^T R_true)^T: the R_cm form of `nearest_symmetric`.
        return _swap(nearest_symmetric(_swap(R_est), _swap(_swap(A) @ R_true))[0])

    def inliers(A):
        return int(np.sum(np.degrees(angle_between(A @ labelled(A), R_true)) < OUTLIER_DEG))

    picks = np.unique(np.linspace(0, len(R_est) - 1, 24).astype(int))
    A = max((R_true[k] @ R_est[k].T for k in picks), key=inliers)
    for _ in range(iterations):
        R_rel = labelled(A)
        A = align_constant(R_rel, R_true)
    return labelled(A)


@dataclass(frozen=True)
class TimeOffsetEstimate:
    """The estimated offset (s, added to the reference's stamps) and the mean ARE (deg) against it and at 0."""

    offset_s: float
    are_deg_at_offset: float
    are_deg_at_zero: float
    offsets_s: np.ndarray
    """(K,) the grid searched."""
    mean_are_deg: np.ndarray
    """(K,) mean ARE at each grid offset (NaN where the shifted reference does not cover the frames)."""
    frames: int
    """Frames used (the relabelled inliers)."""
    low_s: float = float("nan")
    high_s: float = float("nan")
    """The 95 % moving-block bootstrap interval of `offset_s`."""


def are_at_offset(t_s: np.ndarray, R_wc_est: np.ndarray, truth, offset_s: float) -> np.ndarray:
    """Per-frame ARE (deg, one constant alignment) of `R_wc_est` (N, 3, 3) at camera times `t_s` (N,)
    against `truth` (a `GroundTruth`) with `offset_s` added to its stamps; NaN unless it covers every frame."""
    R_true, covered = truth.at(np.asarray(t_s, float) - offset_s)
    if not covered.all():
        return np.full(len(t_s), np.nan)
    return are_deg(R_wc_est, R_true, align=True)


def _minimum(offsets: np.ndarray, curve: np.ndarray) -> float:
    """The grid minimum of `curve`, refined by the parabola through it and its neighbours."""
    k = int(np.nanargmin(curve))
    best = float(offsets[k])
    if 0 < k < len(offsets) - 1 and np.isfinite(curve[k - 1]) and np.isfinite(curve[k + 1]):
        bend = curve[k - 1] - 2 * curve[k] + curve[k + 1]
        if bend > 0:
            best += 0.5 * (offsets[1] - offsets[0]) * (curve[k - 1] - curve[k + 1]) / bend
    return best


def _block_bootstrap(offsets: np.ndarray, are: np.ndarray, block: int, resamples: int, level: float,
                     seed: int) -> tuple[float, float]:
    """(low, high) of the offset over moving-block resamples of the frames (columns of `are` (K, N))."""
    n = are.shape[1]
    block = max(1, min(block, n))
    starts = block_starts(n, block, resamples, seed)
    picks = (starts[:, :, None] + np.arange(block)).reshape(resamples, -1)[:, :n]
    found = [_minimum(offsets, are[:, idx].mean(axis=1)) for idx in picks]
    tail = 50.0 * (1.0 - level)
    return float(np.percentile(found, tail)), float(np.percentile(found, 100.0 - tail))


def estimate_time_offset(t_s, R_wc_est, truth, search_s: float = DEFAULT_SEARCH_S,
                         step_s: float = DEFAULT_STEP_S, outlier_deg: float = OUTLIER_DEG,
                         block_s: float = 1.0, resamples: int = 400, level: float = 0.95) -> TimeOffsetEstimate:
    """The offset in [-search_s, search_s] minimising the mean ARE of the relabelled inlier frames
    (module docstring), with a moving-block bootstrap interval (`level`, blocks of `block_s` of frames:
    neighbouring frames' errors are correlated). `InputError` with fewer than 3 frames (or inliers), a bad
    grid, or a reference that covers the frames at no candidate."""
    t_s, R_wc_est = np.asarray(t_s, float), np.asarray(R_wc_est, float)
    if len(t_s) < 3 or R_wc_est.shape != (len(t_s), 3, 3):
        raise InputError(f"a time offset needs at least 3 frames with (N, 3, 3) rotations, got {len(t_s)} "
                         f"times and rotations of shape {R_wc_est.shape}")
    if not (np.isfinite(search_s) and np.isfinite(step_s) and 0 < step_s <= search_s):
        raise InputError(f"need 0 < step_s <= search_s, got step_s {step_s} and search_s {search_s}")
    R_true, covered = truth.at(t_s)
    if not covered.all():
        raise InputError(f"the ground truth covers {int(covered.sum())} of {len(t_s)} frames at offset 0")
    R_rel = relabel_to_reference(R_wc_est, R_true)
    keep = are_deg(R_rel, R_true, align=True) <= outlier_deg
    if keep.sum() < 3:
        raise InputError(f"only {int(keep.sum())} frames are within {outlier_deg} deg of the reference")
    t_s, R_wc_est = t_s[keep], R_rel[keep]
    n = int(round(search_s / step_s))
    offsets = np.arange(-n, n + 1) * step_s
    are = np.array([are_at_offset(t_s, R_wc_est, truth, d) for d in offsets])  # (K, N)
    curve = are.mean(axis=1)
    covering = np.isfinite(curve)
    if not covering.any():
        raise InputError("the ground truth covers the frames at no candidate offset")
    best = _minimum(offsets, curve)
    frame_s = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 1.0
    low, high = _block_bootstrap(offsets[covering], are[covering], int(round(block_s / max(frame_s, 1e-9))),
                                 resamples, level, seed=0)
    return TimeOffsetEstimate(best, float(np.mean(are_at_offset(t_s, R_wc_est, truth, best))),
                              float(np.mean(are_at_offset(t_s, R_wc_est, truth, 0.0))), offsets, curve,
                              len(t_s), low, high)
