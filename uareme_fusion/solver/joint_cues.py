"""The cues of the joint solve (`joint.py`): each one's cost E_c, derivatives, weight a_c and information.

A cue holds its measurements' moments (the normals' of `moments.py`, the segments' of `lines.py`), its
effective number of independent measurements n_c and the constant s_c of its covariance; `joint.JointSolver`
sets a_c = n_c / (s_c E_c*) at a rotation and sums a_c H_c (module docstring of `joint.py`). The lines'
robust reweighting and their clutter discount live here too (`LineCueConfig`).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .lines import (RANDOM_LINES_COST, LineMoments, cauchy_line_cost, cauchy_reweighted, inlier_fraction,
                    line_cost_gradient_hessian, line_information, normalised_line_cost)
from .manhattan import RANDOM_NORMALS_COST, surface_regions
from .quartic import gradient_hessian, normalised_cost


@dataclass(frozen=True)
class LineCueConfig:
    """How much the segments are trusted (units in the names)."""

    covariance_scale: float = 0.4
    """s_L: ICL-NUIM kt3 (given K, ground truth) gives NEES 0.95 with 1.0; 0.4 brings it near 2.4."""
    independent_segments: float = 40.0
    """Cap on n_L: segments share errors (lens distortion, one edge split in several segments)."""
    min_cost: float = 2e-5
    """Floor on E_L* in a_L (about 1 deg of plane error): exact synthetic lines claim no 0-degree answer."""
    min_effective_segments: float = 4.0
    """Fewer effective segments than this: the line cue is reported absent."""
    clutter_power: float = 2.0
    """The lines' information is multiplied by q^power, q = (f - f0) / (1 - f0) clipped to [0, 1], f the weighted
    fraction of segments along some axis at the solution and f0 what random segments reach (plus
    `chance_sigmas` of its spread): segments
    that fit a Manhattan frame no better than chance say little, however many there are."""
    random_inlier_fraction: float = 0.23
    """f0: the inlier fraction the solver reaches on segments in random directions (synthetic, 8 seeds:
    0.24, 0.23, 0.16 for 40, 80, 150 segments; the robust solver fits clutter better than the plain
    sextic did, which reached 0.16, 0.18, 0.13)."""
    chance_sigmas: float = 4.0
    """f0 in q is raised by this many binomial standard deviations sqrt(f0 (1 - f0) / n), n the effective
    number of segments capped at `independent_segments` (segments share errors, and so does their chance
    fit: one edge split in several, parallel clutter): an inlier fraction within the spread of what clutter
    reaches says nothing (75 segments, 15 of them on axes: a wrong frame explained 30 %, the true one 25 %).
    Real frames whose segments carry no frame reach more than random directions do: EuRoC V1_01 micro cam0
    (a cluttered room, lines-alone tilt 8.6 deg off) f 0.35-0.41 (10th-90th percentile, ~106 segments), TUM
    fr1 rpy train (a desk) up to 0.47 at the 90th percentile, against 0.76-0.88 on ICSL and ICL kt3, whose
    segments carry the frame. With 2 sigmas and n uncapped (f0 0.31 on EuRoC) q^2 was 0.004-0.02 there,
    and as the lines' information before the discount is 2000-3000 times the network normals' there, their
    share was 0.97: joint ARE 1.16 deg against 0.65 for the normals alone (paired +0.51, +0.14 .. +0.57), TUM
    train joint NEES 23.5. With 4 sigmas of n <= 40 (f0 0.50): EuRoC joint 0.65 (the normals'), TUM train
    joint ARE 11.05 -> 10.82 deg (normals alone 11.31), NEES 23.5 -> 4.5; ICSL 0.32, kt3 0.29 and ECD AUC
    90.2 % unchanged (real, `bench realdata` cue-set rotations, single backend)."""
    robust_sine: float = 0.02
    """Cauchy scale on c_j = min_k |p_j . r_k| (about 1.1 deg of plane angle; see the module docstring).
    ICSL corridor, given K, every second frame: RGB vs depth rotation mean 2.85 deg without, 2.10 with
    0.02, 2.13 with 0.01 and with 0.035 (not sensitive)."""
    candidate_sine: float = 0.1
    """The Cauchy scale when the global candidates are scored: about the distance from a rotation to its
    nearest candidate (400 over one symmetric cell, about 6 deg), so that the one nearest the true frame
    scores as explaining its segments."""
    min_robust_segments: float = 20.0
    """Fewer effective segments than this are not reweighted (the plain sextic): with few segments the
    Cauchy loss can fit a subset confidently (`eval` of a simulated room whose frames 3-5 have lines
    only: ARE max 6.7 deg reweighting all, 2.6 without; a threshold of 20 undid the gain on ICSL streams,
    whose 320 px segments number about 10-25)."""
    min_robust_segments_beside_normals: float = 15.0
    """`min_robust_segments` when the frame also has a normal cue (the normals then anchor the joint
    score): ICSL-more RGB-only streams single / mekf / smoother 2.16 / 2.19 / 2.19 deg at 15 against
    6.16 / 6.29 / 5.96 at 20 (`bench horizon`); lines-only frames keep 20."""
    robust_iterations: int = 3
    """Reweightings at `robust_sine` from each start, after one at `candidate_sine` from a global candidate
    (0: the plain sextic)."""


class _Cue:
    """One cue's part of J: its cost E_c, derivatives, weight a_c and information a_c q H_c."""

    name = ""
    random_cost = 1.0
    """E_c of a rotation unrelated to the measurements (for `quality`)."""

    def __init__(self, moments, n_effective: float, scale: float, min_cost: float):
        self.moments, self.n_effective, self.scale, self.min_cost = moments, n_effective, scale, min_cost
        self.alpha = 1.0
        self.discount = 1.0
        """Applied to the information, its square root to the weight in J (`_steering_weights`)."""
        self.info = np.zeros((3, 3))

    def cost(self, R):
        raise NotImplementedError

    def derivatives(self, R) -> tuple[float, np.ndarray, np.ndarray]:
        raise NotImplementedError

    def gradient_hessian(self, R) -> tuple[np.ndarray, np.ndarray]:
        """`derivatives` without the cost, for the solver's iterations (a cue whose cost is a separate
        evaluation skips it there)."""
        return self.derivatives(R)[1:]

    def information_hessian(self, R) -> np.ndarray:
        """The H_c of the covariance (the cost's Hessian unless a cue says otherwise)."""
        return self.derivatives(R)[2]

    def set_alpha(self, R, discounted: bool = True) -> None:
        """a_c = n_c / (s_c max(E*, floor)) at the rotation R (`discounted`: see `_LineCue.set_alpha`)."""
        self.alpha = self.n_effective / (self.scale * max(float(self.cost(R)), self.min_cost))

    def summary(self) -> dict:
        raise NotImplementedError

    def no_information_reason(self) -> str:
        """Why the cue gives no information at the solution ("" when it gives some, or cannot tell)."""
        return ""

    def robust_cost(self, R, coarse: bool = False):
        """E_c~ of the module docstring, for choosing among minima (one rotation or a stack); `coarse`:
        as seen at the spacing of the global candidates."""
        return self.cost(R)

    def reweighted(self, R, coarse: bool = False) -> "_Cue":
        """A copy of the cue, its measurements reweighted at R for a robust cue (its a_c is then set
        on the copy: one start's weights never leak into another's)."""
        return copy.copy(self)

    def labelled(self, R: np.ndarray) -> np.ndarray:
        """The Manhattan labelling of the solution this cue asks for (the same frame; R itself for most)."""
        return R


class _NormalCue(_Cue):
    name = "normals"
    random_cost = RANDOM_NORMALS_COST
    regions_cost = None
    """`NormalMap.regions_cost` of the map (`manhattan.surface_regions`)."""
    _tensor = None

    def set_alpha(self, R, discounted: bool = True) -> None:
        """a_c of any cue, its n_c shrunk by `surface_regions` at the cost there (as the normals-only solver)."""
        cost = float(self.cost(R))
        self.alpha = surface_regions(self.n_effective, cost, self.regions_cost) / (self.scale * max(cost, self.min_cost))

    def cost(self, R):
        cost = normalised_cost(self.moments.G, self.moments.total_weight, R)
        return np.clip(cost, 0.0, 1.0) if np.ndim(cost) else min(max(cost, 0.0), 1.0)  # (np.clip: 4 us a scalar)

    def derivatives(self, R):
        return (float(self.cost(R)),) + self.gradient_hessian(R)

    def gradient_hessian(self, R):
        if self._tensor is None:  # the moments' (3, 3, 3, 3) form, once per cue (copies share it)
            self._tensor = self.moments.tensor()
        return gradient_hessian(self._tensor, self.moments.total_weight, R)

    def summary(self) -> dict:
        return {"valid_pixels": self.moments.n_valid}


class _LineCue(_Cue):
    name = "lines"
    random_cost = RANDOM_LINES_COST

    def __init__(self, moments: LineMoments, config: LineCueConfig, base: LineMoments | None = None,
                 beside_normals: bool = False):
        super().__init__(moments, min(moments.n_effective, config.independent_segments), config.covariance_scale,
                         config.min_cost)
        self.config = config
        self.beside_normals = beside_normals
        self.fit_fractions: tuple[float, float] | None = None
        """(f, f0) of the last discount: the inlier fraction at the rotation, and what chance reaches."""
        self.min_robust_segments = (config.min_robust_segments_beside_normals if beside_normals
                                    else config.min_robust_segments)
        self.base = moments if base is None else base
        """The segments' moments with their own weights (`moments` may be Cauchy-reweighted)."""

    def robust_cost(self, R, coarse: bool = False):
        return cauchy_line_cost(self.base, R, self.config.candidate_sine if coarse else self.config.robust_sine)

    def reweighted(self, R, coarse: bool = False) -> "_LineCue":
        if not self.config.robust_iterations or self.base.n_effective < self.min_robust_segments:
            return copy.copy(self)
        scale = self.config.candidate_sine if coarse else self.config.robust_sine
        return _LineCue(cauchy_reweighted(self.base, R, scale), self.config, self.base, self.beside_normals)

    def cost(self, R):
        return normalised_line_cost(self.moments, R)

    def derivatives(self, R):
        return line_cost_gradient_hessian(self.moments, R)

    def information_hessian(self, R) -> np.ndarray:
        return line_information(self.moments, R)

    def set_alpha(self, R, discounted: bool = True) -> None:
        """As for any cue, plus the clutter discount q^power (`LineCueConfig.clutter_power`); 1 when not
        `discounted` (the joint solve's coarse round, `JointSolver._reweighted_minimum`)."""
        super().set_alpha(R)
        if not discounted:
            self.discount = 1.0
            return
        f0 = self.config.random_inlier_fraction
        n = max(min(self.base.n_effective, self.config.independent_segments), 1.0)
        f0 = min(f0 + self.config.chance_sigmas * np.sqrt(f0 * (1.0 - f0) / n), 0.99)
        f = inlier_fraction(self.base, R)
        self.fit_fractions = (f, f0)
        q = float(np.clip((f - f0) / (1.0 - f0), 0.0, 1.0))
        self.discount = q**self.config.clutter_power

    def summary(self) -> dict:
        out = {"segments": self.base.n_segments, "effective_segments": self.base.n_effective}
        if self.fit_fractions is not None:
            out["inlier_fraction"], out["chance_inlier_fraction"] = self.fit_fractions
        return out

    def no_information_reason(self) -> str:
        if self.discount > 0 or self.fit_fractions is None:
            return ""
        f, f0 = self.fit_fractions
        return (f"the segments fit a Manhattan frame no better than chance ({100 * f:.0f} % of them on an axis, "
                f"chance reaches {100 * f0:.0f} %)")
