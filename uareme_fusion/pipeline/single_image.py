"""Images in: each one's Manhattan rotation, covariance, up vector, focal length and horizon, and an overlay.

Without gravity, "up" is the scene axis nearest image up (`solver.up_candidate`); the rotation is
`R_cm` (Manhattan to camera coordinates) with the covariance (rad^2) of its right perturbation.
Cues: learned normals and line segments (`cues`); without intrinsics the focal length comes from
the segments when they tell it (`solver/focal.py`), else from an assumed field of view. Up comes
from the segments' Atlanta-world horizon when they show one (`solver/atlanta.py`: the zenith and
horizontal vanishing points in any directions), else from the Manhattan axis nearest image up. The horizon
is `l ~ K^-T up_c` in pixels, scaled so that [a, b] is unit (a x + b y + c = 0, positive on the sky side).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..drivers.base import SourceInfo
from ..drivers.intrinsics import scaled_camera, undistorted_image
from ..errors import InputError
from ..formats.images import IMAGE_SUFFIXES, images_in_folder, read_rgb
from ..io.images import image_size, reduction_for
from ..lines.detect import LineSegments, SegmentDetector
from ..overlay import side_by_side
from ..overlay.camera import DEFAULT_FOV_DEG, assumed_K, check_K
from ..overlay.compose import draw_overlay
from ..overlay.horizon import horizon_line
from ..rotations import quat_xyzw
from ..solver.atlanta import AtlantaHorizon, estimate_horizon
from ..solver.focal import FocalConfig, FocalEstimate, solve_given_K, solve_with_focal, unknown_centre_floor
from ..solver.joint import JointSolver
from ..solver.manhattan import up_candidate
from ..types import Frame, NormalMap, VisualRotation
from .cues import DEFAULT_CUES, parse_cues
from .stages import CappedNormals, make_normal_estimator

IMAGE_DETECT_WIDTH_PX = 640
"""Single images are not time-critical: LSD at 640 px wide scores ECD AUC 63.4% against 60.5% at
the stream's 320 px (lines only), for 4x the detection time (12 vs 3.3 ms at 640x480)."""


@dataclass(frozen=True)
class ImageAnalysis:
    path: Path
    rgb: np.ndarray
    normal_map: NormalMap | None
    segments: LineSegments | None
    visual: VisualRotation
    up_c: np.ndarray
    focal: FocalEstimate
    timing_ms: dict
    atlanta: AtlantaHorizon | None = None
    """The segments' Atlanta-world horizon when they showed one (`up_c` then comes from it)."""

    @property
    def horizon(self) -> np.ndarray:
        """[a, b, c] with a x + b y + c = 0 in pixels, [a, b] unit, positive on the sky side."""
        return horizon_line(self.up_c, self.focal.K)

    def as_dict(self) -> dict:
        v = self.visual
        cues = {name: v.cues.get(name, {"present": False}) for name in ("normals", "lines")}
        if not v.cues:  # the normals-only solver
            cues["normals"] = {"share": 1.0, "cost": v.cost, "valid_pixels": v.n_valid}
        for entry in cues.values():
            entry.setdefault("present", True)
        return {"image": str(self.path), "R_cm": v.R_cm.tolist(), "q_cm_xyzw": quat_xyzw(v.R_cm).tolist(),
                "cov_rad2": v.cov.tolist(), "std_deg": np.degrees(np.sqrt(np.diag(v.cov))).tolist(),
                "up_c": self.up_c.tolist(), "analysed_size_px": [self.rgb.shape[1], self.rgb.shape[0]],
                "quality": v.quality, "cost": v.cost, "valid_pixels": v.n_valid,
                **self.focal.as_dict(), "horizon": self.horizon.tolist(), **self._horizon_source(), "cues": cues,
                "timing_ms": self.timing_ms,
                "conventions": "camera OpenCV (x right, y down, z forward); R_cm maps Manhattan to camera "
                               "coordinates; cov of the right perturbation; up_c = up from the "
                               "segments' horizon (horizon_source atlanta; horizon_std_px its std along its normal) or "
                               "the Manhattan axis nearest image up (manhattan); horizon [a, b, c]: a x + b y + c = 0 in pixels, [a, b] unit, "
                               "positive on the sky side"}

    def _horizon_source(self) -> dict:
        if self.atlanta is None:
            return {"horizon_source": "manhattan", "horizon_std_px": None}
        return {"horizon_source": "atlanta", "horizon_std_px": self.atlanta.t_std_px}


ANALYSIS_MAX_PIXELS = 4_000_000
"""Larger images are decoded at 1/2, 1/4 or 1/8 size for `analyse_image` (normals are estimated at
far lower resolution; a 48-megapixel photo at full size needs 4 GB through the pipeline)."""


def image_paths(inputs: list[str | Path]) -> list[Path]:
    """Image files named directly or found (sorted) in the folders given; an InputError when none."""
    paths: list[Path] = []
    for item in map(Path, inputs):
        if item.is_dir():
            found = images_in_folder(item)
            if not found:
                raise InputError(f"{item}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
            paths.extend(found)
        else:
            paths.append(item)
    return paths


class ImageAnalyser:
    """Loads the normal network and the segment detector once; `analyse(path)` per image."""

    def __init__(self, normals: str = "learned", cues: str = DEFAULT_CUES, kappa_cap: float = 75.0,
                 camera=None, assumed_fov_deg: float = DEFAULT_FOV_DEG,
                 detector: SegmentDetector | None = None):
        """`camera`: given intrinsics (`drivers.intrinsics.CameraModel`, in the file's pixels; images are
        undistorted with it); None: the focal length is estimated from the lines, or assumed."""
        self.cues = parse_cues(cues)
        self.estimator = (CappedNormals(make_normal_estimator(normals, SourceInfo(name="image")), kappa_cap)
                          if "normals" in self.cues else None)
        self.detector = (detector or SegmentDetector(IMAGE_DETECT_WIDTH_PX)) if "lines" in self.cues else None
        self.camera = camera
        self.focal_config = FocalConfig(assumed_fov_deg=assumed_fov_deg)
        self.solver = JointSolver()

    def analyse(self, path: str | Path, rgb: np.ndarray | None = None) -> ImageAnalysis:
        path = Path(path)
        given_K, scale = None, 1.0
        if rgb is None:
            rgb = read_rgb(path, ANALYSIS_MAX_PIXELS)
            scale = 1.0 / reduction_for(image_size(path), ANALYSIS_MAX_PIXELS)[0]
        if self.camera is not None:  # K is in the file's pixels; the analysed image may be decoded smaller
            camera = scaled_camera(self.camera, scale)
            rgb = undistorted_image(camera, rgb)
            given_K = check_K(camera.K)
        h, w = rgb.shape[:2]
        t0 = time.perf_counter()
        normal_map = self.estimator.estimate_frame(Frame(0.0, rgb=rgb, index=0)) if self.estimator else None
        t1 = time.perf_counter()
        segments = self.detector.detect(rgb) if self.detector else None
        t2 = time.perf_counter()
        try:
            if given_K is not None or segments is None or not len(segments):
                K = given_K if given_K is not None else assumed_K(h, w, self.focal_config.assumed_fov_deg)
                visual = solve_given_K(self.solver, normal_map, segments, K)
                focal = FocalEstimate(K, "given" if given_K is not None else "assumed", width=w)
                if given_K is None:
                    visual = unknown_centre_floor(visual, focal, self.focal_config, self.solver)
            else:
                visual, focal = solve_with_focal(self.solver, normal_map, segments, config=self.focal_config)
        except InputError:
            raise InputError(f"{path}: no confident normals and no line segments in this image "
                             "(blank or dark?)") from None
        _, up_c = up_candidate(visual.R_cm)
        atlanta = estimate_horizon(segments, focal.K, up_c) if segments is not None else None
        if atlanta is not None:
            up_c = atlanta.up_c(focal.K)
        t3 = time.perf_counter()
        return ImageAnalysis(path, rgb, normal_map, segments, visual, up_c, focal,
                             {"normals": 1e3 * (t1 - t0), "lines": 1e3 * (t2 - t1), "solver": 1e3 * (t3 - t2)},
                             atlanta)


def analyse_image(path: str | Path, normals: str = "learned", kappa_cap: float = 75.0,
                  cues: str = DEFAULT_CUES, camera=None) -> ImageAnalysis:
    """One image through a fresh `ImageAnalyser` (load it once yourself for many images)."""
    return ImageAnalyser(normals, cues, kappa_cap, camera).analyse(path)


def image_overlay(analysis: ImageAnalysis, panes: bool = True) -> np.ndarray:
    """The horizon and axes drawn with the image's own focal length (estimated, given or assumed)."""
    assumed = analysis.focal.source == "assumed"  # drawn with the "assumed FOV" note
    image = draw_overlay(analysis.rgb, analysis.up_c, analysis.visual.R_cm, None if assumed else analysis.focal.K,
                         analysis.focal.hfov_deg)
    if panes and analysis.normal_map is not None:
        return side_by_side(image, analysis.normal_map)
    return image
