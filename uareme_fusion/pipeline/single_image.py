"""One image in: its Manhattan rotation, covariance and best guess of up, and an overlay.

Without gravity, "up" is the scene axis nearest image up (`solver.up_candidate`); the rotation is
`R_cm` (Manhattan to camera coordinates) with the covariance (rad^2) of its right perturbation.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError
from ..io.images import image_size, read_image, reduction_for
from ..overlay import side_by_side
from ..overlay.compose import draw_overlay
from ..rotations import quat_xyzw
from ..solver import solve_manhattan
from ..solver.manhattan import up_candidate
from ..types import Frame, NormalMap, VisualRotation
from .stages import CappedNormals, make_normal_estimator
from ..drivers.base import SourceInfo
from ..drivers.video import to_rgb8


@dataclass(frozen=True)
class ImageAnalysis:
    path: Path
    rgb: np.ndarray
    normal_map: NormalMap
    visual: VisualRotation
    up_c: np.ndarray
    timing_ms: dict
    K: np.ndarray | None = None
    """Intrinsics of `rgb` (undistorted) when given, for drawing the horizon."""

    def as_dict(self) -> dict:
        v = self.visual
        return {"image": str(self.path), "R_cm": v.R_cm.tolist(), "q_cm_xyzw": quat_xyzw(v.R_cm).tolist(),
                "cov_rad2": v.cov.tolist(), "std_deg": np.degrees(np.sqrt(np.diag(v.cov))).tolist(),
                "up_c": self.up_c.tolist(), "analysed_size_px": [self.rgb.shape[1], self.rgb.shape[0]],
                "quality": v.quality, "cost": v.cost, "valid_pixels": v.n_valid,
                "timing_ms": self.timing_ms,
                "conventions": "camera OpenCV (x right, y down, z forward); R_cm maps Manhattan to camera "
                               "coordinates; cov of the right perturbation; up_c = the Manhattan axis nearest "
                               "image up"}


ANALYSIS_MAX_PIXELS = 4_000_000
"""Larger images are decoded at 1/2, 1/4 or 1/8 size for `analyse_image` (normals are estimated at
far lower resolution; a 48-megapixel photo at full size needs 4 GB through the pipeline)."""


def read_rgb(path: str | Path, max_pixels: int | None = None) -> np.ndarray:
    """An image file as RGB uint8 (grayscale, RGBA and 16-bit converted as the image sources do);
    decoded at reduced size when larger than `max_pixels` (`io.images.read_image`)."""
    try:
        return to_rgb8(read_image(path, cv2.IMREAD_UNCHANGED, max_pixels=max_pixels))
    except InputError as exc:
        if str(path) in str(exc):
            raise
        raise InputError(f"{path}: {exc}") from None


def analyse_image(path: str | Path, normals: str = "learned", kappa_cap: float = 75.0,
                  camera=None) -> ImageAnalysis:
    """One image's rotation and up; `camera` (`drivers.intrinsics.CameraModel`) undistorts it first."""
    from ..drivers.intrinsics import scaled_camera, undistorted_image

    path = Path(path)
    rgb = read_rgb(path, ANALYSIS_MAX_PIXELS)
    if camera is not None:  # K is in the file's pixels; the analysed image may be decoded smaller
        camera = scaled_camera(camera, 1.0 / reduction_for(image_size(path), ANALYSIS_MAX_PIXELS)[0])
        rgb = undistorted_image(camera, rgb)
    estimator = CappedNormals(make_normal_estimator(normals, SourceInfo(name=str(path))), kappa_cap)
    t0 = time.perf_counter()
    normal_map = estimator.estimate_frame(Frame(0.0, rgb=rgb, index=0))
    t1 = time.perf_counter()
    try:
        visual = solve_manhattan(normal_map)
    except InputError:
        raise InputError(f"{path}: no confident normals in this image (blank or dark?)") from None
    t2 = time.perf_counter()
    _, up_c = up_candidate(visual.R_cm)
    return ImageAnalysis(path, rgb, normal_map, visual, up_c,
                         {"normals": 1e3 * (t1 - t0), "solver": 1e3 * (t2 - t1)},
                         None if camera is None else camera.K)


def image_overlay(analysis: ImageAnalysis, K: np.ndarray | None = None, fov_deg: float = 60.0,
                  panes: bool = True) -> np.ndarray:
    K = analysis.K if K is None else K
    image = draw_overlay(analysis.rgb, analysis.up_c, analysis.visual.R_cm, K, fov_deg)
    return side_by_side(image, analysis.normal_map) if panes else image
