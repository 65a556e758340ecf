"""The zenith (vertical vanishing point) of one image from its segments, by consensus.

Vertical edges of buildings are many and long, so their vanishing point is the most reliable one in a
street scene; a first guess from elsewhere (the Manhattan solve) can be far off when its focal
length or axes are wrong. Every pair of near-vertical segments (within `candidate_deg` of the image
vertical) proposes a zenith z at its intersection; the first guess and "straight up at infinity"
are proposals too. Each proposal scores

    S(z) = P(roll(z)) sum_i w_i exp(-a_i^2 / (2 s_i^2)),

a_i the angle between segment i and the line from its midpoint to z, s_i the angle its end point
noise allows (floored at `min_angle_deg`), and P a Gaussian prior of std `roll_prior_deg` on the
angle between the image direction of up (from the principal point towards z) and the image vertical:
photos are mostly held upright (ECD's largest is 15 deg). Proposals inside the image are dropped: a
zenith in view leaves the horizon out of it (and segments meeting inside the image are mostly ground
markings or texture). The best proposal is refined by weighted
least squares over its inliers (a_i < 3 s_i), twice.

Points are homogeneous 3-vectors in the caller's coordinates (centred, scaled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ZenithConfig:
    candidate_deg: float = 40.0
    """Segments within this of the image vertical propose and score zeniths."""
    max_candidates: int = 120
    """The heaviest candidates proposing zeniths (pairs grow as the square)."""
    min_angle_deg: float = 1.0
    """Floor of the angle a segment may miss the zenith by (end point noise, bent edges)."""
    roll_prior_deg: float = 20.0
    """Std of the Gaussian prior on the image up direction's angle from the image vertical."""
    refinements: int = 2


@dataclass(frozen=True)
class Zenith:
    point: np.ndarray
    """Unit homogeneous zenith (caller's coordinates), oriented so that point[:2] points to the sky
    for a finite zenith above the image (the sign is fixed by the caller's up)."""
    inliers: np.ndarray
    """Boolean mask of the segments that point at it."""
    n_effective: float
    """Kish effective number of the inlier segments."""
    cov: np.ndarray | None
    """2x2 covariance of the finite zenith point[:2] / point[2] from its inliers (`point_covariance`);
    None at infinity or when singular."""


def segment_lines(ends: np.ndarray) -> np.ndarray:
    """Homogeneous lines (N, 3) through end points (N, 2, 2), scaled so that [a, b] is unit."""
    h = np.concatenate([ends, np.ones(ends.shape[:2] + (1,))], axis=2)
    l = np.cross(h[:, 0], h[:, 1])
    return l / np.maximum(np.linalg.norm(l[:, :2], axis=1, keepdims=True), 1e-300)


def miss_angles(ends: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(P, N) angles (rad, 0..pi/2) between each segment and the line from its midpoint to each point."""
    mid = ends.mean(axis=1)
    d = ends[:, 1] - ends[:, 0]
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    to_x = points[:, None, :2] - mid[None] * points[:, None, 2:3]
    to_x = to_x / np.maximum(np.linalg.norm(to_x, axis=2, keepdims=True), 1e-300)
    sin = np.abs(d[None, :, 0] * to_x[..., 1] - d[None, :, 1] * to_x[..., 0])
    return np.arcsin(np.minimum(sin, 1.0))


def floored_std(angle_std_rad: np.ndarray, min_angle_deg: float) -> np.ndarray:
    """Segments' miss-angle stds floored at `min_angle_deg` (end point noise alone understates bent
    edges and misgrouped segments)."""
    return np.maximum(angle_std_rad, math.radians(min_angle_deg))


def unit_points(points: np.ndarray) -> np.ndarray:
    """Homogeneous points (P, 3) scaled to unit length."""
    return points / np.maximum(np.linalg.norm(points, axis=1, keepdims=True), 1e-300)


def vp_likelihood(miss_rad: np.ndarray, std_rad: np.ndarray) -> np.ndarray:
    """Gaussian support exp(-(a / s)^2 / 2) of segments missing a point by `miss_rad` (`miss_angles`),
    each with angle std `std_rad` (N,); summed with the segments' weights it scores the point."""
    return np.exp(-0.5 * (miss_rad / std_rad) ** 2)


def vp_support(miss_rad: np.ndarray, std_rad: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """S = sum_i w_i exp(-(a_i / s_i)^2 / 2) of each point from its segments' miss angles `miss_rad`
    (P, N) (`miss_angles`): the weight of the segments that point at it."""
    return vp_likelihood(miss_rad, std_rad) @ weights


def least_squares_vp(lines: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The unit point z minimising sum w (l . z)^2 (lines with [a, b] unit)."""
    M = (lines * weights[:, None]).T @ lines
    return np.linalg.eigh(M)[1][:, 0]


def point_covariance(ends: np.ndarray, point: np.ndarray, angle_std_rad: np.ndarray) -> np.ndarray | None:
    """The 2x2 covariance of the finite VP `point` (homogeneous) of segments `ends` (n, 2, 2), each
    with miss-angle std `angle_std_rad`; None at infinity or when singular.

    The inverse of the information sum_i g_i g_i^T / s_i^2, g_i = d_i^perp / r_i the gradient of
    segment i's miss angle with respect to x (d_i its unit direction, r_i its midpoint's distance to
    x), times the Birge ratio chi^2 / (n - 2) of the miss angles when above 1 (segments that scatter
    more than their noise says). A far VP is precise along its direction from the segments and
    imprecise across it: its height along the image up is uncertain by about |x| times an angle."""
    if abs(point[2]) < 1e-9:
        return None
    x = point[:2] / point[2]
    d = ends[:, 1] - ends[:, 0]
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    v = x - ends.mean(axis=1)
    r = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
    g = np.stack([-d[:, 1], d[:, 0]], axis=1) / r[:, None]
    info = (g / angle_std_rad[:, None] ** 2).T @ g
    if np.linalg.cond(info) > 1e12:
        return None
    miss = (d[:, 0] * v[:, 1] - d[:, 1] * v[:, 0]) / r
    n = len(ends)
    birge = float(np.sum((miss / angle_std_rad) ** 2)) / (n - 2) if n > 2 else 1.0
    return max(birge, 1.0) * np.linalg.inv(info)


def roll_rad(points: np.ndarray) -> np.ndarray:
    """Angle between the image line from the centre (origin) to each point and the image vertical."""
    return np.arctan2(np.abs(points[:, 0]), np.abs(points[:, 1]))


def estimate_zenith(ends: np.ndarray, weights: np.ndarray, angle_std_rad: np.ndarray, guess: np.ndarray,
                    half_size: np.ndarray, config: ZenithConfig | None = None) -> Zenith | None:
    """The zenith of segments `ends` (N, 2, 2) in centred coordinates (module docstring); `guess` is a
    homogeneous first guess whose [:2] points to the sky; `half_size` the image's half width and half
    height in those coordinates (proposals inside the image are dropped). None with fewer than two
    candidates."""
    cfg = config or ZenithConfig()
    d = ends[:, 1] - ends[:, 0]
    off_vertical = np.arctan2(np.abs(d[:, 0]), np.abs(d[:, 1]))
    vertical = off_vertical < math.radians(cfg.candidate_deg)
    cand = np.flatnonzero(vertical)
    if len(cand) < 2:
        return None
    top = cand[np.argsort(-weights[cand])][: cfg.max_candidates]
    lines = segment_lines(ends)
    i, j = np.triu_indices(len(top), 1)
    proposals = np.cross(lines[top[i]], lines[top[j]])
    proposals = unit_points(np.concatenate([proposals, guess[None], np.array([[0.0, 1.0, 0.0]])]))
    inside = np.all(np.abs(proposals[:, :2]) < half_size * np.abs(proposals[:, 2:3]), axis=1)
    proposals = proposals[~inside]
    s_all = floored_std(angle_std_rad, cfg.min_angle_deg)
    score = np.zeros(len(proposals))
    for start in range(0, len(proposals), 2048):
        a = miss_angles(ends[cand], proposals[start:start + 2048])
        score[start:start + 2048] = vp_support(a, s_all[cand], weights[cand])
    score *= np.exp(-0.5 * (roll_rad(proposals) / math.radians(cfg.roll_prior_deg)) ** 2)
    z = proposals[int(np.argmax(score))]
    for _ in range(cfg.refinements + 1):
        inliers = (miss_angles(ends, z[None])[0] < 3 * s_all) & vertical
        if inliers.sum() < 2:
            return None
        z = least_squares_vp(lines[inliers], weights[inliers] / s_all[inliers] ** 2)
    z = z if z[:2] @ guess[:2] >= 0 else -z
    wv = weights[inliers]
    return Zenith(z, inliers, float(wv.sum() ** 2 / max(float(wv @ wv), 1e-300)),
                  point_covariance(ends[inliers], z, s_all[inliers]))
