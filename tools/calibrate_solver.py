"""Fit the solver's covariance scale so that NEES averages 3 on synthetic maps with correlated noise.

    python tools/calibrate_solver.py [--count 500] [--seed 0]

Prints the raw mean NEES with `covariance_scale = 1`, the fitted scale (mean NEES / 3), and the
mean NEES the fitted scale gives on a held-out set (another seed). Copy the scale into
`SolverConfig.covariance_scale`.
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from uareme_fusion.rotations import nees
from uareme_fusion.sim.normal_maps import random_noisy_maps
from uareme_fusion.solver import ManhattanSolver, SolverConfig


def mean_nees(solver: ManhattanSolver, count: int, seed: int) -> tuple[float, float, np.ndarray]:
    values = []
    for R_true, normal_map in random_noisy_maps(count, seed):
        # Relabel to the truth's Manhattan labelling (rotating the covariance with it) before NEES.
        result = solver.solve(normal_map).symmetric_to(R_true)
        values.append(nees(result.R_cm, R_true, result.cov))
    values = np.array(values)
    return float(values.mean()), float(np.median(values)), values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--count", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    raw = ManhattanSolver(dataclasses.replace(SolverConfig(), covariance_scale=1.0))
    mean_raw, median_raw, _ = mean_nees(raw, args.count, args.seed)
    scale = mean_raw / 3.0
    print(f"raw mean NEES {mean_raw:.3f} (median {median_raw:.3f}) over {args.count} maps, seed {args.seed}")
    print(f"fitted covariance_scale = {scale:.4f}")
    fitted = ManhattanSolver(dataclasses.replace(SolverConfig(), covariance_scale=scale))
    mean_fit, median_fit, values = mean_nees(fitted, args.count, args.seed + 1)
    print(f"held-out (seed {args.seed + 1}): mean NEES {mean_fit:.3f}, median {median_fit:.3f}, "
          f"fraction inside the 95% chi2(3) bound {np.mean(values < 7.815):.3f}")


if __name__ == "__main__":
    main()
