"""Uncertainty-weighted Manhattan rotation from a normal map (paper Sec. 3.1).

`ManhattanSolver.solve` returns `R_cm` (Manhattan axes as columns, in camera coordinates) and the
covariance of the right perturbation `R_cm_true = R_cm @ Exp(delta)`, in rad^2.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..rotations import R_CM_UPRIGHT, is_rotation, nearest_symmetric, project_to_so3, rotation_problem
from ..types import NormalMap, VisualRotation
from .levenberg import levenberg_marquardt_so3
from .moments import NormalMoments, normal_moments
from .quartic import gradient_hessian, normalised_cost

RANDOM_NORMALS_COST = 0.4
"""Expected normalised cost of isotropic random normals: 1 - 3 E[c^4] = 1 - 3/5."""



@dataclass(frozen=True)
class SolverConfig:
    """Parameters of `ManhattanSolver` (units in the names)."""

    max_iterations: int = 50
    step_tolerance_rad: float = 1e-6
    """Levenberg-Marquardt stops once a step is shorter (taking that step). Its steps shrink quadratically
    near a minimum, so what is left is ~1e-12 rad: 1e-8 took 11 % more iterations for rotations equal to
    1e-11 (the bench pipeline's room walk, normals and lines)."""
    global_candidates: int = 400
    """Rotations tried inside one of the 24 symmetric cells of SO(3) when no prior is given."""
    global_refinements: int = 3
    """How many of the best candidates are refined by Levenberg-Marquardt."""
    independent_regions: float = 120.0
    """Effective number of independent pixels in a fully valid map: normal errors are spatially
    correlated, so the covariance shrinks with this rather than with the pixel count."""
    covariance_scale: float = 0.85
    """Fitted so that NEES averages 3 on synthetic maps with correlated noise (tools/calibrate_solver.py)."""
    floor_std_rad: float = 1.75e-3
    """Error floor (0.1 deg) added in quadrature for what the model leaves out (intrinsics, rendering,
    sensor calibration): a perfect synthetic map does not claim a 0.001-degree answer."""
    max_variance_rad2: float = 1.0
    """Cap on any variance: an unobservable axis (one visible Manhattan direction) gets this."""
    stream_global_starts: int = 1
    """With a prior (a stream's frame), how many global candidates are also refined beside the prior:
    the prior is a start, not an anchor."""
    stream_candidate_ratio: float = 0.7
    """With a prior, the lines' best global candidate (coarse Cauchy cost) is also refined when its cost is
    under this fraction of the prior's: clearly better explained elsewhere (ICL kt3 RGB, every frame
    tried at 1.0: 60 ms per frame instead of 31 and ARE 0.303 instead of 0.288)."""
    jump_margin: float = 9.0
    """A stream's frame leaves the prior's own minimum for another only when that one's robust score
    (twice a negative log-likelihood, `joint._robust_scores`) is lower by more than this (about 1 %
    as likely); the jump is then flagged (`VisualRotation.jump_deg`)."""


@lru_cache(maxsize=8)
def _cell_candidates(count: int) -> np.ndarray:
    """`count` rotations spread over the symmetric cell around identity (seeded, so deterministic)."""
    R = Rotation.random(count, random_state=12345).as_matrix()
    R_cell, _ = nearest_symmetric(R, np.broadcast_to(np.eye(3), R.shape))
    R_cell.setflags(write=False)
    return R_cell


class ManhattanSolver:
    """Solves paper eq. 1 by Levenberg-Marquardt over the moment form; see docs/design.md."""

    def __init__(self, config: SolverConfig | None = None):
        self.config = config or SolverConfig()

    def solve(self, normal_map: NormalMap, R_init: np.ndarray | None = None) -> VisualRotation:
        """Rotation and covariance for one normal map; `R_init` (3, 3) is an `R_cm` guess or None."""
        return self.solve_arrays(normal_map.normals, normal_map.kappa, R_init, t_s=normal_map.t_s,
                                 independent_regions=normal_map.independent_regions,
                                 regions_cost=normal_map.regions_cost)

    def solve_arrays(self, normals, kappa=None, R_init=None, t_s: float = float("nan"),
                     independent_regions: float | None = None, regions_cost: float | None = None) -> VisualRotation:
        """As `solve`, on arrays; `independent_regions` and `regions_cost` as in NormalMap."""
        t0 = time.perf_counter()
        with np.errstate(over="ignore", invalid="ignore"):
            moments = normal_moments(normals, kappa)
        if not np.all(np.isfinite(moments.G)):  # huge finite kappa: the weighted sums overflowed
            moments = normal_moments(normals, _scaled_kappa(kappa))
        t1 = time.perf_counter()
        n_pixels = int(np.prod(np.shape(normals)[:-1]))
        if moments.n_valid == 0 or not moments.total_weight > 0:
            raise InputError(
                f"No valid normals in a map of shape {np.shape(normals)}: all {n_pixels} pixels are NaN, "
                "zero-length, or have kappa <= 0"
            )
        if R_init is None:
            R_cm, iterations, converged = self._solve_global(moments)
        else:
            R_cm, iterations, _, converged = self._refine(moments, _check_rotation(R_init))
        cost = float(np.clip(normalised_cost(moments.G, moments.total_weight, R_cm), 0.0, 1.0))
        cov = self._covariance(moments, R_cm, cost, n_pixels, independent_regions or self.config.independent_regions,
                               regions_cost)
        t2 = time.perf_counter()
        return VisualRotation(
            R_cm=R_cm,
            cov=cov,
            cost=cost,
            iterations=iterations,
            n_valid=moments.n_valid,
            n_invalid=moments.n_invalid,
            quality=float(np.clip(1.0 - cost / RANDOM_NORMALS_COST, 0.0, 1.0)),
            converged=converged,
            t_s=t_s,
            timing_ms={"moments": 1e3 * (t1 - t0), "optimise": 1e3 * (t2 - t1)},
        )

    def _solve_global(self, moments: NormalMoments) -> tuple[np.ndarray, int, bool]:
        """No identity assumption: score rotations over one symmetric cell, refine the best few."""
        cfg = self.config
        candidates = _cell_candidates(cfg.global_candidates)
        costs = normalised_cost(moments.G, moments.total_weight, candidates)
        best = None
        total_iterations = 0
        for i in np.argsort(costs)[: cfg.global_refinements]:
            R, iterations, cost, converged = self._refine(moments, candidates[i])
            total_iterations += iterations
            if best is None or cost < best[1]:
                best = (R, cost, converged)
        R_cm, _ = nearest_symmetric(best[0], R_CM_UPRIGHT)
        return R_cm, total_iterations, best[2]

    def _refine(self, moments: NormalMoments, R0: np.ndarray) -> tuple[np.ndarray, int, float, bool]:
        """Levenberg-Marquardt on SO(3) with right increments; each iteration is O(1) in pixels."""
        G, W, T = moments.G, moments.total_weight, moments.tensor()
        return levenberg_marquardt_so3(lambda R: normalised_cost(G, W, R), lambda R: gradient_hessian(T, W, R),
                                       R0, self.config.max_iterations, self.config.step_tolerance_rad)

    def _covariance(self, moments: NormalMoments, R_cm: np.ndarray, cost: float, n_pixels: int,
                    independent_regions: float, regions_cost: float | None = None) -> np.ndarray:
        """Absolute covariance of delta: scale * residual / N_eff * H^-1 plus a floor, eigenvalues capped.

        Treating the cost as sum_i w_i theta_i^2 with errors of variance proportional to 1/w_i gives
        cov = (E / N) H^-1 for the normalised cost E and Hessian H; correlated errors replace N with
        an effective number of independent pixels (paper eq. 7 scaled to absolute units).
        """
        cfg = self.config
        _, hess = gradient_hessian(moments.tensor(), moments.total_weight, R_cm)
        valid_fraction = moments.n_valid / max(n_pixels, 1)
        n_eff = min(float(moments.n_valid), independent_regions * valid_fraction)
        n_eff = surface_regions(max(n_eff, 1.0), cost, regions_cost)
        eigval, eigvec = np.linalg.eigh(0.5 * (hess + hess.T))
        residual = cfg.covariance_scale * cost / n_eff
        var = np.divide(residual, eigval, out=np.full(3, np.inf), where=eigval > 0) + cfg.floor_std_rad**2
        var = np.minimum(var, cfg.max_variance_rad2)
        return (eigvec * var) @ eigvec.T


def surface_regions(n_eff: float, cost: float, regions_cost: float | None) -> float:
    """A network map's independent errors at residual `cost`: `n_eff` up to `regions_cost`, then
    n_eff * regions_cost / cost (`NormalMap.regions_cost`: a map that badly explained is wrong by whole
    surfaces, and the rotation error grows as the residual rather than as its square root); `n_eff` when
    `regions_cost` is None."""
    if regions_cost is None or not cost > regions_cost:
        return n_eff
    return n_eff * regions_cost / cost


def _scaled_kappa(kappa) -> np.ndarray:
    """kappa divided by a power of two that brings its largest finite value to 1 or below.

    The rotation, cost and covariance depend on the weights only up to a common factor (the cost is
    normalised by the total weight), so this changes nothing but keeps the moment sums finite for
    any finite kappa (e.g. float32 3e38). Only used when the plain sums overflow."""
    kappa = np.asarray(kappa)
    finite = np.where(np.isfinite(kappa), np.abs(kappa), 0)
    exponent = np.frexp(np.float64(finite.max(initial=0.0)))[1]
    return np.ldexp(kappa.astype(np.float64) if kappa.dtype == np.float32 else kappa, -int(exponent))


def _check_rotation(R) -> np.ndarray:
    problem = rotation_problem(R, atol=1e-5)
    if problem is not None:
        raise InputError(f"Expected R_init as a rotation matrix: {problem}")
    R = np.asarray(R, dtype=float)
    # A prior accepted up to 1e-5 is made a rotation to rounding, which the solver's logs assume.
    return R if is_rotation(R, atol=1e-12) else project_to_so3(R)


_DEFAULT_SOLVER = ManhattanSolver()


def solve_manhattan(normals, kappa=None, R_init=None, config: SolverConfig | None = None) -> VisualRotation:
    """Camera-to-Manhattan rotation and its covariance from a normal map.

    `normals` (H, W, 3) or (N, 3) float in the camera frame (OpenCV: x right, y down, z forward),
    or a `NormalMap` (which carries kappa and its source's error correlation);
    `kappa` matching (H, W) or (N,) confidence >= 0, or None for equal weights; `R_init` an `R_cm`
    guess (3, 3) or None for a global search. Returns a `VisualRotation` with `R_cm` (columns are the
    Manhattan axes in camera coordinates) and `cov` (3, 3, rad^2) of `delta` in
    `R_cm_true = R_cm @ Exp(delta)`. NaN/zero-length normals and NaN kappa are ignored and counted
    in `n_invalid`; a map with no valid pixel raises `InputError` (a `ValueError`).

    >>> import numpy as np
    >>> from uareme_fusion.sim.normal_maps import manhattan_normal_map
    >>> from uareme_fusion.rotations import manhattan_symmetries
    >>> R_cm_true = manhattan_symmetries()[0]
    >>> nm = manhattan_normal_map(R_cm_true, np.random.default_rng(0), height=48, width=64, noise_deg=5.0)
    >>> v = solve_manhattan(nm)
    >>> v.R_cm.shape, v.cov.shape, bool(np.all(np.linalg.eigvalsh(v.cov) > 0))
    ((3, 3), (3, 3), True)
    """
    solver = _DEFAULT_SOLVER if config is None else ManhattanSolver(config)
    if isinstance(normals, NormalMap):
        if kappa is not None:
            raise InputError("Pass kappa inside the NormalMap, not beside it")
        return solver.solve(normals, R_init)
    return solver.solve_arrays(normals, kappa, R_init)


IMAGE_UP_C = np.array([0.0, -1.0, 0.0])
"""Up in an upright OpenCV camera (y points down)."""


def up_candidate(R_cm: np.ndarray, up_hint_c: np.ndarray = IMAGE_UP_C) -> tuple[int, np.ndarray]:
    """The signed Manhattan axis (a column of `R_cm`, camera frame) nearest `up_hint_c`.

    Without gravity this is the best guess of "up": by default the axis nearest image up.
    Returns `(column index, unit vector in the camera frame)`.
    """
    dots = np.asarray(R_cm, float).T @ np.asarray(up_hint_c, float)
    k = int(np.argmax(np.abs(dots)))
    return k, np.sign(dots[k]) * np.asarray(R_cm, float)[:, k]
