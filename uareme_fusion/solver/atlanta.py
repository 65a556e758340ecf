"""The horizon of one image from its segments in an Atlanta world (Lezama et al. 2014; Zhai et al. 2016).

An Atlanta world has one vertical direction and any number of horizontal ones, not necessarily
orthogonal (city streets at several angles). Its vanishing points (VPs) are the zenith z and points
on the horizon. With the principal point c and square pixels, the horizon is the line perpendicular
to the image direction of up (from c towards the zenith), whatever the focal length:

    (H)   n . (x - c) = t,   n = unit image direction of up (towards the sky),

and t (pixels along n from c, negative below the centre) is where the horizontal VPs lie. Steps:
1. the zenith by consensus over pairs of near-vertical segments, with a prior on the camera's roll
   (`solver/zenith.py`); the first guess `up_c` (from the Manhattan solve) is one proposal; n from it;
2. t: horizontal VPs by sequential consensus over the intersections of the other segments
   (`solver/horizontal_vps.py`), each with the covariance of its position, and those J-linkage finds
   besides (`solver/vp_linkage.py`: VPs that the greedy removal of segments hides). t maximises
   log P(t) + sum_k log(pi_k N(v_k; t, s_k^2) + (1 - pi_k) / L) (or its posterior mean near that
   mode, `posterior_window_fraction`, off): a VP at height v_k = n . (x_k - c)
   is on the horizon with probability pi_k = S_k / (S_k + `vp_inlier_support`) (S_k its support),
   else anywhere in the searched range L; s_k^2 = n^T C_k n + (a d_k)^2 + (r u_k)^2, C_k its
   covariance, d_k the mean distance of its segments from it, a `vp_floor_deg` (an error of
   direction that its segments share, so that their number does not shrink it: a VP seen from afar
   moves further), u_k its distance along the horizon from the centre and r `roll_std_deg`: the image
   direction of up is uncertain (ECD's horizons, fitted through their VPs, stand a median 0.5 deg
   and a 90th percentile 1.3 deg off perpendicular to the centre-zenith line), so a far VP tells the
   horizon's direction rather than its height. P(t) is the focal range the zenith allows
   (t = -f^2 / v_z, f within `hfov_range_deg`) times a typical lens (`prior_hfov_deg`, log-normal)
   at t = -f^2 / v_z, its spread widened by the zenith's own uncertainty. Without a VP, t is the mode
   of the pair density sum_ij w_i w_j N(v; v_ij, s_ij^2) of the pairs' intersection heights, s_ij
   their uncertainty from end point noise (near-parallel pairs: large s_ij);
3. the horizon's standard deviation `t_std_px`: the scatter of the pair heights within 3 s_ij of t
   over the root of the effective number of segments behind them, scaled (`AtlantaConfig.std_scale`).
With a finite zenith at height v_z, f^2 = -t v_z (K = [f 0 c; 0 f c; 0 0 1]): `focal_px`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .line_detection import LineSegments
from ..pinhole import focal_from_hfov
from .horizontal_vps import VanishingPoint, horizontal_vps
from .vp_linkage import linkage_vps
from .zenith import ZenithConfig, estimate_zenith, miss_angles, segment_lines


_SAME_VP_DEG = 0.5
"""Homogeneous unit VPs closer than this (angle between the 3-vectors) are the same VP."""


@dataclass(frozen=True)
class AtlantaConfig:
    zenith: ZenithConfig = ZenithConfig()
    """The zenith's consensus search (`solver/zenith.py`)."""
    min_vertical_effective: float = 3.0
    """Fewer effective vertical segments than this: the first guess's up direction is kept."""
    horizontal_min_deg: float = 8.0
    """Segments further than this from vertical take part in the horizon's height."""
    max_pairs_segments: int = 160
    """The heaviest segments used for pairwise intersections (pairs grow as the square)."""
    endpoint_noise_px: float = 1.0
    """Segment end point noise (full-resolution pixels). LSD's end points are good to about half a
    pixel at its working scale (640 px wide on ECD's 1152): about 1 px here. Chosen on ECD's
    odd-numbered images (0.5 / 0.75 / 1.0 / 1.25 / 1.5 px: AUC 86.9 / 87.5 / 88.3 / 85.6 / 87.8 %),
    held out on the even ones 86.7 -> 88.1 % (1.5 -> 1.0 px)."""
    min_vp_distance: float = 6.0
    """A pair counts only when it meets further than this many of each segment's lengths from its midpoint
    (ECD first half, lines only: 1 -> 65.9 %, 4 -> 76.4 %, 6 -> 77.5 %, 8 -> 74.0 %)."""
    height_floor_fraction: float = 0.004
    """Floor on each intersection's height spread, fraction of the image diagonal (the mode's resolution)."""
    height_range_fraction: float = 1.5
    """Horizons searched within this fraction of the image diagonal from the centre."""
    hfov_range_deg: tuple[float, float] = (25.0, 110.0)
    """Fields of view the horizon may imply with a seen zenith (f^2 = -t v_z)."""
    zenith_tolerance_fraction: float = 0.02
    """How far (fraction of the diagonal, Gaussian) t may stray out of that range (zenith uncertainty)."""
    std_scale: float = 1.5
    """Multiplies the horizon's standard deviation (the mode's scatter over the root of its segments):
    chosen on ECD's even-numbered images, where it gives median |error / std| 0.64 (odd-numbered 0.75;
    Gaussian 0.67). A wrong height is not covered by it: 83 % of errors within 2 std, not 95 %."""
    min_pairs_weight_fraction: float = 0.02
    """Below this share of the pair weight in the mode's +-3 sigma window, there is no horizon evidence."""
    max_horizontal_vps: int = 3
    """Horizontal VPs sought by sequential consensus (`solver/horizontal_vps.py`); every J-linkage
    cluster holding `min_vp_share` (`solver/vp_linkage.py`) that none of them explains adds one.
    ECD odd-numbered images, 1000 proposals: J-linkage's 2 / 3 / all (at most 5 there) strongest
    added, AUC 88.6 / 89.3 / 89.9 %; even-numbered (held out) 88.9 / 89.1 / 89.2 %."""
    linkage_proposals: int = 1000
    """Proposals (evenly spaced among the pairs' intersections) whose preference sets J-linkage
    compares. Chosen on ECD's odd-numbered images with 3 J-linkage VPs (1000 / 2000 / 3000: AUC
    89.3 / 88.5 / 89.2 %; even-numbered 89.1 / 88.3 / 89.3 %); sequential consensus alone: odd 88.3,
    even 88.1 %. The AUC moves by about +-0.5 % with the proposals taken."""
    min_vp_share: float = 0.08
    """A horizontal VP needs segments holding this share of the non-vertical segments' weight."""
    prior_hfov_deg: float = 55.0
    """A typical lens: 35 mm-equivalent 35 mm (28 mm: 65 deg, 50 mm: 40 deg). With a seen zenith it
    puts the horizon at t = -f^2 / v_z (module docstring, step 2)."""
    prior_log_focal_std: float = 1.2
    """Std of log f about `prior_hfov_deg`. ECD's focal lengths (from its zenith and horizon) spread
    by a median |log f / f_55| of 0.14 with tails to 0.8 (telephotos); tuned below. Tried instead (ECD
    AUC all / odd / even, against 90.2 / 90.6 / 89.8 %): no lens prior 89.4 / 90.7 / 88.1; the exact
    log-normal in t (t = -f^2 / v_z, std 2.4 in log t) 89.1 / 89.1 / 89.0; a mixture of this prior and
    the t that each pair of horizontal VPs on opposite sides implies if orthogonal (f^2 = -x_1 . x_2),
    half each, 89.9 / 90.3 / 89.5. Adding the pairs' height density to the VPs' (its log, weight 0.1-1):
    90.2-90.0 %, no gain."""
    vp_floor_deg: float = 1.0
    """Floor on the direction in which a VP's segments see it (segments misgrouped, edges not
    straight), the same 1 deg as a segment's miss-angle floor (`ZenithConfig.min_angle_deg`); its
    height std is at least this angle times the VP's distance from its segments (module docstring,
    step 2). It replaced a floor of 0.02 of the diagonal whatever the distance: ECD AUC 89.6 ->
    90.2 % (odd 89.9 -> 90.6, even 89.2 -> 89.8; `bench horizon --ecd-only`); 0.5 / 1 / 1.5 / 2 deg:
    89.9 / 90.2 / 90.2 / 89.9 %, and both halves gain at each of them."""
    roll_std_deg: float = 1.0
    """Std of the horizon's direction about perpendicular to the centre-zenith line (seen zenith). ECD's
    labels are least-squares lines through their hand-labelled horizontal VPs (residuals sum to 0), 0.47
    deg (median) off perpendicular to the labelled zenith, while this zenith's direction is 0.16 deg from
    the labelled one; yet fitting the horizon's angle with its height through the VPs (this std as the
    angle's prior, no per-VP roll term) scores AUC 87.4 % (angle error median 0.35 -> 0.55 deg): the
    VPs' heights are too noisy to tilt the line."""
    roll_std_unseen_deg: float = 3.0
    """The same without a seen zenith (up from the first guess)."""
    vp_inlier_support: float = 1.0
    """Support at which a VP is as likely on the horizon as not (pi_k = 1/2). This, a floor of 0.02
    of the diagonal on a VP's height (since replaced by `vp_floor_deg`), `roll_std_deg` and
    `prior_log_focal_std` are the best on ECD's even-numbered images of a grid
    (floor 0.003-0.02, roll 0.5-1 deg, prior std 0.3-1.2, support 0.3-3): AUC even 86.1 -> 86.7 %,
    held out on the odd-numbered ones 87.0 -> 87.8 % (all 86.5 -> 87.3 %). A wider grid (floor to
    0.08, roll to 2 deg) finds 87.1 % on even that scores 83.2 % on odd: +-1 % is the noise of 52
    images."""
    posterior_window_fraction: float = 0.0
    """With a window w > 0, t is the posterior mean of the VPs' height density within w (fraction of the
    diagonal) of its mode; 0: the mode itself. Off: 0.05 was best on ECD's odd-numbered images (0.035 /
    0.05 / 0.07 / 0.1: AUC 90.74 / 90.88 / 90.62 / 90.22 %, the mode 90.61 %), held out on the even ones
    89.79 -> 89.96 % (all 90.20 -> 90.42 %; `bench horizon`: 90.2 -> 90.4 %, odd 90.6 -> 90.9, even
    89.8 -> 90.0), within the +-0.5 % noise of 52 images, while the ECD focal p90 went 21.9 -> 22.3 % and
    ICSL's RGB-only rotation (no intrinsics) 1.72 -> 1.75 deg (NEES 1.64 -> 1.63, kt3 and horizon_uav
    unchanged). Tried besides
    (ECD all / odd / even against 90.20 / 90.61 / 89.79 %, the VPs as found): the posterior median 90.32 /
    90.74 / 89.90; a tempered posterior (log density / 2) 90.48 / 90.98 / 89.97 (one knob more for noise);
    each VP's height from the profile of its segments' miss angles along the candidate horizon instead of
    its Gaussian (horizon-first, a 1-D search of the VP on each line) 89.46 / 88.96 / 89.97; the inlier
    probability from an a-contrario number of false alarms (binomial tail of the VP's inliers among the
    segments, p 0.01-0.05 a segment, over the proposals) 87.3-89.5 %, every odd score below 89.5; even
    an oracle that keeps exactly the VPs within 2 sd of the true height scores 91.7 / 92.3 / 91.1: the
    VPs' heights, not their selection, limit the score (their z-scores about the truth are calibrated:
    median |z| 0.673); the VPs refitted with angle weights 1 / (s r)^2, inliers within 2 s, 3 rounds
    90.40 / 90.30 / 90.51; the label's own definition (an unweighted mean of the inlier VPs' heights,
    weights var^-gamma, gamma 0-1) 67.6-89.5 %; LSD at 1152 px (noise 0.6 / 1 px) 90.05 / 88.53 %;
    more VPs (`max_horizontal_vps` 5: unchanged; `min_vp_share` 0.05: 89.99 / 89.70 / 90.28);
    `max_pairs_segments` 220: 88.11 %."""


@dataclass(frozen=True)
class AtlantaHorizon:
    line_px: np.ndarray
    """[a, b, c]: a x + b y + c = 0 in pixels, [a, b] unit, positive on the sky side."""
    t_std_px: float
    """Standard deviation of the horizon's position along its normal (pixels)."""
    zenith_px: np.ndarray
    """Homogeneous zenith VP in pixels (third entry 0: at infinity)."""
    n_vertical: float
    """Effective number of vertical segments behind the zenith (0: the first guess's direction)."""
    focal_px: float
    """f from the zenith and the horizon, nan when the zenith is (near) infinity or inconsistent."""
    support: float
    """Share of the pair weight within the mode's +-3 sigma window."""
    focal_std_px: float = float("nan")
    """Std of `focal_px` (`focal_std`): the horizon's and the zenith's heights' relative stds, halved, in
    quadrature (f^2 = -t v_z); nan with `focal_px`."""

    def up_c(self, K: np.ndarray) -> np.ndarray:
        """Unit up in the camera frame that puts the horizon `l ~ K^-T up` on this line."""
        up = np.asarray(K, float).T @ self.line_px
        return up / np.linalg.norm(up)


def _vertical_mask(ends: np.ndarray, zenith: np.ndarray, max_deg: float) -> np.ndarray:
    """Segments whose direction is within `max_deg` of the direction from their midpoint to `zenith`."""
    return miss_angles(ends, zenith[None])[0] < math.radians(max_deg)


def _focal_range_weight(n: np.ndarray, zenith: np.ndarray, n_vertical: float, width: float, cfg: AtlantaConfig):
    """Weight (0..1) of horizon heights by the focal length they imply with the zenith: a seen zenith at
    height v_z puts the horizon at t = -f^2 / v_z, f within `hfov_range_deg` (Gaussian tolerance
    outside). All ones without a seen, finite zenith. `width`: the image width in the scaled units."""
    if n_vertical <= 0 or abs(zenith[2]) <= 1e-12:
        return lambda t: np.ones_like(np.asarray(t, float))
    inv_v_z = float(zenith[2] / (n @ zenith[:2]))
    f_lo, f_hi = (focal_from_hfov(width, a) for a in cfg.hfov_range_deg[::-1])
    lo, hi = sorted((-f_lo**2 * inv_v_z, -f_hi**2 * inv_v_z))

    def weight(t):
        t = np.asarray(t, float)
        outside = np.maximum(lo - t, 0.0) + np.maximum(t - hi, 0.0)
        return np.exp(-0.5 * (outside / cfg.zenith_tolerance_fraction) ** 2)
    return weight


def _focal_prior(n: np.ndarray, zenith: np.ndarray, zenith_cov: np.ndarray | None, width: float,
                 cfg: AtlantaConfig) -> tuple[float, float] | None:
    """(t, std t) that a typical lens (`prior_hfov_deg`, log-normal with `prior_log_focal_std`) puts the
    horizon at with a seen, finite zenith of covariance `zenith_cov`: t = -f^2 / v_z, std from
    2 |t| std(log f) and f^2 std(1 / v_z) in quadrature. None without that covariance."""
    if zenith_cov is None:
        return None
    f = focal_from_hfov(width, cfg.prior_hfov_deg)
    v_z = float(n @ zenith[:2] / zenith[2])
    t = -f**2 / v_z
    std_inv_v = math.sqrt(float(n @ zenith_cov @ n)) / v_z**2
    return t, math.hypot(2 * abs(t) * cfg.prior_log_focal_std, f**2 * std_inv_v)


def _candidate_vps(ends: np.ndarray, weights: np.ndarray, lines: np.ndarray, angle_std_rad: np.ndarray,
                   proposals: np.ndarray, cfg: AtlantaConfig) -> list[VanishingPoint]:
    """Horizontal VPs of sequential consensus and of J-linkage (a J-linkage VP within
    `_SAME_VP_DEG` of one already found is dropped), strongest first."""
    found = horizontal_vps(ends, weights, lines, angle_std_rad, proposals, cfg.max_horizontal_vps,
                           cfg.min_vp_share, cfg.zenith.min_angle_deg)
    same = math.cos(math.radians(_SAME_VP_DEG))
    for vp in linkage_vps(ends, weights, lines, angle_std_rad, proposals, None, cfg.min_vp_share,
                          cfg.zenith.min_angle_deg, cfg.linkage_proposals):
        if all(abs(float(vp.point @ other.point)) < same for other in found):
            found.append(vp)
    found.sort(key=lambda v: -v.support)
    return found


def _vp_height(vps: list[VanishingPoint], n: np.ndarray, in_range, prior: tuple[float, float] | None,
               roll_std_rad: float, cfg: AtlantaConfig) -> float | None:
    """The horizon height t from horizontal VPs, each on the horizon or an outlier, with the focal
    range `in_range` and the typical lens `prior` (module docstring, step 2), on a grid of
    `height_floor_fraction` / 4. None without a finite VP."""
    vps = [v for v in vps if v.cov is not None]
    if not vps:
        return None
    x = np.array([v.point[:2] / v.point[2] for v in vps])
    cov = np.array([v.cov for v in vps])
    support = np.array([v.support for v in vps])
    along = np.array([-n[1], n[0]])
    height = x @ n
    distance = np.array([v.distance for v in vps])
    var = (np.einsum("i,kij,j->k", n, cov, n) + (math.radians(cfg.vp_floor_deg) * distance) ** 2
           + (roll_std_rad * (x @ along)) ** 2)
    inlier = support / (support + cfg.vp_inlier_support)
    span = 2.0 * cfg.height_range_fraction
    grid = np.arange(-cfg.height_range_fraction, cfg.height_range_fraction, cfg.height_floor_fraction / 4)
    on = np.exp(-0.5 * (grid[None] - height[:, None]) ** 2 / var[:, None]) / np.sqrt(2 * np.pi * var[:, None])
    log_p = np.log(inlier[:, None] * on + (1.0 - inlier[:, None]) / span).sum(axis=0)
    log_p += np.log(np.maximum(in_range(grid), 1e-300))
    if prior is not None:
        log_p -= 0.5 * ((grid - prior[0]) / prior[1]) ** 2
    k = int(np.argmax(log_p))
    window = np.abs(grid - grid[k]) <= cfg.posterior_window_fraction  # 0: the mode alone
    p = np.exp(log_p[window] - log_p[k])
    return float(p @ grid[window] / p.sum())


def _zenith_step(segments: LineSegments, K: np.ndarray, up_c: np.ndarray, cfg: AtlantaConfig):
    """Step 1 of the module docstring: (scale, the end points centred and scaled, the first guess's
    zenith in those coordinates, each segment's angle std, the `estimate_zenith` found or None)."""
    c = K[:2, 2]
    scale = float(np.hypot(segments.width, segments.height))
    ends = (segments.endpoints_px - c) / scale  # centred, scaled coordinates
    zenith = K @ up_c
    zenith = np.array([zenith[0] - c[0] * zenith[2], zenith[1] - c[1] * zenith[2], zenith[2] * scale])
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    sigma_angle = math.sqrt(2.0) * cfg.endpoint_noise_px / scale / np.maximum(length, 1e-9)
    half_size = np.array([segments.width, segments.height]) / 2.0 / scale
    return scale, ends, zenith, sigma_angle, estimate_zenith(ends, segments.weights, sigma_angle, zenith,
                                                             half_size, cfg.zenith)


def vertical_segments(segments: LineSegments, K: np.ndarray, up_c: np.ndarray,
                      config: AtlantaConfig | None = None) -> float:
    """The effective number of vertical segments behind the zenith that `estimate_horizon` would find
    (its `n_vertical` when it finds a horizon; 0 below `min_vertical_effective`), from its first step
    alone: a fifth of its cost (horizon_uav), for callers that only need to know whether the segments show
    vertical structure."""
    cfg = config or AtlantaConfig()
    if len(segments) < 4:
        return 0.0
    found = _zenith_step(segments, np.asarray(K, float), up_c, cfg)[-1]
    return found.n_effective if found is not None and found.n_effective >= cfg.min_vertical_effective else 0.0


def estimate_horizon(segments: LineSegments, K: np.ndarray, up_c: np.ndarray,
                     config: AtlantaConfig | None = None) -> AtlantaHorizon | None:
    """The Atlanta-world horizon of `segments` (see the module docstring), None without evidence.
    `K` gives the principal point (and the first zenith guess with `up_c`, unit up in the camera frame)."""
    cfg = config or AtlantaConfig()
    if len(segments) < 4:
        return None
    K = np.asarray(K, float)
    c = K[:2, 2]
    scale, ends, zenith, sigma_angle, found = _zenith_step(segments, K, up_c, cfg)
    w = segments.weights
    lines = segment_lines(ends)
    length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)
    n_vertical, zenith_cov = 0.0, None
    if found is not None and found.n_effective >= cfg.min_vertical_effective:
        zenith, n_vertical, zenith_cov = found.point, found.n_effective, found.cov
    # The sky direction in the image: up ~ K^-1 zenith (the sign kept from `up_c`) has up[:2] ~ zenith[:2].
    n = zenith[:2].copy()
    if np.linalg.norm(n) < 1e-12:  # looking straight up or down: no horizon in view
        return None
    n = n / np.linalg.norm(n)
    flat = ~_vertical_mask(ends, zenith, cfg.horizontal_min_deg)
    idx = np.flatnonzero(flat)
    idx = idx[np.argsort(-w[idx])][: cfg.max_pairs_segments]
    if len(idx) < 3:
        return None
    e, wl, l = ends[idx], w[idx], lines[idx]
    mid = e.mean(axis=1)
    length, sigma_angle = length[idx], sigma_angle[idx]
    i, j = np.triu_indices(len(idx), 1)
    p = np.cross(l[i], l[j])
    ok = np.abs(p[:, 2]) > 1e-9
    i, j, p = i[ok], j[ok], p[ok]
    x = p[:, :2] / p[:, 2:3]
    height = x @ n
    sin_ij = np.abs(p[:, 2])  # |l_i[:2] x l_j[:2]| = sine of the angle between the unit-normal lines
    r_i = np.linalg.norm(x - mid[i], axis=1)
    r_j = np.linalg.norm(x - mid[j], axis=1)
    floor = cfg.height_floor_fraction
    spread = np.sqrt((r_i * sigma_angle[i]) ** 2 + (r_j * sigma_angle[j]) ** 2) / np.maximum(sin_ij, 1e-3)
    spread = np.sqrt(spread**2 + floor**2)
    pair_w = wl[i] * wl[j]
    # Segments that meet at or near themselves (window corners, one edge split in two) mark no VP.
    apart = (r_i > cfg.min_vp_distance * length[i]) & (r_j > cfg.min_vp_distance * length[j])
    keep = apart & (np.abs(height) < cfg.height_range_fraction + 3 * spread)
    height, spread, pair_w = height[keep], spread[keep], pair_w[keep]
    if len(height) == 0:
        return None
    in_range = _focal_range_weight(n, zenith, n_vertical, segments.width / scale, cfg)
    vps = _candidate_vps(e, wl, l, sigma_angle, p[keep], cfg)
    prior = _focal_prior(n, zenith, zenith_cov, segments.width / scale, cfg)
    roll_std = math.radians(cfg.roll_std_deg if n_vertical > 0 else cfg.roll_std_unseen_deg)
    t = _vp_height(vps, n, in_range, prior, roll_std, cfg)
    if t is None:  # no VP: the densest height of the pairs' meeting points
        grid = np.arange(-cfg.height_range_fraction, cfg.height_range_fraction + floor / 4, floor / 2)
        density = np.zeros_like(grid)
        for start in range(0, len(height), 4096):
            s = slice(start, start + 4096)
            zsc = (grid[None, :] - height[s, None]) / spread[s, None]
            density += ((pair_w[s] / spread[s])[:, None] * np.exp(-0.5 * zsc**2)).sum(axis=0)
        t = float(grid[int(np.argmax(density * in_range(grid)))])
    # Width of the mode: the pairs that explain it, their heights' weighted spread about t.
    near = np.abs(height - t) < 3 * spread
    support = float(pair_w[near].sum() / pair_w.sum())
    if support < cfg.min_pairs_weight_fraction:
        return None
    # The heights of the pairs in the mode scatter by `scatter`; they come from m effective segments
    # (Kish count over the segments' shares of the mode), each pair not an independent measurement.
    wn = pair_w[near] / spread[near] ** 2
    scatter = math.sqrt(float(wn @ (height[near] - t) ** 2) / float(wn.sum()))
    share = np.bincount(np.concatenate([i[keep][near], j[keep][near]]), np.concatenate([wn, wn]), minlength=len(idx))
    m = share.sum() ** 2 / max(float(share @ share), 1e-300)
    t_std = cfg.std_scale * scatter / math.sqrt(max(m, 1.0))
    t_std = max(t_std, floor)
    # Back to pixels: n . (x - c) / scale = t  <=>  n . x - (n . c + t scale) = 0, positive towards the sky.
    line = np.array([n[0], n[1], -(n @ c) - t * scale])
    zenith_px = np.array([zenith[0] * scale + c[0] * zenith[2], zenith[1] * scale + c[1] * zenith[2], zenith[2]])
    focal, focal_std = float("nan"), float("nan")
    if abs(zenith[2]) > 1e-12:
        v_z = float(n @ zenith[:2] / zenith[2])
        f2 = -t * v_z
        if f2 > 0 and n_vertical > 0:
            focal = math.sqrt(f2) * scale
            focal_std = focal * focal_std_fraction(t, t_std, v_z, zenith_cov, n)
    return AtlantaHorizon(line, t_std * scale, zenith_px, float(n_vertical), focal, support, focal_std)


def focal_std_fraction(t: float, t_std: float, v_z: float, zenith_cov: np.ndarray | None, n: np.ndarray) -> float:
    """std(f) / f of f^2 = -t v_z (the closed form of two orthogonal VPs: the zenith at height v_z and the
    horizon at height t, both along the image direction of up `n` from the principal point, scaled units):
    half the relative stds of t and v_z in quadrature; v_z's from the zenith's 2x2 covariance (inf
    without it)."""
    v_std = math.sqrt(float(n @ zenith_cov @ n)) if zenith_cov is not None else float("inf")
    return 0.5 * math.hypot(t_std / abs(t), v_std / abs(v_z))
