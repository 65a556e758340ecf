"""Building the pipeline's stages from a `RunConfig` and what the source says about itself."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from ..backends.base import Backend
from ..drivers.base import PLATFORMS, SourceInfo
from ..errors import InputError
from ..io.normal_maps import load_normal_map
from ..types import Frame, NormalMap
from .config import RunConfig

NORMAL_FILE_SUFFIXES = (".npz", ".npy", ".png")
MODEL_FILE_SUFFIXES = (".pt", ".pth", ".ts", ".onnx")


class SourceNormals:
    """The normals a source carries with each frame (the simulator's exact normals)."""

    name = "source"

    def __init__(self, source_name: str):
        self.source_name = source_name

    def estimate_frame(self, frame: Frame) -> NormalMap:
        if frame.normals is None:
            raise InputError(f"{self.source_name}: frame {frame.index} carries no normals "
                             "(use --normals learned or depth)")
        return frame.normals


class NormalFiles:
    """Precomputed normal maps, one file per frame in sorted order (frame i reads the i-th file); hidden
    files (an unfinished `.NAME.partial.npz` of an export that was killed) are not maps."""

    name = "files"

    def __init__(self, folder: Path):
        self.files = sorted(p for p in folder.iterdir()
                            if p.suffix.lower() in NORMAL_FILE_SUFFIXES and not p.name.startswith("."))
        if not self.files:
            raise InputError(f"{folder}: no normal maps ({', '.join(NORMAL_FILE_SUFFIXES)}) in this folder")
        self._count = 0

    def estimate_frame(self, frame: Frame) -> NormalMap:
        k = frame.index if frame.index >= 0 else self._count
        self._count += 1
        if k >= len(self.files):
            raise InputError(f"{self.files[0].parent}: {len(self.files)} normal maps but the source has "
                             f"a frame {k}")
        return load_normal_map(self.files[k])


class CappedNormals:
    """Any estimator's normal maps with kappa capped (the paper caps it before the solver)."""

    def __init__(self, estimator, cap: float):
        self.estimator, self.cap = estimator, float(cap)

    @property
    def name(self) -> str:
        return getattr(self.estimator, "name", type(self.estimator).__name__)

    @property
    def needs_depth(self) -> bool:
        return getattr(self.estimator, "needs_depth", False)

    @property
    def note(self) -> str | None:
        """The estimator's note on what it chose (`AutoNormals`), None without one."""
        return getattr(self.estimator, "note", None)

    def estimate_frame(self, frame: Frame) -> NormalMap | None:
        nm = self.estimator.estimate_frame(frame)
        if nm is None:
            return None
        if nm.kappa is not None and np.nanmax(nm.kappa, initial=0.0) > self.cap:
            nm = dataclasses.replace(nm, kappa=np.minimum(nm.kappa, self.cap))
        return nm


class AutoNormals:
    """The normals right for the input, decided on the first frame: the source's own when its frames
    carry them (the simulator's exact normals), else `depth` when given (a source with depth maps and
    intrinsics: TUM, ICL-NUIM, OAK stereo), else learned. `note` says what was chosen when it was
    depth (a user expecting the network should be told)."""

    def __init__(self, source_name: str, threads: int | None = None, depth=None):
        self.source_name, self.name, self._chosen, self.threads = source_name, "auto", None, threads
        self.depth, self.note = depth, None

    @property
    def needs_depth(self) -> bool:
        return getattr(self._chosen, "needs_depth", False)

    def estimate_frame(self, frame: Frame) -> NormalMap | None:
        if self._chosen is None:
            if frame.normals is not None:
                self._chosen = SourceNormals(self.source_name)
            elif self.depth is not None:
                self._chosen = self.depth
                self.note = (f"--normals auto: {self.source_name} has depth maps and intrinsics, so the normals "
                             "come from depth (--normals learned for the network's)")
            else:
                self._chosen = _learned(threads=self.threads)
            self.name = f"auto ({self._chosen.name})"
        return self._chosen.estimate_frame(frame)


class DepthWhereAvailable:
    """Depth normals for frames with a depth map; None (no normal map: the frame uses the remaining
    cues, and the pipeline flags it `DEPTH_MISSING`) for frames without one."""

    name = "depth"
    needs_depth = True
    """A frame without depth gets no normals from it (the runner flags it `DEPTH_MISSING`)."""

    def __init__(self, estimator):
        self.estimator = estimator

    def estimate_frame(self, frame: Frame) -> NormalMap | None:
        return None if frame.depth is None else self.estimator.estimate_frame(frame)


def auto_takes_depth(info: SourceInfo) -> bool:
    """Whether `--normals auto` takes depth's normals for the source `info`: it has depth maps and intrinsics."""
    return info.has_depth and info.K is not None


def make_normal_estimator(spec: str, info: SourceInfo, threads: int | None = None):
    """The normal estimator named by `spec` (see `RunConfig.normals`); checks that the source can feed it.
    `threads`: torch CPU threads of a learned network (None: `LearnedNormalsConfig`'s default)."""
    from ..normals.depth import depth_normals_for

    if spec == "auto":
        depth = DepthWhereAvailable(depth_normals_for(info)) if auto_takes_depth(info) else None
        return AutoNormals(info.name, threads, depth)
    if spec == "source":
        return SourceNormals(info.name)
    if spec == "depth":
        if not info.has_depth:
            raise InputError(f"{info.name}: --normals depth needs a depth map, and this source has none "
                             "(use --normals learned)")
        if info.K is None:
            raise InputError(f"{info.name}: --normals depth needs the camera intrinsics, and this source does not "
                             "know them: give --intrinsics fx,fy,cx,cy or a camera file")
        return DepthWhereAvailable(depth_normals_for(info))
    if spec == "learned":
        return _learned(threads=threads)
    path = Path(spec)
    if path.is_dir():
        return NormalFiles(path)
    if path.suffix.lower() in MODEL_FILE_SUFFIXES:
        if not path.is_file():
            raise InputError(f"{path}: model file not found")
        return _learned(path, threads)
    raise InputError(f"--normals {spec!r}: expected auto, learned, depth, source, a model file "
                     f"({', '.join(MODEL_FILE_SUFFIXES)}) or a folder of normal maps")


def _learned(model_path: Path | None = None, threads: int | None = None):
    from ..normals.learned import DEFAULT_THREADS, LearnedNormals, LearnedNormalsConfig

    # The map stays at the network's size: the solver does not need it upsampled, overlays resize it.
    return LearnedNormals(model=model_path, config=LearnedNormalsConfig(threads=threads or DEFAULT_THREADS,
                                                                        at_input_size=False))


CAMERA_PRESETS = PLATFORMS
"""Shipped EKF presets tuned for a camera with (or without) an IMU, one per camera platform."""
DEFAULT_CAMERA_PRESET = "handheld"
IMU_ONLY_PRESET = "imu_only"


def mekf_preset_for(requested: str | None, info: SourceInfo) -> tuple[str, str | None]:
    """The EKF preset a run uses and, when it is not the one asked for, a note saying why.

    Chosen from what the source holds: with frames, `requested`, else the source's `platform` (a
    simulated bus says `vehicle`), else handheld; without frames (an IMU
    log), `requested` when it is the user's own file or imu_only, and imu_only instead of a camera
    preset (building, handheld, vehicle: their IMU settings assume a camera corrects the attitude; alone
    they give about twice the tilt error of imu_only on BROAD, `bench broad`)."""
    if info.has_frames:
        if requested is None and info.platform in CAMERA_PRESETS and info.platform != DEFAULT_CAMERA_PRESET:
            return info.platform, f"{info.name} says the camera rides a {info.platform}: ran with the '{info.platform}' preset"
        return requested or DEFAULT_CAMERA_PRESET, None
    if requested in CAMERA_PRESETS:
        return IMU_ONLY_PRESET, (f"preset '{requested}' tunes camera + IMU fusion and {info.name} has no camera: "
                                 f"ran with the '{IMU_ONLY_PRESET}' preset")
    return requested or IMU_ONLY_PRESET, None


LEARNED_NORMALS_VISUAL_BIAS = {"image_rotation_visual_bias_std_rad": 0.1, "image_rotation_visual_bias_max_share": 0.3}
"""The visual-only EKF's visual bias (`MekfConfig.image_rotation_visual_bias_std_rad`) for normals from a
network (`image_normals`): its errors are larger than depth's (its correlation time is depth's, the config's
3 s). Real, no IMU, mekf, tuned on TUM fr1 rpy train and ICL kt3 (tools/visual_only_replay.py): TUM train
learned normals+lines ARE 6.33 -> 4.82 deg (single 10.83; NEES 1.43); kt3 RGB normals 3.60 -> 1.69 (single
4.38; NEES 4.02), normals+lines 0.23 -> 0.20 (NEES 1.35). The cap 0.15 instead: TUM train 5.01 (NEES 1.78),
kt3 normals NEES 7.44; 0.5: kt3 normals+lines NEES 0.97. Depth's 0.05 rad, 3 s, cap 0.25 (the config's) for
a network: TUM eval 11.47, NEES 10.4.
Correlation time 10 s (as first tuned) -> 5 / 3 / 2 / 1 s on the same tuning frames: TUM train normals+lines
4.82 -> 4.70 / 4.71 / 4.77 / 4.88 deg (NEES 1.43 -> 1.58 / 1.79 / 2.04 / 2.67), normals 4.59 -> 4.57 / 4.62
/ 4.68 / 4.74, kt3 normals 1.69 -> 1.63 / 1.55 / 1.46 / 1.29 (NEES about 3.9), EuRoC V1_01 micro cam0 alone
(IMU dropped; not trained on) NEES 5.41 -> 1.84 / 1.04 / 1.16 / 0.95 at ARE 0.18-0.19; beside the Kinect's
accelerometer (`eval --normals learned`) TUM train tilt 1.73 -> 1.63 / 1.58 deg (10 / 5 / 3 s). 3 s taken.
Measured on the evaluation frames since (not tuned on): RGB mekf 10.90 -> 10.56 deg; with the
accelerometer tilt 2.32 -> 2.08, ARE 4.45 -> 4.02."""


SCENE_K_VISUAL_BIAS = {"image_rotation_visual_bias_std_rad": 0.0}
"""The visual-only EKF's visual bias is off for a source whose K is estimated from the scene: its image
rotations are scaled by the focal error (`FrameMotionConfig.scene_K_std_scale`), an error the bias state
would take for the frames' own and follow. Real ICSL corridor (scene K), learned normals+lines, bias on:
mekf NEES 19-76 and corridor_more mekf worse than single (the reverted merge c69debc)."""


def image_normals(spec: str, info: SourceInfo) -> bool:
    """Whether `RunConfig.normals` `spec` gives a network's normals for the source `info`, not depth's, the
    source's or precomputed maps: learned, a model file, or auto on a source without depth maps and
    intrinsics (`AutoNormals` then takes the network; a simulator's own normals are counted with them)."""
    if spec == "auto":
        return not auto_takes_depth(info)
    return spec == "learned" or Path(spec).suffix.lower() in MODEL_FILE_SUFFIXES


def backend_for_run(cfg: RunConfig, info: SourceInfo) -> Backend:
    """The backend of `cfg`, made by the one factory (`backends.factory.make_backend`) with the source's
    IMU-to-camera rotation and time offset, the EKF preset for this source and `cfg`'s config keys.

    A source without intrinsics has its K estimated from the scene (focal length a few per cent off: real
    ICSL corridor_more 578.5 px against 537.6), and the image rotation between frames, measured at that K,
    is scaled by the error (7 % of a 90 deg corner): its std is widened for it
    (`FrameMotionConfig.scene_K_std_scale`), and the paper smoother gives the image rotations' rate bias
    room to follow that scaling (`smoother.SCENE_K_IMAGE_ROTATION_BIAS`, for the keys `cfg` does not set);
    the visual-only EKF's visual bias is then off (`SCENE_K_VISUAL_BIAS`), else a network's normals get
    their own (`LEARNED_NORMALS_VISUAL_BIAS`)."""
    from ..backends.factory import backend_kind, make_backend
    from ..backends.smoother import SCENE_K_IMAGE_ROTATION_BIAS

    imu_geometry = {"R_ci": np.asarray(info.R_ci, float).tolist(), "imu_time_offset_s": info.imu_time_offset_s}
    kind = backend_kind(cfg.backend, info.has_imu)
    overrides = cfg.mekf if kind.name == "mekf" else cfg.smoother
    if kind.name == "mekf" and info.K is None:
        overrides = {**SCENE_K_VISUAL_BIAS, **overrides}
    elif kind.name == "mekf" and image_normals(cfg.normals, info):
        overrides = {**LEARNED_NORMALS_VISUAL_BIAS, **overrides}
    if kind.name == "smoother" and info.K is None:
        overrides = {**SCENE_K_IMAGE_ROTATION_BIAS, **overrides}
    preset = mekf_preset_for(cfg.mekf_preset, info)[0] if kind.name == "mekf" else None
    return make_backend(kind.name, imu_geometry, preset, overrides)
