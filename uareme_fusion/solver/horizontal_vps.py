"""Horizontal vanishing points of one image by sequential consensus (J-linkage-like, greedy).

Every proposal (an intersection of two non-vertical segments) scores the weight of the segments
that point at it, S(x) = sum_i w_i exp(-a_i^2 / (2 s_i^2)) (a_i the angle between segment i and the
line from its midpoint to x, s_i its end point noise angle floored at `min_angle_deg`, as for the
zenith). The best proposal is refined by weighted least squares over its inliers (a_i < 3 s_i),
its inliers are removed, and the search repeats while a proposal holds `min_share` of the weight.
Counting the segments through a point, rather than pairs meeting near a height, keeps crossings of
two facades' edges (many pairs, each through a different point) from outvoting a real VP whose
pairs, being nearly parallel, meet imprecisely.

Each finite VP carries the covariance of its position from its inliers (`VanishingPoint.cov`,
`zenith.point_covariance`) and its distance from them (`VanishingPoint.distance`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .zenith import (
    floored_std,
    least_squares_vp,
    miss_angles,
    point_covariance,
    unit_points,
    vp_likelihood,
    vp_support,
)


@dataclass(frozen=True)
class VanishingPoint:
    point: np.ndarray
    """Unit homogeneous point (caller's coordinates)."""
    support: float
    """S of the module docstring: the weight of the segments that point at it."""
    n_inliers: int
    cov: np.ndarray | None = None
    """2x2 covariance of the finite point point[:2] / point[2] (`zenith.point_covariance`); None at infinity."""
    distance: float = float("inf")
    """Weighted mean distance from the finite point to its segments' midpoints (caller's units): an
    angle seen from its segments moves it by about this times the angle; inf at infinity."""


def fitted_vp(ends: np.ndarray, lines: np.ndarray, weights: np.ndarray, std_rad: np.ndarray, members: np.ndarray,
              support: float | None = None) -> VanishingPoint:
    """The VP of the segments `members` (indices or a mask) of `ends` (N, 2, 2) with `lines`, `weights`
    and floored miss-angle stds `std_rad`: weighted least squares (w / s^2) and its covariance. Its
    support is `support`, else S of all the segments at the fitted point (`zenith.vp_support`)."""
    members = np.flatnonzero(members) if members.dtype == bool else members
    point = least_squares_vp(lines[members], weights[members] / std_rad[members] ** 2)
    if support is None:
        support = float(vp_support(miss_angles(ends, point[None]), std_rad, weights)[0])
    cov = point_covariance(ends[members], point, std_rad[members])
    distance = float("inf")  # a VP at infinity: no covariance, no finite distance (`point_covariance`)
    if cov is not None:
        reach = np.linalg.norm(point[:2] / point[2] - ends[members].mean(axis=1), axis=1)
        distance = float(np.average(reach, weights=np.maximum(weights[members], 1e-300)))
    return VanishingPoint(point, support, len(members), cov, distance)


def horizontal_vps(ends: np.ndarray, weights: np.ndarray, lines: np.ndarray, angle_std_rad: np.ndarray,
                   proposals: np.ndarray, max_vps: int = 3, min_share: float = 0.08,
                   min_angle_deg: float = 1.0) -> list[VanishingPoint]:
    """Up to `max_vps` VPs of segments `ends` (N, 2, 2) with `lines` (N, 3, [a, b] unit) from the
    homogeneous `proposals` (P, 3), strongest first (module docstring)."""
    if len(proposals) == 0:
        return []
    s = floored_std(angle_std_rad, min_angle_deg)
    angle = miss_angles(ends, unit_points(proposals))
    inlier_angle = angle < 3 * s[None]
    likelihood = vp_likelihood(angle, s)
    alive = np.ones(len(ends), bool)
    found: list[VanishingPoint] = []
    for _ in range(max_vps):
        score = likelihood @ (weights * alive)
        k = int(np.argmax(score))
        inliers = inlier_angle[k] & alive
        if score[k] < min_share * weights.sum() or inliers.sum() < 2:
            break
        alive &= ~inliers
        found.append(fitted_vp(ends, lines, weights, s, inliers, float(score[k])))
    return found
