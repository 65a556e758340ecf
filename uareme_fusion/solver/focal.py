"""The focal length from the scene: a 1-D profile of the joint Manhattan cost over f.

Segments along two or more Manhattan axes fix f (their vanishing points must be orthogonal through
K^-1). With the principal point at the image centre and square pixels, for each f on a log grid
spanning `FocalConfig.hfov_range_deg` we solve R jointly (normals and lines, `joint.py`; a global
search at the first f, then each f from the previous one's R, which moves smoothly with f: 2.6x
faster than a global search at each f; ECD's AUC unchanged, ICSL's and ICL-NUIM's rotation and
field-of-view figures within 0.02 deg and 0.15 %; following that minimum alone, without the
stream's global candidates at each f (`JointSolver.rotation(local=True)`): ECD 580 -> 403 ms CPU
per image, AUC unchanged at 90.2 %, odd 90.6 / even 89.8 %) and score
how many segments point at a vanishing point of R_f, in pixels (`pixel_consistency`): the angle
cost E_L itself cannot compare focal lengths, since every plane tends to contain the optical axis
as f grows. Both ends of the range are degenerate, so the highest interior peak is taken
(`best_interior_peak`). A parabola through it and its neighbours in log f gives f, and
var(log f) from its curvature, taking -n log S as the negative log-likelihood (n effective
segments). The rotation's covariance then absorbs the focal uncertainty: cov_R += var(log f) s s^T,
s = d delta / d log f of the solved rotation. When the profile has no interior maximum, or std(f)/f
exceeds `FocalConfig.max_relative_std`, the scene cannot tell: f comes from the assumed field of
view and `source` says so.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .atlanta import AtlantaHorizon
from .line_detection import LineSegments
from ..pinhole import DEFAULT_FOV_DEG, assumed_K, centred_K, focal_from_hfov
from ..rotations import log_so3
from ..types import NormalMap, VisualRotation, steady_within
from .joint import JointSolver, capped_covariance
from .lines import LineMoments, interpretation_planes, line_moments


@dataclass(frozen=True)
class FocalConfig:
    hfov_range_deg: tuple[float, float] = (30.0, 120.0)
    """Horizontal fields of view searched (degrees over the full image width)."""
    grid_points: int = 19
    max_relative_std: float = 0.1
    """Above this std(f)/f the estimate is not trusted and the assumed field of view is used."""
    assumed_fov_deg: float = DEFAULT_FOV_DEG
    principal_point_std_fraction: float = 0.02
    """Without intrinsics the principal point is taken at the image centre; real cameras put it this
    far off (std, fraction of the width: ICSL's is 6 px from the centre of 640): the rotation gets an
    isotropic floor of (this * width / f)^2 rad^2 (`unknown_centre_floor`)."""
    endpoint_noise_px: float = 1.5
    """Segment end point noise (full-resolution pixels) behind `pixel_consistency`."""
    closed_form_std_scale: float = 1.5
    """Multiplies the closed form's std (`closed_form_focal`). On ECD (77 photos whose labelled zenith and
    horizon fix f to 5 %) its |log error| / std has a median of 1.28 as computed (0.67 if Gaussian): the
    odd-numbered photos want 1.1, the even-numbered 2.5; 1.5 between."""
    closed_form_max_relative_std: float = 0.3
    """The closed form replaces the profile's f when its scaled std(f) / f is below this (ECD focal error
    90th percentile, the profile's 66.9 %: 0.2 / 0.3 / 0.45: 25.2 / 21.9 / 22.6 %)."""
    closed_form_hfov_range_deg: tuple[float, float] = (10.0, 150.0)
    """... and its field of view within this (ECD has telephotos to 20 deg, beyond `hfov_range_deg`)."""
    assumed_log_std: float = 0.35
    """Std of log f reported with an assumed field of view (the scene cannot tell f): ECD's labelled focal
    lengths stand a median 0.14 and a 90th percentile 0.37 from a 65 deg lens in log f."""


@dataclass(frozen=True)
class FocalEstimate:
    """The camera matrix used for one image and where its focal length came from."""

    K: np.ndarray
    source: str
    """estimated (from the segments), given (by the user or the dataset) or assumed (a field of view)."""
    std_px: float = float("nan")
    """Standard deviation of f in pixels (estimated only)."""
    width: int = 0
    origin: str = ""
    """How K was obtained, in words (e.g. "estimated from 110 frames ..." for a pooled K)."""
    principal_point_std_px: tuple[float, float] | None = None
    """Standard deviations of (cx, cy) in pixels when the principal point was estimated (pooled)."""

    @property
    def f_px(self) -> float:
        return float(self.K[0, 0])

    @property
    def hfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan2(self.width / 2.0, self.f_px))

    def as_dict(self) -> dict:
        return {"K": self.K.tolist(), "hfov_deg": self.hfov_deg, "focal_source": self.source,
                "f_px": self.f_px, "f_std_px": None if not np.isfinite(self.std_px) else self.std_px,
                "intrinsics_origin": self.origin or self.source,
                "principal_point_std_px": None if self.principal_point_std_px is None
                else list(self.principal_point_std_px)}


def segment_moments(segments: LineSegments, K: np.ndarray) -> LineMoments:
    """The sixth-order moments of `segments`' interpretation planes under `K`."""
    planes, ok = interpretation_planes(segments.endpoints_px, K)
    return line_moments(planes[ok], segments.weights[ok])


def _moments_if_any(segments: LineSegments | None, K: np.ndarray) -> LineMoments | None:
    """`segment_moments`, None without segments."""
    return segment_moments(segments, K) if segments is not None and len(segments) else None


def _sky_at(sky, K: np.ndarray):
    """The sky boundary (`sky_horizon.SkyHorizon`, or None) as an up observation under K."""
    return sky.observation(K) if sky is not None else None


def solve_given_K(solver: JointSolver, normal_map: NormalMap | None, segments: LineSegments | None,
                  K: np.ndarray, R_init=None, t_s: float | None = None, sky=None) -> VisualRotation:
    """The joint solve with known intrinsics (segments may be None or empty; `sky`: a sky boundary, the
    third cue, or None)."""
    return solver.solve(normal_map, _moments_if_any(segments, K), R_init, t_s=t_s, horizon=_sky_at(sky, K))


def rotation_given_K(solver: JointSolver, normal_map: NormalMap | None, segments: LineSegments | None,
                     K: np.ndarray, R_init=None, sky=None, local: bool = False) -> np.ndarray:
    """`solve_given_K`'s rotation `R_cm` alone (`JointSolver.rotation`: no covariance, which costs more;
    `local`: R_init's own minimum only)."""
    return solver.rotation(normal_map, _moments_if_any(segments, K), R_init, horizon=_sky_at(sky, K), local=local)


def solve_with_focal(solver: JointSolver, normal_map: NormalMap | None, segments: LineSegments, R_init=None,
                     config: FocalConfig | None = None, t_s: float | None = None,
                     sky=None) -> tuple[VisualRotation, FocalEstimate]:
    """Rotation and focal length together (see the module docstring); `segments` sets the image size.
    The rotation's covariance includes `unknown_centre_floor`."""
    cfg = config or FocalConfig()
    visual, focal = _solve_with_focal(solver, normal_map, segments, R_init, cfg, t_s, sky)
    return unknown_centre_floor(visual, focal, cfg, solver), focal


def closed_form_focal(solver: JointSolver, normal_map: NormalMap | None, segments: LineSegments,
                      visual: VisualRotation, focal: FocalEstimate, atlanta: AtlantaHorizon,
                      config: FocalConfig | None = None) -> tuple[VisualRotation, FocalEstimate]:
    """f from two orthogonal VPs in closed form (centred principal point, square pixels): the zenith at
    height v_z and the horizon at height t along the image direction of up give f^2 = -t v_z
    (`atlanta.AtlantaHorizon.focal_px`, its std `focal_std_px` times `closed_form_std_scale`). It
    replaces the profile's or the assumed f (`visual`, `focal`) when its relative std is below
    `closed_form_max_relative_std`; the rotation is then solved again under it, its covariance widened by
    var(log f) s s^T and the principal point's floor (as `solve_with_focal`). Otherwise (the horizon near
    the image centre, a zenith near infinity: the scene cannot tell) `visual` and `focal` as given. The
    covariance is never below `visual`'s (which holds the principal point's floor): where the two f
    disagree the closed form may be the wrong one (a drone photo turned 90 deg: its ground lines took for
    verticals gave 487 px against the profile's 197 px, and the first solve's roll std of 60 deg must
    stay, not drop to 1.4 deg with a horizon 88 deg off). On ECD (77 photos with a labelled f good to
    5 %, `bench horizon`): error median 16.8 -> 5.7 %, 90th percentile 66.9 -> 21.9 % (28.6 % before the
    line cue's chance level went to 4 sigmas, `LineCueConfig.chance_sigmas`)."""
    cfg = config or FocalConfig()
    f = float(atlanta.focal_px)
    std_log_f = cfg.closed_form_std_scale * float(atlanta.focal_std_px) / f
    lo, hi = (focal_from_hfov(segments.width, a) for a in cfg.closed_form_hfov_range_deg[::-1])
    if not (np.isfinite(f) and lo <= f <= hi and std_log_f < cfg.closed_form_max_relative_std):
        return visual, focal
    K = centred_K(f, segments.height, segments.width)
    solved = solve_given_K(solver, normal_map, segments, K, visual.R_cm)
    slope = _rotation_slope(solver, normal_map, segments, f, solved.R_cm)
    cov = solved.cov + std_log_f**2 * np.outer(slope, slope)
    val, vec = np.linalg.eigh(0.5 * (visual.cov + visual.cov.T) - cov)  # never below the first solve's
    cov = cov + (vec * np.maximum(val, 0.0)) @ vec.T
    focal = FocalEstimate(K, "estimated", std_px=f * std_log_f, width=segments.width,
                          origin="closed form of the zenith and the horizon (f^2 = -t v_z)")
    return replace_cov(solved, solver, cov), focal


def unknown_centre_floor(visual: VisualRotation, focal: FocalEstimate, config: FocalConfig,
                         solver: JointSolver) -> VisualRotation:
    """`visual` with (principal_point_std_fraction * width / f)^2 added to each variance (capped), when
    segments took part; the normals use no intrinsics, so a normals-only rotation is returned as it is.
    The floor is the rotation's `cov_steady`: a stream keeps one K, so its centre errs the same way in every
    frame (on the real ICSL corridor, 80 frames turning 2 deg, the segments' rotations after the constant
    alignment err by 0.19 deg per axis against this floor's 1.34)."""
    if "lines" not in visual.cues and "sky" not in visual.cues:
        return visual
    std_rad = config.principal_point_std_fraction * focal.width / focal.f_px
    floored = replace_cov(visual, solver, visual.cov + std_rad**2 * np.eye(3))
    steady = std_rad**2 * np.eye(3) + (0.0 if visual.cov_steady is None else visual.cov_steady)
    return dataclasses.replace(floored, cov_steady=steady_within(floored.cov, steady))  # one K: a steady error


def assumed_focal(height: int, width: int, config: FocalConfig | None = None) -> FocalEstimate:
    """The assumed field of view's K, its f's std `assumed_log_std` of f (the scene did not tell f)."""
    cfg = config or FocalConfig()
    K = assumed_K(height, width, cfg.assumed_fov_deg)
    return FocalEstimate(K, "assumed", std_px=float(K[0, 0]) * cfg.assumed_log_std, width=width)


def _solve_with_focal(solver, normal_map, segments, R_init, cfg, t_s, sky=None) -> tuple[VisualRotation, FocalEstimate]:
    h, w = segments.height, segments.width
    assumed = assumed_focal(h, w, cfg)
    reference = solve_given_K(solver, normal_map, segments, assumed.K, R_init, t_s, sky)
    if "lines" not in reference.cues:
        return reference, assumed
    lo, hi = (focal_from_hfov(w, a) for a in cfg.hfov_range_deg[::-1])
    log_f = np.linspace(math.log(lo), math.log(hi), cfg.grid_points)
    profile, rotations = [], []
    for lf in log_f:  # the first f searched globally, each next one from the previous f's rotation
        K = centred_K(math.exp(lf), h, w)
        rotations.append(rotation_given_K(solver, normal_map, segments, K, rotations[-1] if rotations else None, sky,
                                          local=True))
        profile.append(pixel_consistency(segments, K, rotations[-1], cfg.endpoint_noise_px))
    i = best_interior_peak(np.array(profile))
    if i is None:
        return reference, assumed
    step = log_f[1] - log_f[0]
    y0, y1, y2 = profile[i - 1: i + 2]
    curvature = -(y0 - 2 * y1 + y2) / step**2
    if not curvature > 0:
        return reference, assumed
    lf_best = log_f[i] + 0.5 * (y0 - y2) / (y0 - 2 * y1 + y2) * step
    # -n log(S / S_max) as the negative log-likelihood of log f (n effective segments).
    std_log_f = 1.0 / math.sqrt(segments.n_effective * curvature / y1)
    if std_log_f > cfg.max_relative_std:
        return reference, assumed
    f = math.exp(lf_best)
    K = centred_K(f, h, w)
    visual = solve_given_K(solver, normal_map, segments, K, rotations[i], t_s, sky)
    slope = _rotation_slope(solver, normal_map, segments, f, visual.R_cm, sky=sky)
    visual = replace_cov(visual, solver, visual.cov + std_log_f**2 * np.outer(slope, slope))
    return visual, FocalEstimate(K, "estimated", std_px=f * std_log_f, width=w)


def best_interior_peak(profile: np.ndarray) -> int | None:
    """Index of the highest local maximum strictly inside the grid, None when there is none.

    Both ends of the range are degenerate for any segment set (as f -> inf every plane contains
    the optical axis; as f -> 0 every plane normal tends to it), so a profile still rising at an
    end says nothing about f; a peak inside the range does."""
    inner = np.arange(1, len(profile) - 1)
    peaks = inner[(profile[inner] >= profile[inner - 1]) & (profile[inner] >= profile[inner + 1])]
    return None if len(peaks) == 0 else int(peaks[np.argmax(profile[peaks])])


def pixel_consistency(segments: LineSegments, K: np.ndarray, R_cm: np.ndarray, noise_px: float) -> float:
    """S = sum_j w_j exp(-c_j^2 / (2 s_j^2)) / sum_j w_j: how many segments point at a vanishing point of R.

    c_j = min_k |p_j . r_k| and s_j = noise_px / length_j: the plane angle that end point noise of
    `noise_px` pixels gives a segment of that length, whatever f. The angle cost E_L alone is no
    measure across f: as f grows every plane tends to contain the optical axis, and E_L -> 0.
    """
    planes, ok = interpretation_planes(segments.endpoints_px, K)
    length = np.linalg.norm(segments.endpoints_px[:, 1] - segments.endpoints_px[:, 0], axis=1)
    c = np.abs(planes @ R_cm).min(axis=1)
    s = noise_px / np.maximum(length, 1.0)
    w = segments.weights * ok
    return float((w * np.exp(-0.5 * (c / s) ** 2)).sum() / max(w.sum(), 1e-300))


def _rotation_slope(solver: JointSolver, normal_map, segments: LineSegments, f_px: float, R_cm,
                    h: float = 0.02, sky=None) -> np.ndarray:
    """d delta / d log f: how the solved rotation moves (right perturbation, rad) as f changes."""
    return rotation_slope(solver, normal_map, segments, lambda s: centred_K(f_px * math.exp(s), segments.height,
                                                                             segments.width), R_cm, h, sky)


def rotation_slope(solver: JointSolver, normal_map, segments: LineSegments, K_at, R_cm, h: float,
                   sky=None) -> np.ndarray:
    """d delta / d s (3,) by central differences: how the solved rotation moves (right perturbation, rad)
    as the intrinsics follow `K_at(s)` from `K_at(0)` (the K that gave `R_cm`), steps of +-h."""
    ends = [rotation_given_K(solver, normal_map, segments, K_at(s * h), R_cm, sky, local=True) for s in (1, -1)]
    return log_so3(R_cm.T @ ends[0]) / (2 * h) - log_so3(R_cm.T @ ends[1]) / (2 * h)


def replace_cov(visual: VisualRotation, solver: JointSolver, cov: np.ndarray) -> VisualRotation:
    """`visual` with the covariance `cov` (symmetrised, eigenvalues clipped to [0, the solver's cap])."""
    return dataclasses.replace(visual, cov=capped_covariance(cov, solver.config))
