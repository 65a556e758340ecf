"""Surface normals and their confidence kappa from a depth map and pinhole intrinsics.

Each pixel gets the plane fitted to the valid depth in a square window around it. Depth sensors
(structured light, stereo, the noise models of rendered RGB-D datasets) measure along the pixel's
ray with fixed image coordinates, so we fit the plane as a linear regression in inverse depth:
a plane n . p = d seen through the ray p = z (x_bar, y_bar, 1) satisfies
    1/z = (n_x x_bar + n_y y_bar + n_z) / d,
which is affine in the pixel offsets (du, dv) from the window centre:
    1/z = c + a du + b dv,   n ~ -(a fx, b fy, c - a (u - cx) - b (v - cy)).
The 3x3 normal equations need only ten window sums, each one separable filter of the image by
centred offset kernels (no cancellation between large sums), and are solved per pixel in closed
form: no eigen-decomposition and no loop over pixels.

kappa is 1 / trace of the fitted normal's angular covariance (so that exp(-kappa theta^2) has the
fitted per-axis variance, the small-angle form of the paper's eq. 3), with the inverse-depth noise
the larger of the fit residual and a sensor model sigma_z = noise_quadratic_m_per_m2 * z^2 +
noise_floor_m (structured light and stereo both grow with z^2; in inverse depth that is nearly
constant). Windows across depth edges or on curved surfaces have large residuals and low kappa.

Conventions: camera frame OpenCV (x right, y down, z forward); normals are unit vectors in it,
oriented towards the camera (n . p < 0). Depth in metres, 0 or NaN where missing; intrinsics K in
pixels with fx, fy > 0. Datasets published with a negative fy (ICL-NUIM: fy = -480, a y-up camera
frame) must pass |fy| here and convert their ground truth with `flip_y_rotation` (see below).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ConfigError, InputError
from ..formats.datasets import (  # noqa: F401
    FLIP_Y,
    ICL_NUIM_K_OPENCV,
    ICL_NUIM_K_PUBLISHED,
    ICSL_CORRIDOR_K,
    flip_y_rotation,
)
from ..formats.depth_png import (  # noqa: F401
    ICL_NUIM_DEPTH_UNIT_M,
    MILLIMETRE_DEPTH_UNIT_M,
    read_depth_png,
)
from ..types import Frame, NormalMap

# The dataset constants and `read_depth_png` live in `uareme_fusion.formats`; they are re-exported here
# for scripts that import them from `uareme_fusion.normals.depth`.

@dataclass(frozen=True)
class DepthNormalsConfig:
    """Parameters of `DepthNormals` (units in the names)."""

    window_px: int = 9
    """Side of the square fitting window (odd)."""
    min_valid_fraction: float = 0.5
    """Windows with fewer valid depth pixels than this fraction of window_px^2 give kappa 0."""
    stride_px: int = 2
    """Fit every stride_px-th pixel in each direction and repeat the result (1 = every pixel). The
    default 2 keeps a 640x480 map within 10 ms on a 2-core CPU (stride 1 costs about twice that) and
    gave the same ICL-NUIM rotation accuracy (tools/bench_depth_normals.py)."""
    min_depth_m: float = 0.1
    max_depth_m: float = 20.0
    noise_quadratic_m_per_m2: float = 1.5e-3
    """Sensor model sigma_z = this * z^2 + noise_floor_m. 1.5e-3 suits structured light (Kinect v1,
    Asus Xtion); an OAK-D stereo pair (7.5 cm baseline, ~0.1 px disparity noise) is ~3e-3."""
    noise_floor_m: float = 1e-3
    """Depth-independent part of the sensor noise (quantisation, rendering noise)."""
    max_residual_ratio: float = 9.0
    """Windows whose residual variance exceeds the sensor model's by more than this factor are not
    planes (a depth edge fits as a steep, confidently wrong plane): kappa 0."""
    max_independent_regions: float = 60.0
    """Cap on the map's independent errors (`NormalMap.independent_regions`, otherwise one per window):
    a real sensor's errors are shared by whole planes (its calibration tilts them, non-Manhattan surfaces
    pull them), so they do not average away with the window count. Fitted on the TUM fr1 rpy train frames
    (Kinect, mocap truth): depth-normal NEES mean 200 with one region per window (3793), 3.4 with 60;
    on the evaluation frames 131 -> 2.2. Rendered depth has per-pixel noise only and would then be
    reported far wider than it is (ICL kt3 NEES 0.013): `RENDERED_DEPTH` lifts the cap for it."""
    errors_per_window_area: float = 1.0
    """Independent errors per fit-window area (`H W / window_px^2` windows, then the cap above): 1 for a
    real sensor, whose errors are shared by whole windows and planes. Per-pixel noise alone (rendered
    depth) averages better over a frame: the slope errors of overlapping windows telescope across a
    plane, so on a rendered plane with per-pixel noise the mean normal's variance is 7.6 (window 7) to
    20 (window 9, kappa at its cap) times smaller than one error per window says
    (tests/test_depth_normals.py); `RENDERED_DEPTH` takes 20, the figure at the default window."""
    kappa_max: float = 100.0
    """Cap on kappa (the paper caps at 100); flat noiseless planes would otherwise go to infinity."""

    @classmethod
    def for_stereo(cls, focal_px: float, baseline_m: float, disparity_noise_px: float = 0.1, **kwargs):
        """Sensor model of a stereo pair: z = f b / d, so sigma_z = sigma_d z^2 / (f b).

        OAK-D at 640x400: focal_px ~ 450, baseline_m = 0.075 (0.1 px gives ~3e-3 m/m^2)."""
        if not (focal_px > 0 and baseline_m > 0 and disparity_noise_px > 0):
            raise ConfigError(
                f"for_stereo needs focal_px, baseline_m and disparity_noise_px > 0, got "
                f"{focal_px}, {baseline_m}, {disparity_noise_px}"
            )
        return cls(noise_quadratic_m_per_m2=disparity_noise_px / (focal_px * baseline_m), **kwargs)

    def __post_init__(self):
        if self.window_px < 3 or self.window_px % 2 == 0:
            raise ConfigError(f"window_px must be an odd integer >= 3, got {self.window_px}")
        if not 0.0 < self.min_valid_fraction <= 1.0:
            raise ConfigError(f"min_valid_fraction must be in (0, 1], got {self.min_valid_fraction}")
        if self.stride_px < 1:
            raise ConfigError(f"stride_px must be >= 1, got {self.stride_px}")
        if not 0.0 <= self.min_depth_m < self.max_depth_m:
            raise ConfigError(
                f"need 0 <= min_depth_m < max_depth_m, got {self.min_depth_m} and {self.max_depth_m}"
            )
        if self.noise_quadratic_m_per_m2 < 0 or self.noise_floor_m < 0:
            raise ConfigError("noise_quadratic_m_per_m2 and noise_floor_m must be >= 0")
        if self.noise_quadratic_m_per_m2 == 0 and self.noise_floor_m == 0:
            raise ConfigError("the sensor noise model needs noise_quadratic_m_per_m2 or noise_floor_m > 0")
        if not self.max_residual_ratio >= 1:
            raise ConfigError(f"max_residual_ratio must be >= 1, got {self.max_residual_ratio}")
        if not self.errors_per_window_area >= 1:
            raise ConfigError(f"errors_per_window_area must be >= 1, got {self.errors_per_window_area}")
        if not self.kappa_max > 0:
            raise ConfigError(f"kappa_max must be > 0, got {self.kappa_max}")


def check_intrinsics(K, source: str = "depth map") -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) from a (3, 3) pinhole matrix; `InputError` naming `source` if unusable."""
    if K is None:
        raise InputError(f"{source}: depth normals need camera intrinsics K (fx, fy, cx, cy), got none")
    try:
        K = np.asarray(K, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{source}: expected intrinsics K as a finite (3, 3) matrix of numbers, got {K!r}") from None
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise InputError(f"{source}: expected intrinsics K as a finite (3, 3) matrix, got shape {K.shape}"
                         + ("" if K.shape != (3, 3) else " with NaN or infinite entries"))
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if fy < 0:
        raise InputError(
            f"{source}: K has fy = {fy:g} < 0 (a y-up camera convention, as ICL-NUIM publishes); "
            "normals here are in the OpenCV frame (y down): pass |fy| and convert the dataset's "
            "rotations with uareme_fusion.normals.depth.flip_y_rotation"
        )
    if not (fx > 0 and fy > 0):
        raise InputError(f"{source}: K needs fx > 0 and fy > 0, got fx = {fx:g}, fy = {fy:g}")
    return float(fx), float(fy), float(cx), float(cy)


def _offset_kernels(window_px: int) -> dict[int, np.ndarray]:
    o = np.arange(window_px, dtype=np.float32) - window_px // 2
    return {0: np.ones_like(o), 1: o, 2: o * o}


RENDERED_DEPTH = DepthNormalsConfig(max_independent_regions=float("inf"), errors_per_window_area=20.0)
"""Depth normals of rendered depth (ICL-NUIM, the simulator): per-pixel noise, 20 independent errors per
window area (`errors_per_window_area`). ICL kt3, depth normals + lines, single: ARE 0.137 -> 0.112 and
NEES 0.89 -> 1.47 against one error per window (normals alone: NEES 0.47 -> 1.04; the solver's error
floor bounds it); 0.013 under the real-sensor cap."""


def depth_normals_for(info) -> "DepthNormals":
    """The depth-normal estimator for a source (`drivers.base.SourceInfo`): `RENDERED_DEPTH` when its
    depth is rendered (`info.depth_rendered`), else the real-sensor defaults."""
    return DepthNormals(RENDERED_DEPTH if getattr(info, "depth_rendered", False) else None)


class DepthNormals:
    """Normal estimator for RGB-D frames: `estimate(depth_m, K) -> NormalMap` (OpenCV camera frame)."""

    def __init__(self, config: DepthNormalsConfig | None = None):
        self.config = config or DepthNormalsConfig()
        self._kernels = _offset_kernels(self.config.window_px)

    def estimate_frame(self, frame: Frame) -> NormalMap:
        """Normals of a `Frame`'s depth with its own K; `InputError` if either is missing."""
        source = f"frame {frame.index} (t = {frame.t_s:g} s)"
        if frame.depth is None:
            raise InputError(f"{source}: depth normals need a depth map, the frame has none")
        result = self.estimate(frame.depth, frame.K, source=source)
        return dataclasses.replace(result, t_s=frame.t_s)

    def estimate(self, depth_m, K, source: str = "depth map") -> NormalMap:
        """Unit normals (H, W, 3) float32 in the OpenCV camera frame, facing the camera, and kappa
        (H, W) float32 in [0, kappa_max]. kappa is 0 where the pixel's own depth is missing (its
        normal, fitted to the neighbours, is kept for display), and kappa is 0 with normal (0, 0, 0)
        where the window has too few valid points or is not a plane (residual gate).

        `depth_m` (H, W) float metres, 0 or NaN where missing; `K` (3, 3) with fx, fy > 0.
        """
        fx, fy, cx, cy = check_intrinsics(K, source)
        try:
            depth = np.asarray(depth_m)
        except ValueError as exc:  # a ragged nested list
            raise InputError(f"{source}: expected a depth map (H, W) of float metres ({exc})") from None
        if depth.ndim != 2 or min(depth.shape) < self.config.window_px:
            raise InputError(
                f"{source}: expected a depth map of shape (H, W) at least {self.config.window_px} px "
                f"each way, got {depth.shape}"
            )
        if not np.issubdtype(depth.dtype, np.floating):
            raise InputError(
                f"{source}: expected depth as float metres, got {depth.dtype}; read 16-bit PNGs with "
                "read_depth_png(path, unit_m)"
            )
        return self._fit(depth.astype(np.float32, copy=False), fx, fy, cx, cy)

    def _fit(self, depth: np.ndarray, fx: float, fy: float, cx: float, cy: float) -> NormalMap:
        cfg, ker = self.config, self._kernels
        H, W = depth.shape
        with np.errstate(invalid="ignore"):
            valid = (depth > cfg.min_depth_m) & (depth < cfg.max_depth_m)  # NaN compares False
        m = valid.astype(np.float32)
        inv = np.zeros_like(depth)
        np.divide(1.0, depth, out=inv, where=valid)

        def window_sums(image, order_u, order_v):
            # sum over offsets (du, dv) of image(v + dv, u + du) du^order_u dv^order_v; zero outside.
            out = cv2.sepFilter2D(image, cv2.CV_32F, ker[order_u], ker[order_v], borderType=cv2.BORDER_CONSTANT)
            return out if cfg.stride_px == 1 else np.ascontiguousarray(out[:: cfg.stride_px, :: cfg.stride_px])

        n_pts, s_w, s_ww = (window_sums(x, 0, 0) for x in (m, inv, inv * inv))
        s_u, s_wu = window_sums(m, 1, 0), window_sums(inv, 1, 0)
        s_v, s_wv = window_sums(m, 0, 1), window_sums(inv, 0, 1)
        s_uu, s_vv, s_uv = window_sums(m, 2, 0), window_sums(m, 0, 2), window_sums(m, 1, 1)

        # Normal equations M (c, a, b) = (s_w, s_wu, s_wv), M = [[N, Su, Sv], [Su, Suu, Suv], [Sv, Suv, Svv]],
        # solved with the adjugate A (symmetric) and determinant.
        a00 = s_uu * s_vv - s_uv * s_uv
        a01 = s_v * s_uv - s_u * s_vv
        a02 = s_u * s_uv - s_uu * s_v
        a11 = n_pts * s_vv - s_v * s_v
        a12 = s_u * s_v - n_pts * s_uv
        a22 = n_pts * s_uu - s_u * s_u
        det = n_pts * a00 + s_u * a01 + s_v * a02
        min_points = cfg.min_valid_fraction * cfg.window_px**2
        # det scales like N^3 r^4; a collinear or tiny set of points makes it vanish.
        ok = (n_pts >= min_points) & (det > 1e-3 * n_pts * a00.clip(min=0) + 1e-12)
        inv_det = np.divide(1.0, det, out=np.zeros_like(det), where=ok)
        c = (a00 * s_w + a01 * s_wu + a02 * s_wv) * inv_det
        a = (a01 * s_w + a11 * s_wu + a12 * s_wv) * inv_det
        b = (a02 * s_w + a12 * s_wu + a22 * s_wv) * inv_det

        # Unnormalised normal g = (a fx, b fy, c - a du0 - b dv0), du0 = u - cx, dv0 = v - cy.
        rows = np.arange(0, H, cfg.stride_px, dtype=np.float32)
        cols = np.arange(0, W, cfg.stride_px, dtype=np.float32)
        du0 = (cols - np.float32(cx))[None, :]
        dv0 = (rows - np.float32(cy))[:, None]
        gx = a * np.float32(fx)
        gy = b * np.float32(fy)
        gz = c - a * du0 - b * dv0
        g2 = gx * gx + gy * gy + gz * gz
        ok &= g2 > 0

        # Inverse-depth noise variance: the larger of the fit residual and the sensor model.
        rss = s_ww - c * s_w - a * s_wu - b * s_wv
        var_fit = np.maximum(rss, 0.0) / np.maximum(n_pts - 3.0, 1.0)
        w_centre = c  # fitted 1/z at the window centre
        sigma_model = np.float32(cfg.noise_quadratic_m_per_m2) + np.float32(cfg.noise_floor_m) * w_centre * w_centre
        var_model = sigma_model * sigma_model
        var_w = np.maximum(var_fit, var_model)
        ok &= var_fit <= np.float32(cfg.max_residual_ratio) * var_model

        # Covariance of g = J (c, a, b), J = [[0, fx, 0], [0, 0, fy], [1, -du0, -dv0]], is
        # var_w J A J^T / det; kappa = |g|^2 / (var_w trace(P J A J^T P) / det), P = I - n n^T.
        p0 = a01 - du0 * a11 - dv0 * a12  # (J A)[z, a]
        q0 = a02 - du0 * a12 - dv0 * a22  # (J A)[z, b]
        cxx = np.float32(fx * fx) * a11
        cyy = np.float32(fy * fy) * a22
        cxy = np.float32(fx * fy) * a12
        cxz = np.float32(fx) * p0
        cyz = np.float32(fy) * q0
        czz = a00 - du0 * a01 - dv0 * a02 - du0 * p0 - dv0 * q0
        # g^T C g = gx (gx cxx + 2 gy cxy + 2 gz cxz) + gy (gy cyy + 2 gz cyz) + gz^2 czz
        g_c_g = gx * (gx * cxx + 2 * (gy * cxy + gz * cxz)) + gy * (gy * cyy + 2 * gz * cyz) + gz * gz * czz
        inv_g2 = np.divide(1.0, g2, out=np.zeros_like(g2), where=ok)
        trace_tangent = (cxx + cyy + czz - g_c_g * inv_g2) * inv_det * var_w
        kappa = np.divide(g2, trace_tangent, out=np.zeros_like(g2), where=ok & (trace_tangent > 0))
        np.minimum(kappa, np.float32(cfg.kappa_max), out=kappa)

        scale = np.divide(-1.0, np.sqrt(g2), out=np.zeros_like(g2), where=ok)  # minus: face the camera
        for component in (gx, gy, gz):
            component *= scale
        normals = cv2.merge([gx, gy, gz])
        if cfg.stride_px > 1:
            normals = _repeat(normals, cfg.stride_px, H, W)
            kappa = _repeat(kappa, cfg.stride_px, H, W)
        kappa[~valid] = 0.0  # no confidence where the pixel itself has no depth
        # Windows overlap: about one independent plane fit per window area carries a real sensor's errors.
        regions = cfg.errors_per_window_area * H * W / cfg.window_px**2
        return NormalMap(normals=normals.astype(np.float32, copy=False), kappa=kappa.astype(np.float32, copy=False),
                         independent_regions=min(regions, cfg.max_independent_regions))


def _repeat(image: np.ndarray, stride: int, height: int, width: int) -> np.ndarray:
    """Nearest-neighbour upsampling of a strided grid back to (height, width)."""
    return np.repeat(np.repeat(image, stride, axis=0), stride, axis=1)[:height, :width]
