"""One answer per frame: up, the rotation, the horizon line and its uncertainty from the same estimate.

A frame's up vector comes from the joint solve (the Manhattan axis nearest image up, or, with a sky
boundary among the cues, the axis nearest the sky's up) or from the segments' Atlanta horizon. The
rotation reported beside it is the solve's `R_cm` turned by the smallest rotation that carries its up
axis onto that up (`aligned_rotation`), so that the horizon `l ~ K^-T up_c`, the axes drawn from
`R_cm` and `up_c` never disagree. The horizon's standard deviations (`HorizonUncertainty`) come from
the covariance of up: its offset at the image centre along the line's normal (px) and its angle (deg),
by central differences through `overlay.horizon.horizon_line`. The horizon is known when a cue that
can fix it took part (segments of man-made structure, the Atlanta horizon, a sky boundary) and both
standard deviations are within `HorizonKnownConfig`'s limits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..overlay.horizon import horizon_line
from ..rotations import vector_angle_deg


@dataclass(frozen=True)
class HorizonKnownConfig:
    max_std_fraction: float = 0.1
    """The horizon's std at the image centre (along its normal) must be below this fraction of the height."""
    max_angle_std_deg: float = 5.0
    """... and its angle's std below this."""
    min_effective_segments: float = 8.0
    """Man-made structure: at least this many effective segments in the line cue."""


@dataclass(frozen=True)
class SkyVetoConfig:
    """When man-made structure overrules a sky boundary (a city skyline is no horizon). ECD (the 5 photos
    where the sky checks passed, all with their skyline 0.45-2.5 H off the true horizon): the Atlanta
    horizon had 23-128 effective vertical segments and a std of 0.018-0.037 H; horizon_uav (every 8th
    photo): where its Atlanta horizon disagreed with the sky beyond the stds it had at most 8 effective
    verticals (runways and field edges), or a std of 0.19 H and more."""

    min_vertical_effective: float = 15.0
    """Effective vertical segments behind the zenith (buildings) from which the structure may veto."""
    max_std_fraction: float = 0.1
    """... when its horizon's std is below this fraction of the height."""
    sigmas: float = 3.0
    """... and the two horizons differ (ECD score, fraction of the height) by more than this many of
    their combined std, and by at least `min_difference_fraction`."""
    min_difference_fraction: float = 0.05
    structure_agree_deg: float = 5.0
    """The structure cannot veto a sky whose up is one of its own Manhattan axes within this: its Atlanta
    zenith is then another of its axes, not the vertical (a horizon_uav photo turned 90 deg: the
    receding ground lines met where image up points, 32 effective "verticals", a horizon 88 deg off,
    while the structure's axis nearest the sky's up was 1.2 deg from it; the 5 ECD skylines vetoed: 23-29
    deg)."""


def sky_vetoed(sky, atlanta, config: SkyVetoConfig | None = None) -> bool:
    """Whether the segments' Atlanta horizon (`solver/atlanta.py`), seen with vertical structure, overrules
    the sky boundary `sky` (`solver/sky_horizon.py`): see `SkyVetoConfig`."""
    from ..scoring.horizon import horizon_error

    cfg = config or SkyVetoConfig()
    h = sky.height
    if atlanta.n_vertical < cfg.min_vertical_effective or atlanta.t_std_px > cfg.max_std_fraction * h:
        return False
    difference = horizon_error(sky.line, atlanta.line_px, h, sky.width)
    combined = np.hypot(atlanta.t_std_px, sky.offset_std_px) / h
    return bool(difference > max(cfg.sigmas * combined, cfg.min_difference_fraction))


def sky_decides(segments, K: np.ndarray, up_guess_c: np.ndarray, config: SkyVetoConfig | None = None) -> bool:
    """Whether a sky boundary sets up alone, without `segments`: they show too few man-made
    verticals (`SkyVetoConfig.min_vertical_effective`, counted from `up_guess_c` by the Atlanta horizon's
    first step, `atlanta.vertical_segments`) to veto it or to join it (`sky_and_segments`'s first case,
    found without the rest of the Atlanta horizon: horizon_uav, 10.8 -> 0.5 ms CPU per photo)."""
    from .atlanta import vertical_segments

    cfg = config or SkyVetoConfig()
    return (segments is None or not len(segments)
            or vertical_segments(segments, K, up_guess_c) < cfg.min_vertical_effective)


def sky_and_segments(sky, segments, K: np.ndarray, up_guess_c: np.ndarray, config: SkyVetoConfig | None = None,
                     R_cm: np.ndarray | None = None):
    """(sky, segments) for a solve with the sky boundary `sky`: the segments' Atlanta horizon (from
    `up_guess_c`) decides. Without a confident one seen with man-made verticals (`SkyVetoConfig`'s
    `min_vertical_effective` and `max_std_fraction`) the segments cannot tell up (a runway's or a field's
    edges: on horizon_uav they pulled the horizon off the sky's, 73.7 % pass with them against 96.9 %
    without), so the sky alone sets it: (sky, None). With one, a disagreeing sky is vetoed:
    (None, segments); an agreeing one joins them: (sky, segments). With the structure's rotation `R_cm`,
    a sky whose up is one of its axes (`SkyVetoConfig.structure_agree_deg`) is not vetoed: (sky, None)."""
    from .atlanta import estimate_horizon

    cfg = config or SkyVetoConfig()
    if sky is None or segments is None or not len(segments):
        return sky, segments
    if sky_decides(segments, K, up_guess_c, cfg):
        return sky, None
    atlanta = estimate_horizon(segments, K, up_guess_c)
    if (atlanta is None or atlanta.n_vertical < cfg.min_vertical_effective
            or atlanta.t_std_px > cfg.max_std_fraction * sky.height):
        return sky, None
    if R_cm is not None:
        from .manhattan import up_candidate

        sky_up = sky.observation(K).up_c
        if np.degrees(np.arccos(np.clip(up_candidate(R_cm, sky_up)[1] @ sky_up, -1.0, 1.0))) < cfg.structure_agree_deg:
            return sky, None
    return (None, segments) if sky_vetoed(sky, atlanta, cfg) else (sky, segments)


@dataclass(frozen=True)
class SkyOrientationConfig:
    """When a sky boundary too rough to be the horizon still says that the segments' up is turned away from
    the sky: the zenith search assumes an upright photo (`ZenithConfig.roll_prior_deg`), and in a photo
    turned 90 deg a facade's horizontal VP, now near the image vertical, is taken for the zenith; the
    segments alone cannot tell (a Manhattan scene looks the same turned). Measured (real) with
    `detect_sky_horizon` on ECD and the same photos turned 90 deg clockwise (segments turned alike), and on
    every 4th ICSL, ICSL-more and ICL kt3 frame: with these limits the sky lies over 70 deg from the
    Atlanta horizon's up in 51 of 102 turned photos (ECD 066 turned: 90 deg, separation 1.27), in 2 of
    102 upright ones (071, 076) and in none of the 43 indoor frames (one indoor frame at 65 deg, 1.35)."""

    min_separation: float = 1.2
    """The boundary's separation (`SkyHorizon.separation`, the trusted sky's check asks 1.6) ..."""
    min_angle_deg: float = 70.0
    """... and the angle between its sky direction and the horizon's up (image plane) from which the
    horizon's angle is in doubt by that angle."""
    required_checks: tuple[str, ...] = ("side", "texture")
    """`SkyHorizon.failed_checks` names it must pass: sky and ground on each side, the ground textured and
    the sky smooth (a skyline of buildings need be neither long nor straight)."""


def sky_orientation_doubt_deg(boundary, line_px: np.ndarray, sky_config,
                              config: SkyOrientationConfig | None = None) -> float:
    """The angle (deg, image plane) between the sky direction of the untrusted sky boundary `boundary`
    (`SkyDetector.boundary`, checked with `sky_config`) and the up of the horizon `line_px` (positive on the
    sky side) when that boundary contradicts it (`SkyOrientationConfig`), else 0."""
    cfg = config or SkyOrientationConfig()
    if boundary is None or boundary.separation < cfg.min_separation:
        return 0.0
    if set(boundary.failed_checks(sky_config)) & set(cfg.required_checks):
        return 0.0
    angle = sky_angle_deg(boundary.line, line_px)
    return angle if angle > cfg.min_angle_deg else 0.0


def sky_angle_deg(line_a, line_b) -> float:
    """The angle (deg, 0..180, image plane) between the sky sides (positive normals) of two image lines."""
    return float(vector_angle_deg(np.asarray(line_a, float)[:2], np.asarray(line_b, float)[:2]))


SKY_START_STEPS = 18
"""Turns about the sky's up tried by `sky_start` (over 90 deg, the Manhattan symmetry about up: 5 deg apart)."""


def sky_start(normal_map, up_c: np.ndarray, steps: int = SKY_START_STEPS) -> np.ndarray | None:
    """A start `R_cm` for the solve of the normals with a sky boundary that sets up alone (`sky_decides`):
    of the rotations whose z axis is the sky's `up_c`, turned about it in `steps` steps, the one the
    normals fit best (their cost, eq. 1). The sky fixes the tilt; the turn about up is the normals' alone
    to tell, so a 1-D search replaces the solver's search over SO(3) (horizon_uav: 14.4 -> 6.6 ms CPU a solve,
    the same horizons). None without a normal map or valid normals."""
    from .moments import normal_moments
    from .quartic import normalised_cost
    from .sky_horizon import tangent_basis

    if normal_map is None:
        return None
    moments = normal_moments(normal_map.normals, normal_map.kappa)
    if moments.n_valid == 0 or not moments.total_weight > 0:
        return None
    up = np.asarray(up_c, float) / np.linalg.norm(up_c)
    upright = np.column_stack([tangent_basis(up), up])  # right-handed: e1 x e2 = up
    turns = Rotation.from_euler("z", np.linspace(0.0, np.pi / 2, steps, endpoint=False)[:, None]).as_matrix()
    candidates = upright @ turns  # (steps, 3, 3): z stays up_c
    return candidates[int(np.argmin(normalised_cost(moments.G, moments.total_weight, candidates)))]


@dataclass(frozen=True)
class HorizonUncertainty:
    offset_std_px: float
    """Std of the horizon's signed distance from the image centre, along its normal (pixels)."""
    angle_std_deg: float
    """Std of its angle in the image (the camera's roll), degrees."""
    centre_offset_px: float
    """Signed distance of the image centre from the horizon (positive: the centre is below it, on the ground side)."""
    in_image: bool
    """Whether the line crosses the image."""


def up_axis(R_cm: np.ndarray, up_c: np.ndarray) -> tuple[int, float]:
    """(k, sign): the column of `R_cm` nearest the direction `up_c`, and the sign that turns it towards it."""
    dots = np.asarray(R_cm, float).T @ np.asarray(up_c, float)
    k = int(np.argmax(np.abs(dots)))
    return k, float(np.sign(dots[k]) or 1.0)


def aligned_rotation(R_cm: np.ndarray, up_c: np.ndarray) -> np.ndarray:
    """`R_cm` turned by the smallest rotation (in the camera frame) that carries its axis nearest `up_c`
    onto `up_c` (unit): the other axes follow, so one rotation holds the frame's up."""
    k, sign = up_axis(R_cm, up_c)
    r = sign * np.asarray(R_cm, float)[:, k]
    u = np.asarray(up_c, float) / np.linalg.norm(up_c)
    axis = np.cross(r, u)
    s, c = np.linalg.norm(axis), float(r @ u)
    if s < 1e-12:
        return np.asarray(R_cm, float)
    turn = Rotation.from_rotvec(axis / s * np.arctan2(s, c)).as_matrix()
    return turn @ np.asarray(R_cm, float)


def up_covariance(R_cm: np.ndarray, cov_rad2: np.ndarray, up_c: np.ndarray) -> np.ndarray:
    """Covariance (3x3, camera frame) of up_c = sign R_cm e_k under the right perturbation delta of R_cm
    with covariance `cov_rad2`: d up = -R_cm [s e_k]x delta."""
    k, sign = up_axis(R_cm, up_c)
    e = np.zeros(3)
    e[k] = sign
    skew = np.array([[0, -e[2], e[1]], [e[2], 0, -e[0]], [-e[1], e[0], 0]])
    J = -np.asarray(R_cm, float) @ skew
    return J @ np.asarray(cov_rad2, float) @ J.T


def horizon_uncertainty(up_c: np.ndarray, cov_up: np.ndarray, K: np.ndarray, height: int,
                        width: int) -> HorizonUncertainty:
    """The horizon's standard deviations (`HorizonUncertainty`) from up's covariance `cov_up` (camera frame)."""
    up_c = np.asarray(up_c, float) / np.linalg.norm(up_c)
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0, 1.0])

    def offset_angle(u):
        line = horizon_line(u / np.linalg.norm(u), K)
        return np.array([float(line @ centre), np.arctan2(line[1], line[0])])

    a = np.array([1.0, 0.0, 0.0]) if abs(up_c[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(up_c, a)
    e1 /= np.linalg.norm(e1)
    basis = np.stack([e1, np.cross(up_c, e1)], axis=1)
    h = 1e-4
    J = np.zeros((2, 2))
    for i in range(2):
        d = offset_angle(up_c + h * basis[:, i]) - offset_angle(up_c - h * basis[:, i])
        d[1] = (d[1] + np.pi) % (2 * np.pi) - np.pi
        J[:, i] = d / (2 * h)
    C = J @ (basis.T @ cov_up @ basis) @ J.T
    line = horizon_line(up_c, K)
    offset = float(line @ centre)
    corners = np.array([[0, 0, 1], [width - 1, 0, 1], [0, height - 1, 1], [width - 1, height - 1, 1]], float) @ line
    finite = np.all(np.isfinite(C)) and np.hypot(line[0], line[1]) > 0.5
    return HorizonUncertainty(offset_std_px=float(np.sqrt(max(C[0, 0], 0.0))) if finite else float("inf"),
                              angle_std_deg=float(np.degrees(np.sqrt(max(C[1, 1], 0.0)))) if finite else float("inf"),
                              centre_offset_px=-offset, in_image=bool(corners.min() < 0 < corners.max()))


def horizon_known(uncertainty: HorizonUncertainty, supported: bool, height: int,
                  config: HorizonKnownConfig | None = None) -> bool:
    """Whether a cue that can fix the horizon took part and its standard deviations are small enough."""
    cfg = config or HorizonKnownConfig()
    return bool(supported and uncertainty.offset_std_px <= cfg.max_std_fraction * height
                and uncertainty.angle_std_deg <= cfg.max_angle_std_deg)
