"""How far the single-frame visual errors decorrelate with the lag L between frames, from cached rotations.

For each sequence and cue set of `tools/visual_only_replay.py --build`'s cache, the `single` backend's errors
e_k (world frame, after the constant alignment) give 1 - rho(L) = E|e_k - e_k-L|^2 / (2 E|e|^2) (the truth).
Beside it, the same ratio read without the truth: the frames' relative rotation against the chained image
rotations (`VisualRotation.R_cp`), which adds the image rotations' own drift (an upper bound on the
decorrelation). It shows what the persistent share of `backends/visual_noise_share.py` (read at lag 1) leaves
out: how much of the "persistent" error is gone within the smoother's 30-frame window.

Usage: python tools/error_decorrelation.py CACHE.pkl [MORE.pkl ...]
"""

from __future__ import annotations

import dataclasses
import pickle
import sys

import numpy as np

LAGS = (1, 3, 10, 30)


def single_errors(visual, info, normals: str) -> tuple[np.ndarray, np.ndarray]:
    """(aligned R_wc of `single` (N, 3, 3), world-frame error vectors (N, 3) rad, NaN without truth)."""
    from uareme_fusion.evaluation.compare import run_backend
    from uareme_fusion.pipeline import RunConfig
    from uareme_fusion.pipeline.stages import backend_for_run
    from uareme_fusion.rotations import align_constant, log_so3

    camera = dataclasses.replace(info, R_ci=np.eye(3), imu_time_offset_s=0.0, has_imu=False)
    run = run_backend(backend_for_run(RunConfig(backend="single", normals=normals), camera), visual)
    R, T = np.array([e.R_wc for e in run.estimates]), visual.R_wc_true
    ok = np.all(np.isfinite(T), axis=(1, 2)) & np.all(np.isfinite(R), axis=(1, 2))
    R = align_constant(R[ok], T[ok]) @ R
    e = np.full((len(R), 3), np.nan)
    e[ok] = log_so3(np.swapaxes(T[ok], 1, 2) @ R[ok])
    return R, e


def decorrelation(visual, R: np.ndarray, e: np.ndarray, lag: int) -> tuple[float, float]:
    """(1 - rho(lag) from the truth, the same read from the image rotations)."""
    from uareme_fusion.rotations import log_so3
    from uareme_fusion.types import chained_image_rotation

    variance = np.nanmean(np.sum(e**2, axis=1))
    truth, image = [], []
    for k in range(lag, len(R)):
        if np.all(np.isfinite(e[k])) and np.all(np.isfinite(e[k - lag])):
            truth.append(np.sum((e[k] - e[k - lag]) ** 2))
        chain = chained_image_rotation(None if v is None else v.R_cp for v in visual.visuals[k - lag + 1:k + 1])
        if chain is not None:
            image.append(np.sum(log_so3(chain.T @ R[k - lag].T @ R[k]) ** 2))
    read = np.mean(image) / (2 * variance) if image else float("nan")
    return float(np.mean(truth) / (2 * variance)), float(read)


def main() -> None:
    from uareme_fusion.benchmarks.realdata import CUE_SETS

    for path in sys.argv[1:]:
        with open(path, "rb") as f:
            sequences = pickle.load(f)
        for (name, cue), (visual, info) in sequences.items():
            R, e = single_errors(visual, info, CUE_SETS[cue][0])
            rms = np.degrees(np.sqrt(np.nanmean(np.sum(e**2, axis=1))))
            cells = [f"L{lag}: {t:4.2f} / {i:4.2f}" for lag in LAGS for t, i in [decorrelation(visual, R, e, lag)]]
            print(f"{name[:18]:18s} {cue:18s} error rms {rms:5.2f} deg | 1 - rho, truth / image rotations: "
                  + " | ".join(cells), flush=True)


if __name__ == "__main__":
    main()
