"""Which visual cues a run uses (`--cues normals,lines`), and the per-frame line cue stage.

The line cue detects segments in each frame and hands them, with the frame's intrinsics, to the
joint solver (`solver/joint.py`). Without intrinsics, the focal length is estimated from the scene
(`solver/focal.py`) on the first `FOCAL_ATTEMPTS` frames; the stream uses the median of the
confident per-frame estimates (one camera per stream) meanwhile, then the K pooled over those frames
(`solver/self_calibration.py`: f, and the principal point when they determine it), and keeps it
(summary.json's `intrinsics.pooled_from` says from which frame, and what it replaced).
A recording (a video file, an image folder: `Source.sample_frames`) has its K pooled before the run
instead, over `FOCAL_ATTEMPTS` frames spread over it (`pool_before_run`), and every frame is solved
with it: the first frames do not wait for a K, and it does not change mid-stream.
"""

from __future__ import annotations

import dataclasses
import logging

import numpy as np

from ..errors import ConfigError, InputError
from .line_detection import LineSegments, SegmentDetector
from ..overlay.camera import DEFAULT_FOV_DEG, assumed_K
from ..solver.focal import (FocalConfig, FocalEstimate, centred_K, solve_given_K, solve_with_focal,
                            unknown_centre_floor)
from ..solver.horizon_estimate import sky_and_segments
from ..solver.cue_offset import CueOffset
from ..solver.evidence import no_evidence_reason, without_evidence
from ..solver.frame_motion import FrameMotion
from ..solver.joint import JointSolver
from ..solver.manhattan import up_candidate
from ..solver.sky_horizon import SkyDetector
from ..solver.self_calibration import FrameEvidence, SelfCalibrationConfig, pool_intrinsics
from ..solver import solve_manhattan
from ..types import Frame, NormalMap, VisualRotation
from .sky_cadence import SkyCadence

log = logging.getLogger(__name__)

VALID_CUES = ("normals", "lines", "sky")
DEFAULT_CUES = "normals,lines,sky"
"""sky: the sky/ground boundary as a horizon (`solver/sky_horizon.py`), for open scenes."""


def parse_cues(spec: str | tuple | list) -> tuple[str, ...]:
    """`"normals,lines"` -> ("normals", "lines"); an unknown or empty selection is a one-line ConfigError."""
    names = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec)]
    names = [n for n in names if n]
    bad = [n for n in names if n not in VALID_CUES]
    if bad or not names:
        raise ConfigError(f"--cues {','.join(names) if isinstance(spec, (list, tuple)) else spec!r}: "
                          f"expected a comma-separated selection of {', '.join(VALID_CUES)}")
    return tuple(n for n in VALID_CUES if n in names)


FOCAL_ATTEMPTS = 30
"""Frames (with segments) on which a stream without intrinsics estimates f; at the last of them the K
pooled over them all (`pool_intrinsics`) takes over and is kept (the median of the confident estimates,
or the assumed field of view, stays when the pool cannot tell)."""


class CueSolver:
    """The visual rotation of each frame from its normal map and/or its segments (one joint solve).

    Intrinsics: the frame's K when it has one; otherwise f estimated from the scene on the first
    frames that tell it, then pooled over them (then kept: one camera per stream), the assumed field of
    view until then.
    `focal` is the `FocalEstimate` in use.
    """

    def __init__(self, lines: bool = True, assumed_fov_deg: float = DEFAULT_FOV_DEG,
                 detector: SegmentDetector | None = None, sky: bool = False, image_normals: bool = True,
                 motion: bool = True):
        self.detector = (detector or SegmentDetector()) if lines else None
        self.sky = SkyDetector() if sky else None
        """The sky boundary cue (`solver/sky_horizon.py`), None without it."""
        self.sky_cadence = SkyCadence() if sky else None
        """On which frames the sky detector runs (`solver/sky_cadence.py`)."""
        self._sky_now = None
        """The current frame's sky boundary (None: none, or not looked for)."""
        self.image_normals = image_normals
        """Whether the normals come from the image (a network): then a frame without image evidence
        (`solver.evidence`) reports the capped covariance and why; depth normals are not judged so."""
        self.motion = FrameMotion() if motion else None
        """The camera's rotation since the previous frame from the image motion (`VisualRotation.R_cp`:
        the stream's labelling follows it, `backends/labelling_track.py`); None: not measured."""
        self.solver = JointSolver()
        self.offset = CueOffset()
        """The stream's steady normals-to-segments offset (`solver/cue_offset.py`)."""
        self.focal_config = FocalConfig(assumed_fov_deg=assumed_fov_deg)
        self.focal: FocalEstimate | None = None
        self._attempts = 0
        self._focal_px: list[float] = []
        self._evidence: list[FrameEvidence] = []
        self._frames = 0
        self._size: tuple[int, int] | None = None
        """(width, height) of the stream's camera: the first frame without K that has an image. Frames of
        another size are refused once the K is from the scene, solved alone (assumed FOV) before."""
        self.pooled_switch: dict | None = None
        """When the pooled K took over (the stream's frame index and time) and what was used before."""

    def solve(self, frame: Frame, normal_map: NormalMap | None, R_init=None,
              image_motion: bool = True) -> VisualRotation | None:
        """None when neither cue is usable (a blank frame and no normals). `image_motion`: also measure the
        image rotation since the previous frame (`VisualRotation.R_cp`), for a backend that uses it."""
        self._frames += 1
        other_size = self._other_size(frame)
        segments = self.detector.detect(frame.rgb) if self.detector is not None and frame.rgb is not None else None
        looked = self.sky is not None and frame.rgb is not None and self.sky_cadence.look()
        self._sky_now = self.sky.detect(frame.rgb) if looked else None
        found = self._sky_now is not None
        if found:  # the segments join only with man-made verticals (`sky_and_segments`); R_init: the structure's axes
            K = frame.K if frame.K is not None else (self.focal or self._assumed(*frame.rgb.shape[:2])).K
            guess = (up_candidate(R_init, self._sky_now.observation(K).up_c)[1] if R_init is not None
                     else self._sky_now.observation(K).up_c)
            self._sky_now, segments = sky_and_segments(self._sky_now, segments, K, guess, R_cm=R_init)
        try:
            if other_size:
                visual = self._solve_alone(frame, normal_map, segments, R_init)
            else:
                visual = self._solve(frame, normal_map, segments, R_init)
        except InputError:
            visual = None
        if self.sky_cadence is not None:
            self.sky_cadence.seen(looked, found, visual)
        if visual is None:
            return None
        visual = self.offset.update(visual)
        reason = (no_evidence_reason(frame.rgb, normal_map.textured_fraction)
                  if self.image_normals and normal_map is not None else "")
        visual = without_evidence(visual, reason, self.solver.config.max_variance_rad2) if reason else visual
        return self._with_motion(frame, visual) if image_motion else visual

    def _with_motion(self, frame: Frame, visual: VisualRotation) -> VisualRotation:
        """`visual` with the image rotation since the previous frame (`FrameMotion`, at the K in use; its std
        widened when that K is the scene's, `FrameMotionConfig.scene_K_std_scale`)."""
        if self.motion is None:
            return visual
        K = frame.K if frame.K is not None else (self.focal.K if self.focal is not None else None)
        step = self.motion.step(frame.t_s, frame.rgb, K, K_from_scene=frame.K is None)
        return visual if step is None else dataclasses.replace(visual, R_cp=step.R_cp, R_cp_std_rad=step.std_rad)

    def _other_size(self, frame: Frame) -> bool:
        """Whether a frame without K differs in size from the stream's camera (the first such frame's);
        a one-line InputError when it does, the stream's K came from the scene (it holds for one size) and
        the frame is not that camera's image resized (another aspect ratio)."""
        if frame.K is not None or frame.rgb is None:
            return False
        size = (frame.rgb.shape[1], frame.rgb.shape[0])
        self._size = self._size or size
        if (size != self._size and self.focal is not None and self.focal.source == "estimated"
                and self._scaled(size) is None):
            raise InputError(f"frame {self._index(frame)} (t {frame.t_s:.3f} s): {size[0]}x{size[1]} px, but the stream's "
                             f"camera is {self._size[0]}x{self._size[1]} px: one camera's frames have one size")
        return size != self._size

    def _scaled(self, size: tuple[int, int]) -> FocalEstimate | None:
        """The stream's estimated K scaled to a frame of `size` (w, h) with the camera's aspect ratio (the
        same camera's image resized, within 1 %); None for another aspect ratio or without an estimate."""
        if self.focal is None or self.focal.source != "estimated" or self._size is None:
            return None
        sx, sy = size[0] / self._size[0], size[1] / self._size[1]
        if abs(sx / sy - 1.0) > 0.01:
            return None
        K = np.diag([sx, sy, 1.0]) @ self.focal.K
        return FocalEstimate(K, "estimated", self.focal.std_px * sx, width=size[0],
                             origin=f"{self.focal.origin or 'estimated'}, scaled to {size[0]}x{size[1]} px")

    def _solve_alone(self, frame: Frame, normal_map, segments: LineSegments | None, R_init) -> VisualRotation:
        """A frame of another size: the stream's estimated K scaled to it when it is the camera's image
        resized, else the assumed field of view at its own size; it takes no part in the stream's focal length."""
        h, w = frame.rgb.shape[:2]
        focal = self._scaled((w, h)) or self._assumed(h, w)
        return self._solve_at(focal, normal_map, segments, R_init, frame.t_s)

    def _assumed(self, h: int, w: int) -> FocalEstimate:
        """The assumed field of view's K for an h x w image."""
        return FocalEstimate(assumed_K(h, w, self.focal_config.assumed_fov_deg), "assumed", width=w)

    def _solve_at(self, focal: FocalEstimate, normal_map, segments: LineSegments | None, R_init,
                  t_s: float) -> VisualRotation:
        """The joint solve with `focal`'s K, with the floor of a principal point not given."""
        visual = solve_given_K(self.solver, normal_map, segments, focal.K, R_init, t_s=t_s, sky=self._sky_now)
        return unknown_centre_floor(visual, focal, self.focal_config, self.solver)

    def _index(self, frame: Frame) -> int:
        """The frame's index in its source, or its count in this stream when it has none."""
        return frame.index if frame.index >= 0 else self._frames - 1

    def _solve(self, frame: Frame, normal_map, segments: LineSegments | None, R_init) -> VisualRotation:
        if frame.K is not None:
            self.focal = FocalEstimate(np.asarray(frame.K, float), "given", width=frame.rgb.shape[1]
                                       if frame.rgb is not None else 0)
            return solve_given_K(self.solver, normal_map, segments, frame.K, R_init, t_s=frame.t_s, sky=self._sky_now)
        if segments is not None and len(segments) and self._attempts < FOCAL_ATTEMPTS:
            self._attempts += 1
            visual, focal = solve_with_focal(self.solver, normal_map, segments, R_init, self.focal_config, t_s=frame.t_s,
                                             sky=self._sky_now)
            self._evidence.append(FrameEvidence(segments, visual.R_cm))
            if focal.source == "estimated":
                self._focal_px.append(focal.f_px)
            own = None  # the frame's own solve, kept while the stream has no K of its own yet
            if len(self._focal_px) >= 3:
                self.focal = stream_focal(self._focal_px, segments.height, segments.width)
            elif focal.source == "estimated" or self.focal is None or self.focal.source == "assumed":
                self.focal, own = focal, visual
            if self._attempts == FOCAL_ATTEMPTS:  # also when no frame was confident: the pool may still tell
                pooled = pool_intrinsics(self._evidence, self.focal.f_px)
                self._evidence = []
                if pooled is not None:
                    self._switch_to(pooled.focal_estimate(), frame)
                    own = None
            if own is not None:
                return own
        if self.focal is None:
            h, w = (segments.height, segments.width) if segments is not None else (
                frame.rgb.shape[:2] if frame.rgb is not None else normal_map.normals.shape[:2])
            self.focal = self._assumed(h, w)
        return self._solve_at(self.focal, normal_map, segments, R_init, frame.t_s)

    def pool_before(self, frames: list[Frame]) -> bool:
        """The stream's K pooled over `frames` (without K, spread over a recording: `pool_before_run`)
        before it runs, each solved alone from its segments; then kept for every frame, as a K pooled
        mid-stream is. False, changing nothing, when the frames cannot tell one (too few with segments,
        f undetermined) or have a K or differ in size."""
        if self.detector is None or self.focal is not None or len(frames) < SelfCalibrationConfig.min_frames:
            return False  # (too few frames to pool: the stream's own path does its frames once)
        if any(f.K is not None or f.rgb is None or f.rgb.shape != frames[0].rgb.shape for f in frames):
            return False
        evidence, focal_px = [], []
        for frame in frames:
            segments = self.detector.detect(frame.rgb)
            if not len(segments):
                continue
            try:
                visual, focal = solve_with_focal(self.solver, None, segments, None, self.focal_config, t_s=frame.t_s)
            except InputError:  # too few segments for the line cue alone
                continue
            evidence.append(FrameEvidence(segments, visual.R_cm))
            if focal.source == "estimated":
                focal_px.append(focal.f_px)
        if not evidence:
            return False
        h, w = frames[0].rgb.shape[:2]
        f_init = float(np.median(focal_px)) if focal_px else self._assumed(h, w).f_px
        pooled = pool_intrinsics(evidence, f_init)
        if pooled is None:
            return False
        focal = pooled.focal_estimate()
        self.focal = dataclasses.replace(focal, origin=f"{focal.origin}, spread over the recording, before the run")
        self._attempts, self._size = FOCAL_ATTEMPTS, (w, h)
        log.warning("intrinsics: K %s (f %.1f px)", self.focal.origin, self.focal.f_px)  # one line, as `_switch_to`
        return True

    def _switch_to(self, pooled: FocalEstimate, frame: Frame) -> None:
        """Use the pooled K from `frame` on; record and log the change (one line)."""
        n = len(self._focal_px)
        before = ("the assumed field of view" if n == 0 else "each frame's own estimate" if n < 3
                  else f"the median of {n} frames' estimates")
        index = self._index(frame)
        self.pooled_switch = {"frame": index, "t_s": frame.t_s, "before": before, "f_px_before": self.focal.f_px}
        log.warning("intrinsics: from frame %d (t %.3f s) on, K %s (f %.1f px) replaces %s (f %.1f px)",
                    index, frame.t_s, pooled.origin, pooled.f_px, before, self.focal.f_px)
        self.focal = pooled

    def intrinsics_summary(self) -> dict:
        """`focal.as_dict()` for summary.json, with `pooled_from` when a pooled K took over mid-stream."""
        doc = self.focal.as_dict()
        if self.pooled_switch is not None:
            doc["pooled_from"] = self.pooled_switch
        return doc


def pool_before_run(cues: "CueSolver | None", source, max_frames: int | None = None) -> None:
    """`CueSolver.pool_before` over `FOCAL_ATTEMPTS` frames spread over `source` (`Source.sample_frames`;
    over its first `max_frames` when the run stops there) when it is a recording whose frames have no K
    and the line cue runs."""
    if cues is None or cues.detector is None or source.info.K is not None or not source.info.has_frames:
        return
    frames = source.sample_frames(FOCAL_ATTEMPTS, max_frames)
    if frames:
        cues.pool_before(frames)


def stream_focal(focal_px: list[float], height: int, width: int) -> FocalEstimate:
    """The median of per-frame focal estimates, with the standard error of a median (1.25 sigma / sqrt n,
    sigma from the median absolute deviation)."""
    f = np.asarray(focal_px, float)
    median = float(np.median(f))
    sigma = 1.4826 * float(np.median(np.abs(f - median)))
    return FocalEstimate(centred_K(median, height, width), "estimated", std_px=1.25 * sigma / np.sqrt(len(f)),
                         width=width)


def solve_frame(cues: CueSolver | None, frame: Frame | None, normal_map: NormalMap | None,
                R_init=None, image_motion: bool = True) -> VisualRotation | None:
    """One frame's visual rotation: through `cues` (normals and segments jointly) when given with the
    frame, else from the normal map alone; None when no cue is usable (no valid normals, no segments)."""
    if cues is not None and frame is not None:
        return cues.solve(frame, normal_map, R_init, image_motion)
    if normal_map is None:
        return None
    try:
        return solve_manhattan(normal_map, R_init=R_init)
    except InputError:  # a blank or black frame: no valid normals
        return None
