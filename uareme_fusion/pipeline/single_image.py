"""Images in: each one's Manhattan rotation, covariance, up vector, focal length and horizon, and an overlay.

Without gravity, "up" is the scene axis nearest image up (`solver.up_candidate`); the rotation is
`R_cm` (Manhattan to camera coordinates) with the covariance (rad^2) of its right perturbation.
Cues: learned normals and line segments (`cues`); without intrinsics the focal length comes from
the segments when they tell it (`solver/focal.py`), else from an assumed field of view. Up comes
from the segments' Atlanta-world horizon when they show one (`solver/atlanta.py`: the zenith and
horizontal vanishing points in any directions), else from the Manhattan axis nearest image up. In open
scenes a sky boundary (`solver/sky_horizon.py`, the third cue) sets up instead, unless man-made verticals
put the horizon elsewhere (`solver/horizon_estimate.sky_and_segments`). The horizon is `l ~ K^-T up_c` in
pixels, scaled so that [a, b] is unit (a x + b y + c = 0, positive on the sky side), with its std, and
`horizon_known` false when no cue fixes it; the reported `R_cm` is turned onto `up_c` (one answer).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..drivers.base import SourceInfo
from ..drivers.intrinsics import scaled_camera, undistorted_image
from ..errors import InputError
from ..formats.images import IMAGE_SUFFIXES, images_in_folder, read_rgb
from ..io.images import image_size, reduction_for
from ..solver.line_detection import LineSegments, SegmentDetector
from ..overlay import side_by_side
from ..overlay.camera import DEFAULT_FOV_DEG, check_K
from ..overlay.compose import draw_overlay
from ..overlay.horizon import horizon_line
from ..rotations import quat_xyzw
from ..solver.atlanta import AtlantaHorizon, estimate_horizon
from ..solver.evidence import no_evidence_reason, without_evidence
from ..solver.focal import (FocalConfig, FocalEstimate, assumed_focal, closed_form_focal, solve_given_K,
                            solve_with_focal, unknown_centre_floor)
from ..solver.horizon_estimate import (HorizonKnownConfig, HorizonUncertainty, SkyVetoConfig, aligned_rotation,
                                      horizon_known, horizon_uncertainty, sky_and_segments, sky_decides,
                                      sky_angle_deg, sky_orientation_doubt_deg, sky_start, up_covariance)
from ..solver.joint import JointSolver
from ..solver.sky_horizon import SkyDetector, SkyHorizon
from ..solver.manhattan import up_candidate
from ..solver.self_calibration import FrameEvidence, SelfCalibrationConfig, pool_intrinsics, solve_with_pooled_K
from ..types import Frame, NormalMap, VisualRotation
from ..solver.cues import DEFAULT_CUES, VALID_CUES, parse_cues
from .stages import CappedNormals, make_normal_estimator
from .turned_photo import TurnConfig, sky_quarters, turned_back, turned_photo

IMAGE_DETECT_WIDTH_PX = 640
"""Single images are not time-critical: LSD at 640 px wide scores ECD AUC 63.4% against 60.5% at
the stream's 320 px (lines only), for 4x the detection time (12 vs 3.3 ms at 640x480). At ECD's full
1152 px (every cue): AUC 88.5 % against 90.2 % at 640 (the end point noise and VP floors were chosen at
640)."""


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
    sky: SkyHorizon | None = None
    """The sky boundary that took part as the third cue (None: no sky found, or not looked for)."""
    uncertainty: HorizonUncertainty | None = None
    """The horizon's standard deviations (`solver/horizon_estimate.py`)."""
    known: bool = True
    """Whether the scene fixes the horizon (`horizon_known`); False: no horizon is given."""
    orientation_doubt_deg: float = 0.0
    """How far (deg) a sky boundary too rough to be the horizon puts the sky from the Atlanta horizon's up
    when it contradicts it (`horizon_estimate.sky_orientation_doubt_deg`: a photo turned 90 deg); the
    horizon's angle std is then at least that (and the horizon not known). 0: no contradiction."""
    R_cm_reported: np.ndarray | None = None
    """`visual.R_cm` turned onto `up_c` (`aligned_rotation`): the rotation of the JSON and the overlay, one
    answer with the horizon. `visual` keeps the solve's own rotation (what a stream's backend gets); the
    two differ when the Atlanta horizon sets up (ICSL, K pooled, vs depth: 1.65 deg mean for the solve's,
    1.93 for the turned one; on ECD the Atlanta horizon is the better one)."""

    turned_deg: float = 0.0
    """How far (deg, clockwise) the photo was turned to be answered upright (`pipeline/turned_photo.py`: its
    sky boundary put the sky off to the side or below); 0: answered as it is."""

    @property
    def R_cm(self) -> np.ndarray:
        """The reported rotation (Manhattan to camera): `R_cm_reported`, else the solve's."""
        return self.visual.R_cm if self.R_cm_reported is None else self.R_cm_reported

    @property
    def horizon(self) -> np.ndarray:
        """[a, b, c] with a x + b y + c = 0 in pixels, [a, b] unit, positive on the sky side."""
        return horizon_line(self.up_c, self.focal.K)

    def as_dict(self) -> dict:
        v = self.visual
        cues = {name: v.cues.get(name, {"present": False}) for name in VALID_CUES}
        if not v.cues:  # the normals-only solver
            cues["normals"] = {"share": 1.0, "cost": v.cost, "valid_pixels": v.n_valid}
        for entry in cues.values():
            entry.setdefault("present", True)
        return {"image": str(self.path), "R_cm": self.R_cm.tolist(), "q_cm_xyzw": quat_xyzw(self.R_cm).tolist(),
                "cov_rad2": v.cov.tolist(), "std_deg": np.degrees(np.sqrt(np.diag(v.cov))).tolist(),
                "up_c": self.up_c.tolist(), "analysed_size_px": [self.rgb.shape[1], self.rgb.shape[0]],
                "quality": v.quality, "cost": v.cost, "valid_pixels": v.n_valid, "reason": v.reason,
                **self.focal.as_dict(), "horizon_known": self.known,
                "horizon": self.horizon.tolist() if self.known else None, **self._horizon_source(), "cues": cues,
                "timing_ms": self.timing_ms,
                "conventions": "camera OpenCV (x right, y down, z forward); R_cm maps Manhattan to camera "
                               "coordinates; cov of the right perturbation; up_c = up from the "
                               "segments' horizon (horizon_source atlanta; horizon_std_px its std along its normal) or "
                               "the Manhattan axis nearest image up (manhattan); "
                               "horizon [a, b, c]: a x + b y + c = 0 in pixels, [a, b] unit, "
                               "positive on the sky side"}

    def _horizon_source(self) -> dict:
        u = self.uncertainty
        source = "atlanta" if self.atlanta is not None else "sky" if self.sky is not None else "manhattan"
        std = self.atlanta.t_std_px if self.atlanta is not None else u.offset_std_px if u is not None else None
        return {"horizon_source": source, "horizon_std_px": _finite_or_none(std),
                "horizon_angle_std_deg": _finite_or_none(u.angle_std_deg) if u is not None else None,
                "horizon_in_image": u.in_image if u is not None else None,
                "horizon_centre_offset_px": _finite_or_none(u.centre_offset_px) if u is not None else None,
                "horizon_orientation_doubt_deg": self.orientation_doubt_deg, "turned_deg": self.turned_deg,
                "sky": self.sky.as_dict() if self.sky is not None else None}


ANALYSIS_MAX_PIXELS = 4_000_000
"""Larger images are decoded at 1/2, 1/4 or 1/8 size for `analyse_image` (normals are estimated at
far lower resolution; a 48-megapixel photo at full size needs 4 GB through the pipeline)."""


def _finite_or_none(x) -> float | None:
    return float(x) if x is not None and np.isfinite(x) else None


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
        self.sky = SkyDetector() if "sky" in self.cues else None
        self.sky_veto = SkyVetoConfig()
        self.camera = camera
        self.focal_config = FocalConfig(assumed_fov_deg=assumed_fov_deg)
        self.solver = JointSolver()
        self.calibration_config = SelfCalibrationConfig()
        self.turn = TurnConfig()

    def analyse(self, path: str | Path, rgb: np.ndarray | None = None, turn: bool = True) -> ImageAnalysis:
        """The image's answer; with `turn`, a photo whose sky boundary contradicts its horizon is analysed
        again turned upright by that boundary (`pipeline/turned_photo.py`)."""
        seen = self._observe(Path(path), rgb)
        t0 = time.perf_counter()
        visual, focal = self._solve_alone(seen)
        analysis = self._analysis(seen, visual, focal, t0)
        if turn and analysis.orientation_doubt_deg > 0 and self.camera is None:
            return self._turned(seen, analysis)
        return analysis

    def _turned(self, seen: "_Seen", analysis: ImageAnalysis) -> ImageAnalysis:
        """`analysis` of a photo whose sky boundary contradicts its horizon: the answer of the photo turned so
        that the boundary's sky is on top, carried back, when it is known and agrees with the boundary
        (`TurnConfig`); else `analysis` (declined)."""
        quarters = sky_quarters(seen.sky_boundary.line)
        if quarters == 0 or seen.sky_boundary.separation < self.turn.min_separation:
            return analysis
        upright = self.analyse(seen.path, turned_photo(seen.rgb, quarters), turn=False)
        if not upright.known:
            return analysis
        back = turned_back(upright, seen.rgb, seen.normal_map, seen.segments, quarters)
        if sky_angle_deg(seen.sky_boundary.line, back.horizon) > self.turn.max_sky_angle_deg:
            return analysis
        return back

    def analyse_same_camera(self, paths: list[str | Path],
                            warn: Callable[[str], None] | None = None) -> Iterator[ImageAnalysis]:
        """`analyse` of images from ONE camera with one K: without given intrinsics, in two passes: each
        image solved alone, then the focal length and principal point pooled over all of them
        (`solver/self_calibration.py`) and each image solved again with that K (its `focal` says so).
        Between the passes only each image's segments and answer are kept, so that memory does not grow
        by a normal map per image (0.3 MB at the shipped network's 160x120, 5 MB a 640x480 map): the
        second pass reads the image and estimates its normals again (the same map).
        When the images cannot tell a shared K (too few with segments), each keeps its own answer, and
        `warn` (when given) gets one line saying why; so it does without the line cue or with one image.
        All images must have the same size (an InputError names the first that does not)."""
        paths = [Path(p) for p in paths]
        why = (None if self.camera is not None else "no line cue (--cues)" if self.detector is None
               else "one image" if len(paths) < 2 else None)
        if self.camera is not None or why is not None:
            if why is not None and warn is not None:
                warn(f"{why}, each image keeps its own K")
            yield from (self.analyse(p) for p in paths)
            return
        alone, evidence, size = [], [], None
        for path in paths:
            seen = self._observe(path, None)
            size = size or seen.rgb.shape[:2]
            if seen.rgb.shape[:2] != size:
                raise InputError(f"{path}: {seen.rgb.shape[1]}x{seen.rgb.shape[0]} px, but {paths[0]} is "
                                 f"{size[1]}x{size[0]}: one camera's images have one size")
            visual, focal = self._solve_alone(seen)
            alone.append((_Seen(seen.path, None, None, seen.segments, None, seen.timing_ms, seen.sky,
                                seen.sky_boundary), visual, focal))
            evidence.append(FrameEvidence(seen.segments, visual.R_cm))
        estimated = [focal.f_px for _, _, focal in alone if focal.source == "estimated"]
        f_init = float(np.median(estimated)) if estimated else alone[0][2].f_px
        pooled = pool_intrinsics(evidence, f_init, self.calibration_config)
        if pooled is None and warn is not None:
            cfg = self.calibration_config
            lined = sum(seen.segments is not None and len(seen.segments) >= cfg.min_segments for seen, _, _ in alone)
            warn(f"the {len(paths)} images ({lined} with {cfg.min_segments}+ line segments) could "
                 f"not tell one K (fewer than {cfg.min_frames} with segments, or f undetermined or outside "
                 f"{cfg.hfov_range_deg[0]:g}-{cfg.hfov_range_deg[1]:g} deg HFOV), each image keeps its own K")
        for seen, visual, focal in alone:
            rgb = self._read(seen.path)[0]
            seen = dataclasses.replace(seen, rgb=rgb, normal_map=self._normals(rgb))
            t0 = time.perf_counter()
            if pooled is not None:  # the frames' floor stays: systematic errors escape the pooled K's std
                focal = pooled.focal_estimate()
                visual = unknown_centre_floor(solve_with_pooled_K(self.solver, seen.normal_map, seen.segments, pooled),
                                              focal, self.focal_config, self.solver)
                visual = self._with_sky(seen, visual, focal)
            yield self._analysis(seen, visual, focal, t0)

    def _read(self, path: Path) -> tuple[np.ndarray, float]:
        """The image as analysed (decoded smaller when huge) and that scale."""
        return read_rgb(path, ANALYSIS_MAX_PIXELS), 1.0 / reduction_for(image_size(path), ANALYSIS_MAX_PIXELS)[0]

    def _observe(self, path: Path, rgb: np.ndarray | None) -> "_Seen":
        """The image (undistorted with given intrinsics), its normal map and its segments."""
        given_K, scale = None, 1.0
        if rgb is None:
            rgb, scale = self._read(path)
        if self.camera is not None:  # K is in the file's pixels; the analysed image may be decoded smaller
            camera = scaled_camera(self.camera, scale)
            rgb = undistorted_image(camera, rgb)
            given_K = check_K(camera.K)
        t0 = time.perf_counter()
        try:
            normal_map = self._normals(rgb)
        except InputError as exc:  # the estimator names a frame ("frame 0 (t = 0 s): ..."); here it is a file
            raise InputError(f"{path}: {str(exc).split(': ', 1)[-1]}") from None
        t1 = time.perf_counter()
        segments = self.detector.detect(rgb) if self.detector else None
        t2 = time.perf_counter()
        boundary = self.sky.boundary(rgb) if self.sky else None
        sky = self.sky.trusted(boundary) if self.sky else None
        t3 = time.perf_counter()
        return _Seen(path, rgb, normal_map, segments, given_K, {"normals": 1e3 * (t1 - t0), "lines": 1e3 * (t2 - t1),
                                                                "sky": 1e3 * (t3 - t2)}, sky, boundary)

    def _normals(self, rgb: np.ndarray) -> NormalMap | None:
        """The image's normal map (None without the normal cue)."""
        return self.estimator.estimate_frame(Frame(0.0, rgb=rgb, index=0)) if self.estimator else None

    def _solve_alone(self, seen: "_Seen") -> tuple[VisualRotation, FocalEstimate]:
        """The rotation and K of one image by itself (K given, estimated from its segments, or assumed)."""
        h, w = seen.rgb.shape[:2]
        normal_map, segments, given_K = seen.normal_map, seen.segments, seen.given_K
        sky_first = self._sky_first(seen) if seen.sky is not None else None
        if sky_first is not None:
            return sky_first
        try:
            if given_K is not None or segments is None or not len(segments):
                focal = self._fixed_focal(given_K, h, w)
                visual = solve_given_K(self.solver, normal_map, segments, focal.K)
                if given_K is None:
                    visual = unknown_centre_floor(visual, focal, self.focal_config, self.solver)
            else:
                visual, focal = solve_with_focal(self.solver, normal_map, segments, config=self.focal_config)
        except InputError:
            if seen.sky is None:
                raise InputError(f"{seen.path}: no confident normals and no line segments in this image "
                                 "(blank or dark?)") from None
            focal = self._fixed_focal(given_K, h, w)
            visual = None
        return self._with_sky(seen, visual, focal), focal

    def _fixed_focal(self, given_K: np.ndarray | None, h: int, w: int) -> FocalEstimate:
        """The given intrinsics (in the analysed image's pixels), else the assumed field of view's K."""
        if given_K is not None:
            return FocalEstimate(given_K, "given", width=w, origin=self.camera.origin)
        return assumed_focal(h, w, self.focal_config)

    def _sky_first(self, seen: "_Seen") -> tuple[VisualRotation, FocalEstimate] | None:
        """When the sky boundary sets up alone (the segments show no man-made verticals that could veto
        or join it: `sky_decides`), one solve of the normals and the sky under the given or assumed K,
        without the focal-length search: the segments it would read are those judged unable to tell up
        (a runway's, a field's edges), and a sky horizon l ~ K^-T up_c is the boundary whatever K.
        None otherwise (the structure is solved first, `_with_sky`)."""
        focal = self._fixed_focal(seen.given_K, *seen.rgb.shape[:2])
        sky_up = seen.sky.observation(focal.K).up_c
        if not sky_decides(seen.segments, focal.K, sky_up, self.sky_veto):
            return None
        visual = solve_given_K(self.solver, seen.normal_map, None, focal.K, sky_start(seen.normal_map, sky_up),
                               sky=seen.sky)
        return (visual if focal.source == "given" else unknown_centre_floor(visual, focal, self.focal_config,
                                                                            self.solver)), focal

    def _with_sky(self, seen: "_Seen", visual: VisualRotation | None, focal: FocalEstimate) -> VisualRotation:
        """The structure's solve `visual` (None: no normals or segments) solved again with the sky boundary as
        the third cue, from the structure's rotation turned onto the sky's up, under the same K, with the
        segments only when they show man-made verticals (`sky_and_segments`); unchanged without a sky, or
        when those verticals put the horizon elsewhere (`sky_vetoed`)."""
        if seen.sky is None:
            return visual
        sky_up = seen.sky.observation(focal.K).up_c
        guess = up_candidate(visual.R_cm)[1] if visual is not None else sky_up
        sky, segments = sky_and_segments(seen.sky, seen.segments, focal.K, guess, self.sky_veto,
                                         visual.R_cm if visual is not None else None)
        if sky is None:
            return visual
        R0 = aligned_rotation(visual.R_cm, sky_up) if visual is not None else None
        with_sky = solve_given_K(self.solver, seen.normal_map, segments, focal.K, R0, sky=sky)
        return with_sky if focal.source == "given" else unknown_centre_floor(with_sky, focal, self.focal_config,
                                                                             self.solver)

    def _analysis(self, seen: "_Seen", visual: VisualRotation, focal: FocalEstimate, t0: float) -> ImageAnalysis:
        """Up and the horizon of a solved image, one answer (`solver/horizon_estimate.py`): with a sky
        boundary among the cues, the solve's axis nearest the sky's up; else the segments' Atlanta horizon
        when they show one, else the Manhattan axis nearest image up; `R_cm` turned onto that up. `t0`:
        when its solve began."""
        # the network's normals on a black, blank or blurred image are a guess (`solver/evidence.py`); a sky
        # boundary that took part is evidence of its own (it is found at 96 px: blur does not hide it)
        reason = no_evidence_reason(seen.rgb) if self.estimator is not None and "sky" not in visual.cues else ""
        if reason:
            visual = without_evidence(visual, reason, self.solver.config.max_variance_rad2)
        segments = seen.segments
        sky = seen.sky if "sky" in visual.cues else None
        if sky is not None:
            up_c = up_candidate(visual.R_cm, sky.observation(focal.K).up_c)[1]
            atlanta = None
        else:
            _, up_c = up_candidate(visual.R_cm)
            atlanta = estimate_horizon(segments, focal.K, up_c) if segments is not None else None
            if atlanta is not None and seen.given_K is None and not focal.origin:  # the image's own f
                visual, focal = closed_form_focal(self.solver, seen.normal_map, segments, visual, focal, atlanta,
                                                  self.focal_config)
            if atlanta is not None:
                up_c = atlanta.up_c(focal.K)
        R_cm = aligned_rotation(visual.R_cm, up_c)
        h, w = seen.rgb.shape[:2]
        uncertainty = horizon_uncertainty(up_c, up_covariance(R_cm, visual.cov, up_c), focal.K, h, w)
        doubt = 0.0
        if atlanta is not None:
            uncertainty = dataclasses.replace(uncertainty, offset_std_px=atlanta.t_std_px)
            doubt = sky_orientation_doubt_deg(seen.sky_boundary, atlanta.line_px, self.sky.config) if self.sky else 0.0
            if doubt > 0:  # a sky off to the side: the photo may be turned, the segments cannot tell
                uncertainty = dataclasses.replace(uncertainty, angle_std_deg=max(uncertainty.angle_std_deg, doubt))
        lines = visual.cues.get("lines", {})
        supported = (sky is not None or atlanta is not None
                     or lines.get("effective_segments", 0.0) >= HorizonKnownConfig.min_effective_segments)
        known = horizon_known(uncertainty, supported, h)
        timing = {**seen.timing_ms, "solver": 1e3 * (time.perf_counter() - t0)}
        return ImageAnalysis(seen.path, seen.rgb, seen.normal_map, segments, visual, up_c, focal, timing, atlanta,
                             sky, uncertainty, known, doubt, R_cm)


@dataclass(frozen=True)
class _Seen:
    """An image as read, undistorted (`given_K`: the given intrinsics in its pixels) and measured."""

    path: Path
    rgb: np.ndarray | None
    normal_map: NormalMap | None
    segments: LineSegments | None
    given_K: np.ndarray | None
    timing_ms: dict
    sky: SkyHorizon | None = None
    sky_boundary: SkyHorizon | None = None
    """The sky boundary before the checks (`SkyDetector.boundary`), which `sky` passed."""


def analyse_image(path: str | Path, normals: str = "learned", kappa_cap: float = 75.0,
                  cues: str = DEFAULT_CUES, camera=None) -> ImageAnalysis:
    """One image through a fresh `ImageAnalyser` (load it once yourself for many images)."""
    return ImageAnalyser(normals, cues, kappa_cap, camera).analyse(path)


def image_overlay(analysis: ImageAnalysis, panes: bool = True) -> np.ndarray:
    """The horizon (a +-1 std band) and axes drawn with the image's own focal length (estimated, given or
    assumed); neither when the horizon is not known, but a note."""
    assumed = analysis.focal.source == "assumed"  # drawn with the "assumed FOV" note
    std = analysis.as_dict()["horizon_std_px"]
    axes = analysis.R_cm if analysis.known else None  # no up glyph for an unknown horizon
    image = draw_overlay(analysis.rgb, analysis.up_c, axes, None if assumed else analysis.focal.K,
                         analysis.focal.hfov_deg, std_px=std, known=analysis.known)
    if panes and analysis.normal_map is not None:
        return side_by_side(image, analysis.normal_map)
    return image
