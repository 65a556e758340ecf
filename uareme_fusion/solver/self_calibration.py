"""One camera's intrinsics from many frames: the focal length and principal point pooled over a sequence.

A video or a folder of images from one camera has one K. A single frame tells the focal length
(`focal.py`) but not the principal point: shifting it by dc pixels looks like rotating the camera by
about dc / f, so each frame alone trades one for the other. Over frames seen from different
directions the trade differs, and one K shared by all of them fixes both.

Model (square pixels): theta = (log f, cx, cy), K(theta) = [[f, 0, cx], [0, f, cy], [0, 0, 1]];
frame i has R_i = R0_i Exp(delta_i) (right perturbation of its initial Manhattan rotation `R_cm`,
Manhattan axes as columns in the camera frame). Minimised jointly over theta and every delta_i:

    sum_ij rho( d_ij(theta, R_i) / s )                         segments, each on its nearest axis k
  + sum_i |L_i^T Log(R_Ni^T R_i)|^2                            the normals' own rotation of frame i
  + |(cx, cy) - centre|^2 / s_c^2                              the principal point's prior

d_ij the distance (pixels) of segment j's end point from the line through its midpoint and the
vanishing point K(theta) r_ik (finite or not), s = `endpoint_noise_px`, rho the Cauchy loss at
`robust_scale`; each segment's axis is re-chosen at the current estimate between rounds. In pixels, not
as the angle of the segment's interpretation plane to r_ik: that angle shrinks for every segment as f
grows (every plane then contains the optical axis), and the fit would run to f -> inf.
The normals term is off by default (`SelfCalibrationConfig.with_normals`): they do not depend on K and
could hold each frame's rotation while the segments move K, but the learned normals' own bias then moves
K. The prior (the image centre, std `principal_point_prior_fraction` of the width, the spread real
cameras show) keeps the principal point near the centre when the frames say little; when they do not
determine it to `max_principal_point_std_fraction`, it is held at the centre and f alone is pooled.
Solved by iteratively reweighted Levenberg-Marquardt with the analytic sparse Jacobian (each delta_i
touches only frame i's residuals): about 1 s for 110 real frames.

Uncertainty: a delete-a-group jackknife over `jackknife_groups` consecutive blocks of frames (the fit
repeated without each block), which holds the correlation between neighbouring frames; never below the
Gauss-Newton covariance of the fit. Errors common to all frames (what the pinhole model leaves out)
escape both, so frames solved with a pooled K keep the principal-point floor of `focal.py`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial.transform import Rotation

from ..errors import InputError
from .line_detection import LineSegments
from ..pinhole import focal_from_hfov, pinhole
from ..rotations import nearest_symmetric, skew
from ..types import NormalMap, VisualRotation
from .focal import FocalConfig, FocalEstimate, replace_cov, rotation_slope, solve_given_K
from .joint import JointSolver


@dataclass(frozen=True)
class SelfCalibrationConfig:
    endpoint_noise_px: float = FocalConfig.endpoint_noise_px
    """Segment end point noise s (pixels), as `FocalConfig.endpoint_noise_px`."""
    robust_scale: float = 3.0
    """Cauchy scale in units of s: segments further than this from every axis count little."""
    rounds: int = 4
    """Axis assignments re-chosen this many times (fewer when K settles to `settled_px`)."""
    settled_px: float = 0.05
    """A round that moves f, cx and cy each by less than this (pixels) ends the rounds."""
    jackknife_groups: int = 8
    """Consecutive blocks of frames the jackknife leaves out in turn (count); with fewer than twice as
    many frames the Gauss-Newton covariance alone is reported."""
    min_frames: int = 3
    """Fewer frames with segments than this: nothing is pooled."""
    min_segments: int = 6
    """Frames with fewer segments take no part."""
    principal_point_prior_fraction: float = FocalConfig.principal_point_std_fraction
    """s_c / width: the principal point's prior std (as `FocalConfig.principal_point_std_fraction`)."""
    max_principal_point_std_fraction: float = 0.01
    """The principal point is taken from the fit only when its std (each axis) is below this fraction of
    the width, half the prior's; otherwise it is held at the centre and f alone is pooled. ICSL at every
    second frame: icsl_corridor_more (70 frames) std (3.2, 2.3) px; icsl_corridor (40 frames, looking along
    the corridor) std (10.9, 5.4) px with the principal point 44 px left of the centre."""
    max_relative_focal_std: float = FocalConfig.max_relative_std
    """Above this std(f)/f the frames could not tell f: nothing is pooled (as `FocalConfig.max_relative_std`)."""
    hfov_range_deg: tuple[float, float] = FocalConfig.hfov_range_deg
    """Fields of view searched (as `FocalConfig.hfov_range_deg`); a fit that ends at either (log f within
    `_AT_BOUND` of it) is refused: the frames then say only that f lies beyond."""
    with_normals: bool = False
    """Hold each frame's rotation by its normals-only rotation too (FrameEvidence.normals_*). Off: the
    learned normals' own bias then moves K (ICL kt3, rendered, true f 481.2 and centre (319.5, 239.5):
    f 483.5, (320.4, 240.3) from the segments alone; 494.6, (327.7, 239.4) with the normals)."""


@dataclass(frozen=True)
class FrameEvidence:
    """What one frame brings: its segments, a first Manhattan rotation `R_cm` (e.g. its own solve), and
    optionally the normals-only rotation `normals_R_cm` with its covariance `normals_cov` (rad^2)."""

    segments: LineSegments
    R_cm: np.ndarray
    normals_R_cm: np.ndarray | None = None
    normals_cov: np.ndarray | None = None


@dataclass(frozen=True)
class PooledIntrinsics:
    """The shared K of a sequence, with the covariance of (f, cx, cy) in pixels^2."""

    K: np.ndarray
    cov_px2: np.ndarray
    n_frames: int
    width: int
    height: int
    principal_point_estimated: bool = True
    """False: the frames could not tell it, it is the image centre (f alone was pooled)."""

    @property
    def f_px(self) -> float:
        return float(self.K[0, 0])

    @property
    def std_px(self) -> np.ndarray:
        """Standard deviations of (f, cx, cy), pixels."""
        return np.sqrt(np.diag(self.cov_px2))

    @property
    def origin(self) -> str:
        what = ("focal length and principal point pooled" if self.principal_point_estimated
                else "focal length pooled; principal point at the image centre")
        return f"estimated from {self.n_frames} frames ({what})"

    def focal_estimate(self) -> FocalEstimate:
        """As the `FocalEstimate` every frame reports (source "estimated", `origin` says pooled)."""
        std = self.std_px
        return FocalEstimate(self.K, "estimated", std_px=float(std[0]), width=self.width, origin=self.origin,
                             principal_point_std_px=(float(std[1]), float(std[2])) if self.principal_point_estimated
                             else None)


def pool_intrinsics(frames: list[FrameEvidence], f_init_px: float,
                    config: SelfCalibrationConfig | None = None) -> PooledIntrinsics | None:
    """The K shared by `frames` (module docstring), starting from `f_init_px` and the image centre; the
    principal point stays at the centre (f alone is pooled) unless the frames determine it to
    `max_principal_point_std_fraction` of the width. None when fewer than `min_frames` frames have
    segments or f stays undetermined; an InputError when the frames' image sizes differ (one camera, one
    size)."""
    cfg = config or SelfCalibrationConfig()
    sizes = [(fr.segments.width, fr.segments.height) for fr in frames]
    odd = next((i for i, size in enumerate(sizes) if size != sizes[0]), None)
    if odd is not None:
        raise InputError(f"frame {odd}: {sizes[odd][0]}x{sizes[odd][1]} px, but frame 0 is "
                         f"{sizes[0][0]}x{sizes[0][1]}: one camera's frames have one size")
    used = [i for i, fr in enumerate(frames) if len(fr.segments) >= cfg.min_segments]
    if len(used) < cfg.min_frames:
        return None
    chosen = [frames[i] for i in used]
    fit = _fit(_Problem(chosen, cfg), f_init_px, cfg)
    if fit is not None and np.sqrt(np.diag(fit[1])[1:]).max() > cfg.max_principal_point_std_fraction * fit[0].width:
        fit = _fit(_Problem(chosen, cfg, centre_fixed=True), f_init_px, cfg)
    if fit is None:
        return None
    problem, cov, x = fit
    f = math.exp(x[0])
    J = np.diag([f, 1.0, 1.0])  # d(f, cx, cy) / d(log f, cx, cy)
    cov_px2 = J @ cov @ J
    if not math.sqrt(cov_px2[0, 0]) / f <= cfg.max_relative_focal_std:
        return None
    return PooledIntrinsics(pinhole(f, f, x[1], x[2]), cov_px2, len(used), problem.width, problem.height,
                            principal_point_estimated=not problem.centre_fixed)


def _fit(problem: "_Problem", f_init_px: float, cfg: SelfCalibrationConfig):
    """(problem, covariance of theta, x) of one fit, or None when it fails. The covariance is the
    jackknife's (when there are frames enough) with its variances raised to the Gauss-Newton ones."""
    x = problem.solve(problem.start(f_init_px))
    if x is None:
        return None
    gauss_newton = problem.gauss_newton_cov()
    cov = _jackknife_cov(problem, x, cfg) if problem.n_frames >= 2 * cfg.jackknife_groups else gauss_newton
    cov = cov + np.diag(np.maximum(np.diag(gauss_newton) - np.diag(cov), 0.0))
    if problem.centre_fixed:
        cov[1:, :] = cov[:, 1:] = 0.0
    return problem, cov, x


def solve_with_pooled_K(solver: JointSolver, normal_map: NormalMap | None, segments: LineSegments | None,
                        pooled: PooledIntrinsics, R_init=None, t_s: float | None = None,
                        step_px: float = 2.0, sky=None) -> VisualRotation:
    """One frame's joint solve with the pooled K, its covariance widened by K's: cov += S C S^T, C the
    covariance of (f, cx, cy) and S = d delta / d (f, cx, cy) by central differences of `step_px` (the
    normals alone do not depend on K: a frame without segments is returned as solved)."""
    visual = solve_given_K(solver, normal_map, segments, pooled.K, R_init, t_s, sky)
    if "lines" not in visual.cues and "sky" not in visual.cues:
        return visual
    slopes = []
    for k in range(3):
        shift = np.zeros(3)
        shift[k] = 1.0

        def K_at(s, shift=shift):
            f, cx, cy = np.array([pooled.f_px, *pooled.K[:2, 2]]) + s * shift
            return pinhole(f, f, cx, cy)

        slopes.append(rotation_slope(solver, normal_map, segments, K_at, visual.R_cm, step_px, sky))
    S = np.array(slopes).T
    return replace_cov(visual, solver, visual.cov + S @ pooled.cov_px2 @ S.T)


def _jackknife_cov(problem: "_Problem", x: np.ndarray, cfg: SelfCalibrationConfig) -> np.ndarray:
    """Delete-a-group jackknife covariance of theta over `jackknife_groups` consecutive blocks of frames."""
    groups = np.array_split(np.arange(problem.n_frames), cfg.jackknife_groups)
    thetas = []
    for g in groups:
        keep = np.setdiff1d(np.arange(problem.n_frames), g)
        sub = problem.subset(keep)
        xs = sub.solve(np.concatenate([x[:3], np.zeros(3 * len(keep))]), rounds=2)
        if xs is not None:
            thetas.append(xs[:3])
    if len(thetas) < 2:
        return np.full((3, 3), np.inf)
    t = np.array(thetas)
    n = len(t)
    d = t - t.mean(axis=0)
    return (n - 1) / n * d.T @ d


_FIXED = 1e-6
"""The principal point's prior std, as a fraction of its usual one, when it is held at the centre."""

_AT_BOUND = 1e-3
"""log f this close to a bound of the searched range: the fit ran into it (LM only takes steps that stay
inside, so it stops there rather than leaving)."""


class _Problem:
    """The stacked residuals of the module docstring over a list of frames."""

    def __init__(self, frames: list[FrameEvidence], cfg: SelfCalibrationConfig, centre_fixed: bool = False):
        self.frames, self.cfg, self.centre_fixed = frames, cfg, centre_fixed
        self.n_frames = len(frames)
        seg = frames[0].segments
        self.width, self.height = seg.width, seg.height
        self.centre = np.array([(seg.width - 1) / 2.0, (seg.height - 1) / 2.0])
        self.ends = np.concatenate([fr.segments.endpoints_px for fr in frames])
        self.mid = np.concatenate([self.ends.mean(axis=1), np.ones((len(self.ends), 1))], axis=1)
        self.half = np.concatenate([0.5 * (self.ends[:, 1] - self.ends[:, 0]), np.zeros((len(self.ends), 1))], axis=1)
        self.frame_of = np.concatenate([np.full(len(fr.segments), i) for i, fr in enumerate(frames)])
        self.R0 = np.array([np.asarray(fr.R_cm, float) for fr in frames])
        self.has_normals = np.array([cfg.with_normals and fr.normals_R_cm is not None and fr.normals_cov is not None
                                     for fr in frames])
        self.R_normals = np.array([nearest_symmetric(fr.normals_R_cm, R)[0] if ok else np.eye(3)
                                   for fr, R, ok in zip(frames, self.R0, self.has_normals)])
        self.L_normals = np.array([_information_root(fr.normals_cov) if ok else np.zeros((3, 3))
                                   for fr, ok in zip(frames, self.has_normals)])
        self.prior_std_px = cfg.principal_point_prior_fraction * self.width * (_FIXED if centre_fixed else 1.0)
        lo, hi = (math.log(focal_from_hfov(self.width, a)) for a in cfg.hfov_range_deg[::-1])
        self.log_f_range = (lo, hi)

    def inside(self, x: np.ndarray) -> bool:
        """Whether f ended inside the searched range and (cx, cy) inside the image."""
        lo, hi = self.log_f_range
        return bool(lo < x[0] < hi and 0.0 <= x[1] <= self.width - 1 and 0.0 <= x[2] <= self.height - 1)

    def at_bound(self, x: np.ndarray) -> bool:
        """Whether log f ended within `_AT_BOUND` of either end of the searched range."""
        lo, hi = self.log_f_range
        return bool(min(x[0] - lo, hi - x[0]) < _AT_BOUND)

    def subset(self, keep: np.ndarray) -> "_Problem":
        """The problem over the frames `keep`, starting from their rotations as now."""
        frames = [dataclasses.replace(self.frames[i], R_cm=self.R0[i]) for i in keep]
        return _Problem(frames, self.cfg, self.centre_fixed)

    def start(self, f_px: float) -> np.ndarray:
        log_f = np.clip(math.log(f_px), *self.log_f_range)
        return np.concatenate([[log_f], self.centre, np.zeros(3 * self.n_frames)])

    def rotations(self, x: np.ndarray) -> np.ndarray:
        return self.R0 @ Rotation.from_rotvec(x[3:].reshape(-1, 3)).as_matrix()

    def _segment_geometry(self, x: np.ndarray, axes: np.ndarray, R: np.ndarray):
        """(u, v, l) per segment at its axis `axes[j]` (each (N, 3)): u = R_i r-hat_k (R `rotations(x)`),
        the vanishing point v = K u and the line l = m x v through its midpoint m (homogeneous); its half
        vector (x2 - x1) / 2 is `self.half`."""
        f = math.exp(x[0])
        u = R[self.frame_of, :, axes]
        v = u @ pinhole(f, f, x[1], x[2]).T
        l = np.cross(self.mid, v)
        return u, v, l

    def _end_distances(self, l: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance (N,) in pixels of each segment's end point from its line `l` (N, 3, through
        its midpoint), the norm of l's [a, b] it was divided by)."""
        den = np.maximum(np.hypot(l[:, 0], l[:, 1]), 1e-12)
        return np.einsum("ni,ni->n", l, self.half) / den, den

    def axis_distances(self, x: np.ndarray) -> np.ndarray:
        """d_jk (N, 3) in pixels: the distance of segment j's end point from the line through its midpoint
        and the vanishing point K r_k of axis k (finite or not)."""
        n, R = len(self.ends), self.rotations(x)
        return np.stack([self._end_distances(self._segment_geometry(x, np.full(n, k), R)[2])[0] for k in range(3)],
                        axis=1)

    def nearest_axes(self, x: np.ndarray) -> np.ndarray:
        return np.argmin(np.abs(self.axis_distances(x)), axis=1)

    def _normals_phi(self, R: np.ndarray) -> np.ndarray | None:
        """phi_i = Log(R_Ni^T R_i) (F, 3) of the frames' rotations `R`, or None when no frame has the
        normals' rotation (`with_normals` off: their rows are zero)."""
        if not self.has_normals.any():
            return None
        return Rotation.from_matrix(np.swapaxes(self.R_normals, 1, 2) @ R).as_rotvec()

    def residuals(self, x: np.ndarray, axes: np.ndarray) -> np.ndarray:
        R = self.rotations(x)
        lines = self._end_distances(self._segment_geometry(x, axes, R)[2])[0]
        phi = self._normals_phi(R)
        normals = np.zeros(3 * self.n_frames) if phi is None else np.einsum("fij,fj->fi", self.L_normals, phi).ravel()
        prior = (x[1:3] - self.centre) / self.prior_std_px
        return np.concatenate([lines / self.cfg.endpoint_noise_px, normals, prior])

    def jacobian(self, x: np.ndarray, axes: np.ndarray) -> csr_matrix:
        """d residuals / d x (sparse); for each delta_i as a right perturbation of the current R_i, i.e. exact
        at delta_i = 0 (`solve` re-centres R0 on every round, so the steps stay small). The normals' rows
        are L_i^T J_r^-1(phi_i), phi_i = Log(R_Ni^T R_i)."""
        f = math.exp(x[0])
        R = self.rotations(x)
        u, v, l = self._segment_geometry(x, axes, R)
        distance, den = self._end_distances(l)
        dr_dl = (self.half / den[:, None] - (distance / den**2)[:, None] * l * [1.0, 1.0, 0.0]) / self.cfg.endpoint_noise_px
        dr_dv = np.cross(dr_dl, self.mid)  # dr/dl . (m x dv) = (dr/dl x m) . dv
        d_theta = np.stack([dr_dv[:, 0] * f * u[:, 0] + dr_dv[:, 1] * f * u[:, 1],
                            dr_dv[:, 0] * u[:, 2], dr_dv[:, 1] * u[:, 2]], axis=1)
        # v(delta) = K R Exp(delta) e_k, dv = K R (d delta x e_k): dr = a . (d delta x e_k) = (e_k x a) . d delta
        a = np.einsum("ni,ij,njk->nk", dr_dv, pinhole(f, f, x[1], x[2]), R[self.frame_of])
        d_delta = np.cross(np.eye(3)[axes], a)
        n_seg, F = len(self.ends), self.n_frames
        rows = [np.repeat(np.arange(n_seg), 6)]
        cols = [np.concatenate([np.tile(np.arange(3), (n_seg, 1)), 3 + 3 * self.frame_of[:, None] + np.arange(3)],
                               axis=1).ravel()]
        vals = [np.concatenate([d_theta, d_delta], axis=1).ravel()]
        block = np.arange(3 * F)
        rows.append(n_seg + np.repeat(block, 3))
        cols.append((3 + 3 * (block // 3)[:, None] + np.arange(3)).ravel())
        phi = self._normals_phi(R)
        vals.append(np.zeros(9 * F) if phi is None else (self.L_normals @ _right_jacobian_inverse(phi)).reshape(-1))
        rows.append(n_seg + 3 * F + np.array([0, 1]))
        cols.append(np.array([1, 2]))
        vals.append(np.full(2, 1.0 / self.prior_std_px))
        return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n_seg + 3 * F + 2, 3 + 3 * F))

    def solve(self, x: np.ndarray, rounds: int | None = None) -> np.ndarray | None:
        """Rounds of (nearest axes at x, robust least squares, R0 re-centred on the result); None when a
        fit fails or f leaves the searched range or ends at its bound."""
        for _ in range(rounds or self.cfg.rounds):
            axes = self.nearest_axes(x)
            x_new = self._levenberg_marquardt(x, axes)
            if x_new is None or not self.inside(x_new) or self.at_bound(x_new):
                return None
            moved = np.abs(np.append(math.exp(x[0]) - math.exp(x_new[0]), x[1:3] - x_new[1:3])).max()
            self.R0 = self.rotations(x_new)
            x = np.concatenate([x_new[:3], np.zeros(3 * self.n_frames)])
            if moved < self.cfg.settled_px:
                break
        return x

    def _levenberg_marquardt(self, x: np.ndarray, axes: np.ndarray, max_iterations: int = 50,
                             tolerance: float = 1e-9) -> np.ndarray | None:
        """Iteratively reweighted Levenberg-Marquardt on sum rho(r^2) (normal equations, (3 + 3F)^2, dense);
        keeps H = J^T W J of the last step for `gauss_newton_cov`."""
        cost, r = self._cost(x, axes)
        lam = 1e-3
        for _ in range(max_iterations):
            w = self._loss(r**2)[1]
            J = self.jacobian(x, axes)
            Jw = J.multiply(w[:, None]).tocsr()
            H, g = (J.T @ Jw).toarray(), J.T @ (w * r)
            self._information = H
            while True:
                step = np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-12), -g)
                trial = x + step
                if self.inside(trial):
                    trial_cost, trial_r = self._cost(trial, axes)
                    if trial_cost <= cost:
                        break
                lam *= 4.0
                if lam > 1e8:
                    return x
            x, r, lam, settled = trial, trial_r, max(lam / 3.0, 1e-9), cost - trial_cost <= tolerance * max(cost, 1.0)
            cost = trial_cost
            if settled:
                break
        return x if np.all(np.isfinite(x)) else None

    def _cost(self, x: np.ndarray, axes: np.ndarray) -> tuple[float, np.ndarray]:
        """(sum rho(r^2), the residuals r) at x."""
        r = self.residuals(x, axes)
        return float(self._loss(r**2)[0].sum()), r

    def _loss(self, z: np.ndarray) -> np.ndarray:
        """(rho, rho') of z = r^2: Cauchy on the segments' residuals, plain squares on the normals' and the
        prior's."""
        n_seg = len(self.ends)
        a = self.cfg.robust_scale**2
        out = np.empty((2, len(z)))
        out[0], out[1] = z, 1.0
        zs = z[:n_seg]
        out[0, :n_seg] = a * np.log1p(zs / a)
        out[1, :n_seg] = 1.0 / (1.0 + zs / a)
        return out

    def gauss_newton_cov(self) -> np.ndarray:
        """The (3, 3) block of theta in (J^T W J)^-1 at the last step (W the robust weights)."""
        return np.linalg.pinv(self._information)[:3, :3]


def _right_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """J_r^-1(phi) (n, 3, 3) of rotation vectors phi (n, 3): Log(Exp(phi) Exp(d)) = phi + J_r^-1(phi) d + O(d^2)."""
    theta = np.linalg.norm(phi, axis=1)
    P = skew(phi)
    small = theta < 1e-4
    t = np.where(small, 1.0, theta)
    c = np.where(small, 1.0 / 12.0, 1.0 / t**2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    return np.eye(3) + 0.5 * P + c[:, None, None] * P @ P


def _information_root(cov: np.ndarray) -> np.ndarray:
    """L^T with L L^T = cov^-1 (cov (3, 3) rad^2, eigenvalues floored): |L^T d|^2 = d^T cov^-1 d."""
    val, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    return (vec / np.sqrt(np.maximum(val, 1e-12))).T
