"""The horizon of open scenes from the sky/ground boundary, and that line as a cue on the up vector.

Detection (one image, no intrinsics), after the classical sky-boundary detectors (colour and texture
likelihoods of sky, a boundary fitted robustly):
1. a per-pixel sky probability at `SkyHorizonConfig.work_size_px` (the longer side): a tiny MLP
   (`SKY_WEIGHTS`, trained by `tools/train_sky.py` on horizon_uav's land masks, clips a and b only)
   on colour and local texture features (`sky_features`);
2. the line that best separates sky from ground: for each of `angle_steps` orientations of its sky
   normal n (all 360 deg: a photo held sideways has its sky on the left), the offset t maximising
   sum_i (2 p_i - 1) [n . x_i > t] (a vote over projections, one `np.bincount`);
3. the boundary near that line: along it, where the probability crosses 1/2 within a band, fitted
   by iteratively reweighted least squares (Tukey) as v = v0 + s u in the line's own frame; the
   covariance of (v0, s) from the residual scatter over the root of the effective number of
   boundary points (neighbouring points share errors: one point per `correlation_length_px`);
4. checks that a sky is there at all (`SkyHorizon.failed_checks`): enough sky and ground on each side, the
   two sides well told apart, the ground side textured and the sky side smooth, a long and straight
   boundary. A white wall or ceiling fails them: smooth on both sides, or a boundary that bends.

As a cue (`HorizonCue`): with K, the line l (a x + b y + c = 0, positive on the sky side) is world up
in the camera, up_c ~ K^T l (`overlay.horizon.horizon_line` inverted), with a 2x2 covariance on the
tangent plane of up_c; its cost in the joint solve is 0.5 e^T W e, e the tangent offset of the
rotation's up axis from up_c and W the inverse of that covariance, so that its Hessian is its
information (as the other cues' a_c H_c).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..rotations import log_so3, manhattan_symmetries
from .joint import _Cue

SKY_WEIGHTS = Path(__file__).with_name("weights") / "sky_mlp.npz"
"""The sky classifier's weights (`tools/train_sky.py`; a few kB)."""


@dataclass(frozen=True)
class SkyHorizonConfig:
    """How the sky boundary is found and when it counts (units in the names)."""

    work_size_px: int = 96
    """The probability map's longer side (the boundary is then refined to a fraction of its pixels)."""
    coarse_size_px: int = 32
    """The longer side of the map the separating line is searched on (it only has to fall in the band)."""
    angle_steps: int = 72
    """Orientations of the separating line's normal searched over 360 deg (5 deg apart)."""
    band_fraction: float = 0.12
    """Half-width of the band around the separating line searched for the boundary, fraction of the
    work image's diagonal."""
    tukey_width_px: float = 3.0
    """Tukey loss width of the boundary fit, work pixels (about 4.7 times the scatter of a clean fit)."""
    fit_rounds: int = 6
    correlation_length_px: float = 4.0
    """Boundary points closer than this (work pixels) share errors (one effective point each)."""
    std_scale: float = 1.0
    """Multiplies the fit's standard deviations."""
    offset_floor_work_px: float = 1.5
    """Added in quadrature to the offset's std (work pixels): where the classifier puts a boundary is
    biased by about a work pixel (texture features reach across it; 6 px at 480 on a synthetic scene)."""
    angle_floor_deg: float = 0.4
    """Added in quadrature to the angle's std: the roll error median on horizon_uav's even frames."""
    min_side_fraction: float = 0.01
    """Each side of the line must hold at least this fraction of the image."""
    min_separation: float = 1.6
    """Mean of (2 p - 1) on the sky side minus on the ground side (2 is perfect; chance 0). horizon_uav
    (every 3rd photo): 1.82 at least, median 1.96; indoor frames whose walls or ceiling looked like sky
    (ICSL, ICL kt3, every 5th: 16 of 65 with the other checks alone): 1.21 at most."""
    min_span_fraction: float = 0.85
    """The boundary's inliers must span this fraction of the line's length inside the image."""
    max_residual_fraction: float = 0.012
    """Robust scatter of the boundary about its line, fraction of the work image's diagonal."""
    min_texture_ratio: float = 0.8
    """Mean gradient on the ground side over the sky side: the ground is not the smoother side (horizon_uav:
    1.006 at least in every 3rd photo, 0.87 under clouds)."""


@dataclass(frozen=True)
class SkyHorizon:
    """A sky boundary line in the full image's pixels: `line` [a, b, c] with a x + b y + c = 0, [a, b]
    unit, positive on the sky side; `cov_line` the 2x2 covariance of (offset of the line at the image
    centre along its normal, px; its angle, rad); and what the checks looked at."""

    line: np.ndarray
    cov_line: np.ndarray
    height: int
    width: int
    separation: float
    sky_fraction: float
    span_fraction: float
    residual_fraction: float
    texture_ratio: float
    inliers: int

    @property
    def offset_std_px(self) -> float:
        return float(np.sqrt(self.cov_line[0, 0]))

    @property
    def angle_std_deg(self) -> float:
        return float(np.degrees(np.sqrt(self.cov_line[1, 1])))

    def failed_checks(self, config: SkyHorizonConfig) -> list[str]:
        """The names of the checks this boundary fails (none: a sky horizon)."""
        checks = {"side": min(self.sky_fraction, 1.0 - self.sky_fraction) >= config.min_side_fraction,
                  "separation": self.separation >= config.min_separation,
                  "span": self.span_fraction >= config.min_span_fraction,
                  "straight": self.residual_fraction <= config.max_residual_fraction,
                  "texture": self.texture_ratio >= config.min_texture_ratio}
        return [name for name, ok in checks.items() if not ok]

    def as_dict(self) -> dict:
        return {"line": self.line.tolist(), "offset_std_px": self.offset_std_px, "angle_std_deg": self.angle_std_deg,
                "separation": self.separation, "sky_fraction": self.sky_fraction, "span_fraction": self.span_fraction,
                "residual_fraction": self.residual_fraction, "texture_ratio": self.texture_ratio}

    def observation(self, K: np.ndarray) -> HorizonObservation:
        """The line as world up in the camera frame under K, with its covariance (`up_from_line`)."""
        return up_from_line(self.line, self.cov_line, K, self.height, self.width)


@dataclass(frozen=True)
class HorizonObservation:
    """World up in the camera frame (unit, OpenCV) seen by the sky boundary, and the 2x2 covariance
    (rad^2) of its offset in the tangent basis `basis` (3, 2) at `up_c`."""

    up_c: np.ndarray
    cov_rad2: np.ndarray
    basis: np.ndarray


# --- the sky probability ------------------------------------------------------------------------------
def work_image(rgb: np.ndarray, work_size_px: int) -> np.ndarray:
    """`rgb` (H, W, 3) uint8 area-resized so that its longer side is `work_size_px`, float32 in [0, 1]."""
    h, w = rgb.shape[:2]
    s = work_size_px / max(h, w)
    size = (max(round(w * s), 8), max(round(h * s), 8))
    return cv2.resize(rgb, size, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0


def sky_features(small: np.ndarray) -> np.ndarray:
    """Per-pixel features (h, w, F) of a work image (float RGB in [0, 1]): colour (r, g, b, brightness,
    blue minus red, blue minus green, red minus green, saturation), the same chroma over 9x9 pixels, local
    texture (gradient magnitude at three scales and the 3x3 standard deviation of the brightness, in
    log), and the brightness relative to the image's median and the image's contrast."""
    grey = small.mean(axis=2)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3)
    grad = np.sqrt(gx * gx + gy * gy)
    mean3 = cv2.blur(grey, (3, 3))
    std3 = np.sqrt(np.maximum(cv2.blur(grey * grey, (3, 3)) - mean3 * mean3, 0.0))
    r, g, b = small[..., 0], small[..., 1], small[..., 2]
    sat = small.max(axis=2) - small.min(axis=2)
    chroma = np.stack([b - r, b - g, r - g, sat], axis=-1)
    wide = cv2.blur(chroma, (9, 9))
    log = [np.log(x + 0.01) for x in (grad, cv2.blur(grad, (7, 7)), cv2.blur(grad, (15, 15)), std3)]
    feats = [r, g, b, grey, *np.moveaxis(chroma, -1, 0), *np.moveaxis(wide, -1, 0), *log,
             grey - float(np.median(grey)), np.full_like(grey, float(np.std(grey)))]
    return np.stack(feats, axis=-1).astype(np.float32)


@functools.cache
def _weights(path: Path = SKY_WEIGHTS) -> dict:
    with np.load(path) as data:
        return {k: data[k].astype(np.float32) for k in data.files}


def sky_probability(small: np.ndarray, weights: dict | None = None) -> np.ndarray:
    """P(sky) (h, w) of each pixel of a work image: the MLP (features standardised, one hidden tanh
    layer, logistic output), then a 3x3 blur. The hidden layer's product runs in OpenCV's gemm, not numpy's
    BLAS: (6912, 18) x (18, 12) is large enough for OpenBLAS to start its worker threads, which then spin
    beside the pipeline (on 2 loaded cores: 8 ms against 0.4 a call, and every later stage slowed)."""
    wts = weights or _weights()
    x = (sky_features(small).reshape(-1, wts["mean"].size) - wts["mean"]) / wts["std"]
    hidden = np.tanh(cv2.gemm(x, wts["W1"], 1.0, None, 0.0) + wts["b1"])
    logit = hidden @ wts["W2"] + wts["b2"]
    p = 1.0 / (1.0 + np.exp(-np.clip(logit[:, 0], -30, 30)))
    return cv2.blur(p.reshape(small.shape[:2]).astype(np.float32), (3, 3))


# --- the boundary ---------------------------------------------------------------------------------------
def _separating_line(p: np.ndarray, steps: int, coarse_px: int) -> tuple[np.ndarray, float]:
    """(n, t): the sky normal n (unit) and offset t (work pixels, from the work image's centre) of the line
    n . x = t that best separates P(sky) > 1/2 (n . x > t) from the rest (step 2 of the module docstring),
    searched on the map area-resized to `coarse_px` (the boundary fit then refines it)."""
    h, w = p.shape
    k = coarse_px / max(h, w)
    cw, ch = max(round(w * k), 4), max(round(h * k), 4)
    q = cv2.resize(p, (cw, ch), interpolation=cv2.INTER_AREA)
    ys, xs = np.mgrid[0:ch, 0:cw]
    pts = np.stack([xs.ravel() - (cw - 1) / 2.0, ys.ravel() - (ch - 1) / 2.0], axis=1)
    vote = 2.0 * q.ravel().astype(np.float64) - 1.0
    theta = np.linspace(0.0, 2 * np.pi, steps, endpoint=False)
    normals = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    half = 0.5 * np.hypot(ch, cw)
    nbins = int(2 * half) + 2
    bins = np.clip((pts @ normals.T + half).astype(np.intp), 0, nbins - 1)  # (N, steps)
    bins += nbins * np.arange(steps)[None, :]
    hist = np.bincount(bins.ravel(), weights=np.broadcast_to(vote[:, None], bins.shape).ravel(),
                       minlength=steps * nbins).reshape(steps, nbins)
    above = np.cumsum(hist[:, ::-1], axis=1)[:, ::-1]  # vote of the pixels with n . x >= bin
    i, j = np.unravel_index(int(np.argmax(above)), above.shape)
    return normals[i], float(j - half) / k


def _boundary_points(p: np.ndarray, n: np.ndarray, t: float, band_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples along the line n . x = t (work pixels, centred coordinates): u along it, and the offset
    v (along n) where P(sky) crosses 1/2 within +-band_px, one per unit of u (NaN where it does not)."""
    h, w = p.shape
    d = np.array([-n[1], n[0]])
    half = 0.5 * np.hypot(h, w)
    u = np.arange(-half, half + 1.0)
    v = np.arange(-band_px, band_px + 0.5, 0.5)
    xy = (t * n)[None, None, :] + u[:, None, None] * d + v[None, :, None] * n  # (U, V, 2)
    mx = (xy[..., 0] + (w - 1) / 2.0).astype(np.float32)
    my = (xy[..., 1] + (h - 1) / 2.0).astype(np.float32)
    inside = (mx >= 0) & (mx <= w - 1) & (my >= 0) & (my <= h - 1)
    prof = cv2.remap(p, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE) - 0.5
    prof = np.where(inside, prof, np.nan)
    # the crossing from ground (< 0) to sky (> 0) nearest the line along each profile
    s0, s1 = prof[:, :-1], prof[:, 1:]
    cross = (s0 < 0) & (s1 >= 0)
    frac = np.where(cross, -s0 / np.where(cross, s1 - s0, 1.0), np.nan)
    vc = v[:-1][None, :] + 0.5 * frac
    dist = np.where(cross, np.abs(vc), np.inf)
    pick = np.argmin(dist, axis=1)
    rows = np.arange(len(u))
    found = np.isfinite(dist[rows, pick])
    out = np.where(found, vc[rows, pick], np.nan)
    line_inside = inside[:, len(v) // 2]
    return u[line_inside], out[line_inside]


def _robust_line_fit(u: np.ndarray, v: np.ndarray, width_px: float, rounds: int):
    """v ~ v0 + s u by IRLS with Tukey's biweight: (v0, s, weights, robust residual scale)."""
    A = np.stack([np.ones_like(u), u], axis=1)
    wts = np.ones_like(u)
    coef = np.zeros(2)
    for _ in range(rounds):
        W = wts[:, None] * A
        coef = np.linalg.lstsq(W.T @ A + 1e-9 * np.eye(2), W.T @ v, rcond=None)[0]
        r = v - A @ coef
        wts = np.where(np.abs(r) < width_px, (1.0 - (r / width_px) ** 2) ** 2, 0.0)
    r = v - A @ coef
    inl = wts > 0
    scale = float(1.4826 * np.median(np.abs(r[inl]))) if inl.sum() > 2 else float("inf")
    return coef, wts, scale


def detect_sky_horizon(rgb: np.ndarray, config: SkyHorizonConfig | None = None) -> SkyHorizon | None:
    """The sky boundary of an RGB uint8 image (H, W, 3) as a line with its covariance, or None when no
    boundary could be fitted at all (check `failed_checks` before trusting one)."""
    cfg = config or SkyHorizonConfig()
    if rgb is None or rgb.ndim != 3 or min(rgb.shape[:2]) < 16:
        return None
    H, W = rgb.shape[:2]
    small = work_image(rgb, cfg.work_size_px)
    p = sky_probability(small)
    h, w = p.shape
    n, t = _separating_line(p, cfg.angle_steps, cfg.coarse_size_px)
    diag = float(np.hypot(h, w))
    u, v = _boundary_points(p, n, t, cfg.band_fraction * diag)
    ok = np.isfinite(v)
    if ok.sum() < 8:
        return None
    coef, wts, scale = _robust_line_fit(u[ok], v[ok], cfg.tukey_width_px, cfg.fit_rounds)
    v0, s = coef
    # the refined line in work pixels (centred): points t n + u d + (v0 + s u) n
    d = np.array([-n[1], n[0]])
    direction = d + s * n
    direction /= np.linalg.norm(direction)
    normal = np.array([direction[1], -direction[0]])
    if normal @ n < 0:
        normal = -normal
    foot = (t + v0) * n
    # covariance of (offset at the centre along the normal, angle) from the fit
    inl = wts > 0
    uu = u[ok][inl]
    n_eff = max(np.ptp(uu) / cfg.correlation_length_px, 2.0) if uu.size else 2.0
    cov_coef = scale**2 * np.linalg.inv(np.array([[1.0, uu.mean()], [uu.mean(), (uu * uu).mean()]])) / n_eff
    cov_line_work = cfg.std_scale**2 * cov_coef + np.diag([cfg.offset_floor_work_px**2, np.radians(cfg.angle_floor_deg)**2])
    # full-image pixels: x_full = (x_work_centred) * k + centre_full
    k = max(H, W) / float(max(h, w))
    centre = np.array([(W - 1) / 2.0, (H - 1) / 2.0])
    c = -(normal @ (foot * k + centre))
    line = np.array([normal[0], normal[1], c])
    scale_to_full = np.diag([k, 1.0])  # offsets scale with the image, angles do not
    cov_line = scale_to_full @ cov_line_work @ scale_to_full
    # texture on each side and the separation
    ys, xs = np.mgrid[0:h, 0:w]
    side = (xs - (w - 1) / 2.0) * normal[0] + (ys - (h - 1) / 2.0) * normal[1] - (t + v0) > 0
    sky_fraction = float(side.mean())
    vote = 2.0 * p - 1.0
    separation = (float(vote[side].mean()) if side.any() else -1.0) - (float(vote[~side].mean()) if (~side).any() else 1.0)
    grey = small.mean(axis=2)
    grad = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=3))
    margin = np.abs((xs - (w - 1) / 2.0) * normal[0] + (ys - (h - 1) / 2.0) * normal[1] - (t + v0)) > 3
    g_sky = float(grad[side & margin].mean()) if (side & margin).any() else 0.0
    g_ground = float(grad[~side & margin].mean()) if (~side & margin).any() else 0.0
    span = float(np.ptp(uu) / max(len(u) - 1, 1)) if uu.size else 0.0
    return SkyHorizon(line=line, cov_line=cov_line, height=H, width=W, separation=separation,
                      sky_fraction=sky_fraction, span_fraction=span, residual_fraction=scale / diag,
                      texture_ratio=g_ground / max(g_sky, 1e-4), inliers=int(inl.sum()))


# --- the line as a constraint on up ---------------------------------------------------------------------
def tangent_basis(u: np.ndarray) -> np.ndarray:
    """Two unit vectors (3, 2) orthogonal to the unit vector `u` and to each other."""
    a = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(u, e1)], axis=1)


def up_from_line(line: np.ndarray, cov_line: np.ndarray, K: np.ndarray, height: int, width: int) -> HorizonObservation:
    """up_c ~ K^T l (the inverse of `overlay.horizon.horizon_line`), unit, and the covariance of its
    tangent offset from that of (offset at the image centre, angle) by central differences."""
    K = np.asarray(K, float)
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])

    def up_of(offset_px, angle_rad):
        a, b, c = line
        phi = np.arctan2(b, a) + angle_rad
        normal = np.array([np.cos(phi), np.sin(phi)])
        dist = a * centre[0] + b * centre[1] + c + offset_px  # signed distance of the centre (sky side > 0)
        l = np.array([normal[0], normal[1], dist - normal @ centre])
        up = K.T @ l
        return up / np.linalg.norm(up)

    up = up_of(0.0, 0.0)
    basis = tangent_basis(up)
    steps = (1.0, 1e-3)
    J = np.zeros((2, 2))
    for i, h in enumerate(steps):
        dp = up_of(*(h * np.eye(2)[i])) - up_of(*(-h * np.eye(2)[i]))
        J[:, i] = basis.T @ dp / (2 * h)
    return HorizonObservation(up, J @ cov_line @ J.T, basis)


class HorizonCue(_Cue):
    """The sky boundary's up in the joint solve: E_H(R) = 0.5 e^T W e, e = B^T r_k (the tangent offset
    of R's axis r_k nearest up_c, signed towards it, B the observation's tangent basis), W = cov^-1.
    Its weight a_c is 1 (E_H is already in information units), so a_c H_c is W on the two tilt
    directions and nothing about the rotation around up."""

    name = "sky"
    random_cost = 1.0

    def __init__(self, observation: HorizonObservation, floor_std_rad: float = np.radians(0.2)):
        cov = observation.cov_rad2 + floor_std_rad**2 * np.eye(2)
        super().__init__(observation, n_effective=2.0, scale=1.0, min_cost=1.0)
        self.obs = observation
        self.W = np.linalg.inv(0.5 * (cov + cov.T))

    def _axis(self, R):
        """(r, k): R's axis nearest up_c (sign towards it) and its index; R (3, 3) or (N, 3, 3)."""
        R = np.asarray(R, float)
        if R.ndim == 2:  # one rotation (each step of the solve): without the stacks' indexing, 4x faster
            dots = self.obs.up_c @ R
            k = int(np.argmax(np.abs(dots)))
            return (R[:, k] if dots[k] >= 0 else -R[:, k]), k
        dots = np.einsum("...ik,i->...k", R, self.obs.up_c)
        k = np.argmax(np.abs(dots), axis=-1)
        r = np.take_along_axis(R, k[..., None, None].repeat(3, axis=-2), axis=-1)[..., 0]
        sign = np.sign(np.take_along_axis(dots, k[..., None], axis=-1))
        return r * np.where(sign == 0, 1.0, sign), k

    def cost(self, R):
        r, _ = self._axis(R)
        e = r @ self.obs.basis
        return 0.5 * float(e @ self.W @ e) if e.ndim == 1 else 0.5 * np.einsum("...i,ij,...j->...", e, self.W, e)

    def derivatives(self, R):
        """Gradient and Gauss-Newton Hessian in the right perturbation: r(R Exp(d)) = r - R [e_k]x d."""
        R = np.asarray(R, float)
        r, k = self._axis(R)
        sign = np.sign(r @ R[:, k]) or 1.0
        e_k = np.zeros(3)
        e_k[k] = sign
        skew = np.array([[0, -e_k[2], e_k[1]], [e_k[2], 0, -e_k[0]], [-e_k[1], e_k[0], 0]])
        Jr = -R @ skew  # d r / d delta (3, 3)
        Je = self.obs.basis.T @ Jr  # (2, 3)
        e = self.obs.basis.T @ r
        return float(0.5 * e @ self.W @ e), Je.T @ self.W @ e, Je.T @ self.W @ Je

    def set_alpha(self, R, discounted: bool = True) -> None:
        self.alpha = 1.0

    def robust_cost(self, R, coarse: bool = False):
        return np.minimum(self.cost(R), 50.0)

    def labelled(self, R: np.ndarray) -> np.ndarray:
        """The labelling of R whose z axis is the axis nearest up_c, pointing up (the backends take m's z
        as up without gravity), nearest R among those."""
        options = np.asarray(R, float) @ manhattan_symmetries()  # (24, 3, 3)
        up = options[:, :, 2] @ self.obs.up_c
        keep = options[up > up.max() - 1e-9]
        angles = [np.linalg.norm(log_so3(np.asarray(R, float).T @ Q)) for Q in keep]
        return keep[int(np.argmin(angles))]

    def summary(self) -> dict:
        return {"up_c": self.obs.up_c.tolist()}


class SkyDetector:
    """`detect_sky_horizon` with the checks applied: `detect(rgb)` is a `SkyHorizon` that passed them all,
    or None (no sky boundary to trust in this image)."""

    def __init__(self, config: SkyHorizonConfig | None = None):
        self.config = config or SkyHorizonConfig()

    def detect(self, rgb: np.ndarray | None) -> SkyHorizon | None:
        return self.trusted(self.boundary(rgb))

    def boundary(self, rgb: np.ndarray | None) -> SkyHorizon | None:
        """The fitted boundary before the checks (`detect_sky_horizon`), None when none could be fitted."""
        return detect_sky_horizon(rgb, self.config) if rgb is not None else None

    def trusted(self, found: SkyHorizon | None) -> SkyHorizon | None:
        """`found` when it passes all the checks, else None."""
        return found if found is not None and not found.failed_checks(self.config) else None
