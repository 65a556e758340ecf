"""Horizontal vanishing points of one image by J-linkage (Toldo and Fusiello, ECCV 2008).

Sequential consensus (`solver/horizontal_vps.py`) takes the strongest point first and removes its
segments, so one crossing of two families (ground texture, road hatching meeting a facade) can take
segments from both and hide the VPs behind them. J-linkage groups segments instead of points: each
segment's preference set is the set of proposals (intersections of segment pairs) it points at
(miss angle under `inlier_sigmas` times its angle std, as in `zenith.miss_angles`); the two clusters
whose preference sets are closest in Jaccard distance are merged, the merged cluster keeping the
proposals both prefer, until no two clusters share a proposal. Each cluster holding `min_share` of
the segments' weight gives a VP by weighted least squares over its segments, scored like a
sequential one (S, the weight of all segments that point at it). `inlier_sigmas` 2 was chosen on
ECD's odd-numbered images (2 / 3 / 4: AUC 87.4 / 86.7 / 85.3 % with J-linkage's VPs alone, 2000
proposals drawn at random).

J-linkage's VPs complement the sequential ones rather than replace them (`solver/atlanta.py`). On
ECD (103 photos; a hand-labelled group of 3 or more lines is found when 60 % of its length points
within 2 deg of a VP): sequential consensus alone finds 63 % of the groups and 81 % of its VPs
match one; with J-linkage's distinct VPs added, 69 % and 70 % (the horizon's robust height weighs
the extra false ones down).
"""

from __future__ import annotations

import numpy as np

from .horizontal_vps import VanishingPoint, fitted_vp
from .zenith import floored_std, miss_angles, unit_points


def _preference_sets(ends: np.ndarray, angle_std_rad: np.ndarray, proposals: np.ndarray, max_proposals: int,
                     inlier_sigmas: float) -> np.ndarray:
    """(N, P) bool: segment i points at proposal p; at most `max_proposals` proposals, evenly spaced."""
    props = unit_points(proposals)
    if len(props) > max_proposals:
        props = props[np.linspace(0, len(props) - 1, max_proposals).astype(int)]
    return (miss_angles(ends, props) < inlier_sigmas * angle_std_rad[None]).T


def _jaccard_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) Jaccard distances between the bool rows of `a` and of `b`; inf where either
    set is empty (a cluster that prefers no proposal merges with nothing)."""
    a, b = a.astype(np.float32), b.astype(np.float32)
    both = a @ b.T
    either = a.sum(axis=1)[:, None] + b.sum(axis=1)[None] - both
    empty = (a.sum(axis=1)[:, None] == 0) | (b.sum(axis=1)[None] == 0)
    return np.where(empty, np.inf, 1.0 - both / np.maximum(either, 1.0))


def linkage_clusters(pref: np.ndarray) -> list[np.ndarray]:
    """Segment clusters (index arrays) of J-linkage over preference sets `pref` (N, P)."""
    pref = pref.copy()
    n = len(pref)
    dist = _jaccard_distances(pref, pref)
    np.fill_diagonal(dist, np.inf)
    members = [[i] for i in range(n)]
    alive = np.ones(n, bool)
    while True:
        a, b = divmod(int(np.argmin(dist)), n)
        if not dist[a, b] < 1.0:  # no two clusters share a proposal
            break
        pref[a] &= pref[b]
        members[a] += members[b]
        alive[b] = False
        dist[b, :] = dist[:, b] = np.inf
        others = np.flatnonzero(alive)
        others = others[others != a]
        dist[a, others] = dist[others, a] = _jaccard_distances(pref[others], pref[a : a + 1])[:, 0]
    return [np.array(members[i]) for i in np.flatnonzero(alive)]


def linkage_vps(ends: np.ndarray, weights: np.ndarray, lines: np.ndarray, angle_std_rad: np.ndarray,
                proposals: np.ndarray, max_vps: int | None = None, min_share: float = 0.08,
                min_angle_deg: float = 1.0, max_proposals: int = 1000,
                inlier_sigmas: float = 2.0) -> list[VanishingPoint]:
    """Up to `max_vps` (None: all) VPs of segments `ends` (N, 2, 2) with `lines` (N, 3, [a, b] unit)
    by J-linkage over the homogeneous `proposals` (P, 3), strongest first (module docstring)."""
    if len(proposals) == 0:
        return []
    s = floored_std(angle_std_rad, min_angle_deg)
    pref = _preference_sets(ends, s, proposals, max_proposals, inlier_sigmas)
    found = []
    for idx in linkage_clusters(pref):
        if len(idx) < 2 or weights[idx].sum() < min_share * weights.sum():
            continue
        found.append(fitted_vp(ends, lines, weights, s, idx))
    found.sort(key=lambda v: -v.support)
    return found if max_vps is None else found[:max_vps]
