"""`open_source`: one string names any input; the right driver opens it.

    with open_source("clip.mp4", imu="imu.csv") as src: ...
    with open_source("sim:bus", seconds=20, render=False) as src: ...

Spec -> driver (first match wins):
- `sim:SCENARIO` -> `SimulatedSource` (options: seconds, width, height, seed, render, imu, imu_rate_hz,
  imu_noise, hfov_deg, normals_noise_deg, R_ci);
- `webcam` / `webcam:N` -> `VideoSource`; `oak` / `oak:ID` -> `OakSource` (size, depth, imu_rate_hz);
- a folder with `rgb.txt` -> `TumSource` (TUM RGB-D, `simulate` output, `--record` folders);
  with `associations.txt` -> `IclNuimSource` when its timestamps are frame numbers, else `TumSource`;
  with `mav0/` (or `cam0/`/`imu0/`) -> `EurocSource`; holding image files -> `ImageSource`;
- a ROS 2 bag folder (`metadata.yaml`), a `.bag` (ROS 1), `.mcap` or `.db3` file -> `RosbagSource`
  (options `image_topic`, `imu_topic`, `depth_topic`, `camera_info_topic`, `gt_topic`; given for
  another source they are refused);
- a `.hdf5`/`.h5` file (or any file with the HDF5 signature) -> `BroadSource`; an image file or a
  glob -> `ImageSource`; a text file, whatever its extension, is an IMU table -> `ImuCsvSource`
  (EuRoC columns; one that does not read as one is refused naming the file and line); any other
  file -> `VideoSource` (refused, naming the file, when OpenCV cannot open it).
`imu=FILE` merges an EuRoC-format IMU CSV into a camera source (`merge_imu`; option
`imu_time_offset_s`, added to the IMU stamps to put them on the camera clock). `fps` applies to
video, images, ICL-NUIM, the simulator and OAK; datasets with their own timestamps refuse it.
`intrinsics` (`--intrinsics`: fx,fy,cx,cy or a camera file, see `intrinsics.parse_intrinsics`)
replaces the camera's K and undistorts its frames (`calibrated.with_intrinsics`).
Every failure to open is an `InputError` naming the spec and what is missing.
"""

from __future__ import annotations

import glob as globlib
import inspect
from pathlib import Path

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.io.paths import is_pipe, path_kind
from uareme_fusion.io.text_tables import is_text_file

from ..formats.tum import read_associations
from ..sim.dataset import incomplete_simulation
from .base import Source
from .broad_source import BroadSource
from .calibrated import with_intrinsics
from .euroc import EurocSource, find_mav0
from .icl_nuim import IclNuimSource
from .images import IMAGE_SUFFIXES, ImageSource
from .imu_csv import ImuCsvSource, merge_imu
from .intrinsics import parse_intrinsics
from .rosbag import is_bag
from .simulated import SimulatedSource
from .tum import TumSource
from .video import VideoSource, parse_webcam

BROAD_SUFFIXES = (".hdf5", ".h5")
HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
TOPIC_OPTIONS = ("image_topic", "imu_topic", "depth_topic", "camera_info_topic", "gt_topic")
"""Options only a ROS bag takes (`--image-topic` ...)."""
TABLE_SUFFIXES = (".csv", ".txt", ".tsv", ".dat", ".log", "")
"""Names users give IMU tables; a text file under another name is also read as one, with a message
that says it is not a video when it does not read."""


def _construct(cls, where: str, *args, **options) -> Source:
    """`cls(*args, **options)` with unknown option names reported as an `InputError`."""
    accepted = [name for name in inspect.signature(cls.__init__).parameters if name != "self"]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise InputError(f"{where}: unknown option(s) {', '.join(unknown)}; {cls.__name__} accepts "
                         f"{', '.join(accepted[len(args):])}")
    return cls(*args, **options)


def _no_fps(fps: float | None, where: str) -> None:
    if fps is not None:
        raise InputError(f"{where}: --fps does not apply (the dataset has its own timestamps)")


def _associations_count_frames(path: Path) -> bool:
    t, _, _ = read_associations(path)
    return len(t) > 0 and bool(np.all(np.asarray(t) == np.round(t)))


def _open_folder(path: Path, fps: float | None, options: dict) -> Source:
    where = str(path)
    interrupted = incomplete_simulation(path)
    if interrupted:
        raise InputError(f"{path}: is {interrupted}; write it again with 'uareme-fusion simulate ... --out {path} "
                         "--force'")
    if (path / "rgb.txt").is_file():
        _no_fps(fps, where)
        return _construct(TumSource, where, path, **options)
    if (path / "associations.txt").is_file():
        if _associations_count_frames(path / "associations.txt"):
            return _construct(IclNuimSource, where, path, fps=fps, **options)
        _no_fps(fps, where)
        return _construct(TumSource, where, path, **options)
    if find_mav0(path) is not None:
        _no_fps(fps, where)
        return _construct(EurocSource, where, path, **options)
    if any(p.suffix.lower() in IMAGE_SUFFIXES for p in path.iterdir() if p.is_file()):
        return _construct(ImageSource, where, path, fps=fps, **options)
    subfolders = sorted(p.name for p in path.iterdir() if p.is_dir())
    if {"rgb", "depth"} & set(subfolders):
        raise InputError(f"dataset folder {path}: has {'/ and '.join(s for s in subfolders if s in ('rgb', 'depth'))}/ "
                         "but no index file: expected rgb.txt (TUM RGB-D, simulate output) or associations.txt "
                         "(ICL-NUIM); to run on the images alone, pass the image folder itself")
    if "mav0" in subfolders or "imu0" in subfolders:
        raise InputError(f"EuRoC folder {path}: found no cam0/data.csv or imu0/data.csv")
    raise InputError(f"folder {path}: not a dataset (no rgb.txt, associations.txt or mav0/) and holds no image "
                     "files")


def open_source(spec: str, imu: str | None = None, fps: float | None = None, intrinsics: str | None = None,
                **options) -> Source:
    """Open the input `spec` names (see the module docstring); `imu` merges an IMU CSV into it,
    `intrinsics` gives the camera's K (and distortion)."""
    imu_offset_s = float(options.pop("imu_time_offset_s", 0.0))
    if fps is not None and not (np.isfinite(fps) and fps > 0):
        raise InputError(f"--fps must be > 0, got {fps}")
    camera = parse_intrinsics(intrinsics) if intrinsics is not None else None
    topics = {name: options.pop(name) for name in TOPIC_OPTIONS if options.get(name) is not None}
    for name in TOPIC_OPTIONS:
        options.pop(name, None)
    if camera is not None and is_bag(Path(str(spec).strip()).expanduser()):
        options["camera"] = camera  # a bag undistorts its raw frames with the given camera in place of its CameraInfo
        camera = None
    source = _open(str(spec).strip(), fps, options, topics)
    if camera is not None:
        source = with_intrinsics(source, camera)
    if imu is None:
        return source
    try:
        return merge_imu(source, ImuCsvSource(imu, accelerometer_only=True), imu_offset_s)
    except BaseException:
        source.close()
        raise


def _open(spec: str, fps: float | None, options: dict, topics: dict) -> Source:
    path = Path(spec).expanduser()
    if is_bag(path):
        from .rosbag import RosbagSource

        _no_fps(fps, spec)
        return _construct(RosbagSource, spec, path, **options, **topics)
    if topics:
        given = ", ".join("--" + name.replace("_", "-") for name in topics)
        raise InputError(f"{spec}: {given} applies to ROS bags and MCAP files (.bag, .mcap, .db3 or a folder with "
                         "metadata.yaml), not to this source")
    if spec.startswith("sim:"):
        if fps is not None:
            options["fps"] = fps
        return _construct(SimulatedSource, spec, spec[4:], **options)
    if parse_webcam(spec) is not None:
        return _construct(VideoSource, spec, spec, fps=fps, **options)
    if spec == "oak" or spec.startswith("oak:"):
        from .oak import OakSource

        return _construct(OakSource, spec, spec[4:] or None, fps=fps, **options)
    if path.is_dir():
        return _open_folder(path, fps, options)
    if path.is_file():
        if path.stat().st_size == 0:
            raise InputError(f"{spec}: empty file (0 bytes), expected a video, an image or an IMU table")
        suffix = path.suffix.lower()
        if suffix in BROAD_SUFFIXES:
            _no_fps(fps, spec)
            return _construct(BroadSource, spec, path, **options)
        if suffix in IMAGE_SUFFIXES:
            return _construct(ImageSource, spec, path, fps=fps, **options)
        if is_text_file(path):
            _no_fps(fps, spec)
            return _open_table(path, spec, options)
        if _has_hdf5_signature(path):
            _no_fps(fps, spec)
            return _construct(BroadSource, spec, path, **options)
        return _construct(VideoSource, spec, path, fps=fps, **options)
    if is_pipe(path) and path.suffix.lower() == ".csv":
        _no_fps(fps, spec)
        return _construct(ImuCsvSource, spec, path, **options)
    if globlib.has_magic(spec):
        return _construct(ImageSource, spec, spec, fps=fps, **options)
    kind = path_kind(path)
    if kind is not None:
        raise InputError(f"{spec}: is {kind}, not a video, images or a dataset folder"
                         + (" (a pipe is read only as an IMU CSV: --imu, or a name ending in .csv)"
                            if is_pipe(path) else ""))
    raise InputError(f"{spec}: no such file or folder (expected a video, images, a dataset folder, a .hdf5 or "
                     ".csv file, webcam:N, sim:SCENARIO or oak[:ID])")


def _has_hdf5_signature(path: Path) -> bool:
    with open(path, "rb") as fh:
        return fh.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE


def _open_table(path: Path, spec: str, options: dict) -> Source:
    """A text file as an IMU table; under a name users do not give tables (`clip.mp4` holding text),
    the message says it is neither a video nor an IMU table."""
    try:
        return _construct(ImuCsvSource, spec, path, **options)
    except InputError as exc:
        if path.suffix.lower() in TABLE_SUFFIXES:
            raise
        reason = str(exc).replace(f"{path}: ", "").replace(f"{path} ", "").split(";")[0]
        raise InputError(f"{path}: neither a video (it holds text) nor an IMU table ({reason})") from None
