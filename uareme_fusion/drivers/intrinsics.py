"""Camera intrinsics: the `--intrinsics` option, camera files, the values datasets publish, undistortion.

    camera = parse_intrinsics("525,525,319.5,239.5")          # fx,fy,cx,cy (pixels)
    camera = parse_intrinsics("calib.yaml")                    # a camera file (formats below)
    camera = published_camera(Path("rgbd_dataset_freiburg1_desk"))   # None when the name is unknown
    undistort = Undistorter(camera, (height, width)); frame = undistort.frame(frame)

Option values: `fx,fy,cx,cy`, optionally followed by OpenCV radial-tangential distortion
`k1,k2,p1,p2[,k3]`, or a path to a camera file. Camera files (YAML or JSON):
- OpenCV (`cv::FileStorage`, `%YAML:1.0` and `!!opencv-matrix` accepted, or plain YAML/JSON):
  `camera_matrix` (3x3, as `{rows, cols, data}` or nested lists), optional `distortion_coefficients`
  (also `dist_coeffs`, `D`), optional `image_width`/`image_height`;
- Kalibr camchain: `cam0: {camera_model: pinhole, intrinsics: [fu, fv, pu, pv], distortion_model:
  radtan | equidistant, distortion_coeffs: [...], resolution: [w, h]}` (the first camera);
- EuRoC / ASL `sensor.yaml`: `intrinsics: [fu, fv, cu, cv]`, `distortion_model`,
  `distortion_coefficients`, `resolution`.
Distortion models: `radtan` (OpenCV's plumb-bob, 4, 5 or 8 coefficients) and `equidistant`
(OpenCV's fisheye, 4 coefficients).

Published intrinsics (`PUBLISHED`), recognised from a dataset folder's name: TUM RGB-D freiburg1,
2 and 3 (`rgbd_dataset_freiburg{1,2,3}_*`, the values on the TUM RGB-D site, with their distortion)
and ICL-NUIM (`living_room_traj*`, `office_room_traj*`, `lr_kt*`, `of_kt*`; fy as +480 in OpenCV's
y-down frame). EuRoC's `cam0/sensor.yaml` is read by the EuRoC driver with `read_camera_file`.

Undistortion: frames are delivered undistorted with the SAME K (`cv2.initUndistortRectifyMap` with
K as the new camera matrix), so the K a frame carries always describes its pixels; depth maps are
remapped with nearest-neighbour interpolation (no mixing of depths across edges).
Every problem is an `InputError`/`ConfigError` naming the option or the file and the key.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import yaml

from uareme_fusion.errors import ConfigError, InputError
from uareme_fusion.formats.datasets import PUBLISHED_ACCELEROMETER_R_CI, PUBLISHED_INTRINSICS
from uareme_fusion.pinhole import pinhole
from uareme_fusion.types import Frame

DISTORTION_MODELS = ("radtan", "equidistant")
RADTAN_COUNTS = (4, 5, 8)
OPTION = "--intrinsics"


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics `K` (3, 3, pixels, OpenCV convention: x right, y down) with lens distortion
    `dist` (empty: none) of `model` ('radtan' or 'equidistant'); `origin` says where they came from."""

    K: np.ndarray
    dist: np.ndarray
    model: str = "radtan"
    origin: str = ""
    image_size: tuple[int, int] | None = None
    """(height, width) the calibration was made for, when the file says."""

    @property
    def distorted(self) -> bool:
        return bool(np.any(self.dist != 0))


def scaled_camera(camera: CameraModel, scale: float) -> CameraModel:
    """The same camera for its image resized by `scale` (pixel centres kept: x' = (x + 0.5) scale - 0.5);
    distortion acts on normalised coordinates and is unchanged."""
    if scale == 1.0:
        return camera
    K = camera.K.astype(float).copy()
    K[:2, :2] *= scale
    K[:2, 2] = (K[:2, 2] + 0.5) * scale - 0.5
    size = None if camera.image_size is None else tuple(int(round(n * scale)) for n in camera.image_size)
    return replace(camera, K=K, image_size=size)


PUBLISHED: dict[str, CameraModel] = {name: CameraModel(K.copy(), dist.copy())
                                     for name, (K, dist) in PUBLISHED_INTRINSICS.items()}
"""Intrinsics datasets publish (640x480 images; `formats.datasets.PUBLISHED_INTRINSICS`)."""

_PUBLISHED_NAMES = (
    (re.compile(r"freiburg([123])"), lambda m: f"TUM RGB-D freiburg{m.group(1)}"),
    (re.compile(r"\bfr([123])_"), lambda m: f"TUM RGB-D freiburg{m.group(1)}"),
    (re.compile(r"(living_room|office_room)_traj\d|^(lr|of)_?kt\d|icl_nuim"), lambda m: "ICL-NUIM"),
)


def published_dataset(folder: Path) -> tuple[str, str] | None:
    """(dataset, the folder name that identified it) for the dataset a folder's name (or its parent's)
    identifies by `_PUBLISHED_NAMES`, else None."""
    for name in (Path(folder).resolve().name, Path(folder).resolve().parent.name):
        for pattern, dataset in _PUBLISHED_NAMES:
            match = pattern.search(name.lower())
            if match:
                return dataset(match), name
    return None


def published_camera(folder: Path) -> CameraModel | None:
    """The published intrinsics of the dataset a folder's name (or its parent's) identifies, else None."""
    found = published_dataset(folder)
    if found is None:
        return None
    key, name = found
    return replace(PUBLISHED[key], origin=f"published {key} intrinsics (folder name {name})")


def published_accelerometer_rotation(folder: Path) -> tuple[np.ndarray, str] | None:
    """(camera-from-accelerometer `R_ci` (3, 3), where it comes from) of the dataset a folder's name
    identifies, for an accelerometer without gyro (`formats.datasets.PUBLISHED_ACCELEROMETER_R_CI`); None
    when the name identifies none with one."""
    found = published_dataset(folder)
    if found is None or found[0] not in PUBLISHED_ACCELEROMETER_R_CI:
        return None
    key, name = found
    return PUBLISHED_ACCELEROMETER_R_CI[key].copy(), f"published {key} accelerometer axes (folder name {name})"


def parse_intrinsics(value: str) -> CameraModel:
    """`--intrinsics` as `fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]` or a camera file path (module docstring)."""
    text = str(value).strip()
    path = Path(text).expanduser()
    if "," in text and not path.exists():
        return _from_numbers(text)
    if not path.exists():
        raise InputError(f"{OPTION} {text!r}: expected fx,fy,cx,cy (pixels) or a camera file, and no such file "
                         "exists")
    return read_camera_file(path)


def _from_numbers(text: str) -> CameraModel:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"{OPTION} {text!r}: expected fx,fy,cx,cy as numbers (pixels)") from None
    if len(values) < 4 or (len(values) > 4 and len(values) - 4 not in RADTAN_COUNTS):
        raise InputError(f"{OPTION} {text!r}: expected 4 numbers fx,fy,cx,cy, optionally followed by 4, 5 or 8 "
                         f"distortion coefficients (k1,k2,p1,p2[,k3...]); got {len(values)}")
    camera = CameraModel(pinhole(*values[:4]), np.array(values[4:]), "radtan", f"{OPTION} {text}")
    return check_camera(camera, camera.origin)


def check_camera(camera: CameraModel, where: str, image_size: tuple[int, int] | None = None) -> CameraModel:
    """`camera` when its numbers are usable (finite, fx, fy > 0, principal point inside the image when
    `image_size` (height, width) is known); else `InputError` naming `where` and the value."""
    K = camera.K
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(camera.dist))):
        raise InputError(f"{where}: intrinsics must be finite numbers, got K = {K.tolist()}, "
                         f"distortion {camera.dist.tolist()}")
    if fx <= 0 or fy <= 0:
        raise InputError(f"{where}: focal lengths must be > 0 pixels, got fx = {fx:g}, fy = {fy:g}")
    size = image_size or camera.image_size
    if size is not None:
        h, w = size
        if not (0 <= cx <= w and 0 <= cy <= h):
            raise InputError(f"{where}: principal point (cx, cy) = ({cx:g}, {cy:g}) lies outside the {w}x{h} image")
    return camera


class _CameraYamlLoader(yaml.SafeLoader):
    """Safe YAML that also reads OpenCV's `!!opencv-matrix` nodes as plain mappings."""


_CameraYamlLoader.add_constructor("tag:yaml.org,2002:opencv-matrix", lambda loader, node:
                                  loader.construct_mapping(node, deep=True))


def read_camera_mapping(path: Path) -> dict:
    """A camera file's YAML (OpenCV's `%YAML:1.0` line and `!!opencv-matrix` accepted) or JSON mapping."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"camera file {path}: cannot read it as text ({exc})") from None
    text = "\n".join(line for line in text.splitlines() if not line.startswith("%YAML"))
    try:
        if path.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = yaml.load(text, Loader=_CameraYamlLoader)  # noqa: S506 (a SafeLoader subclass)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        first = str(exc).splitlines()[0]
        raise ConfigError(f"camera file {path}: not valid {'JSON' if path.suffix.lower() == '.json' else 'YAML'} "
                          f"({first})") from None
    if not isinstance(data, dict):
        raise ConfigError(f"camera file {path}: expected a mapping of keys, got {type(data).__name__}")
    return data


def _numbers(path: Path, key: str, value, count: int | tuple[int, ...] | None = None) -> np.ndarray:
    """`value` (a list, nested lists, or OpenCV's {rows, cols, data}) as a flat float array."""
    if isinstance(value, dict) and "data" in value:
        value = value["data"]
    try:
        array = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ConfigError(f"camera file {path}: key {key}: expected numbers, got {value!r}") from None
    counts = (count,) if isinstance(count, int) else count
    if counts is not None and len(array) not in counts:
        raise ConfigError(f"camera file {path}: key {key}: expected {' or '.join(map(str, counts))} numbers, "
                          f"got {len(array)}")
    return array


def _size(path: Path, data: dict, key: str = "resolution") -> tuple[int, int] | None:
    if key in data:
        w, h = _numbers(path, key, data[key], 2)
        return int(h), int(w)
    if "image_width" in data and "image_height" in data:
        return int(_numbers(path, "image_height", data["image_height"], 1)[0]), int(
            _numbers(path, "image_width", data["image_width"], 1)[0])
    return None


def _asl_camera(path: Path, data: dict, where: str) -> CameraModel:
    """Kalibr camchain entries and ASL sensor.yaml share `intrinsics` [fu, fv, cu, cv] + a model name."""
    fu, fv, cu, cv = _numbers(path, f"{where}intrinsics", data["intrinsics"], 4)
    model = str(data.get("distortion_model", "radtan")).lower()
    model = {"plumb_bob": "radtan", "radial-tangential": "radtan", "fisheye": "equidistant"}.get(model, model)
    key = "distortion_coeffs" if "distortion_coeffs" in data else "distortion_coefficients"
    dist = _numbers(path, f"{where}{key}", data.get(key, []))
    return CameraModel(pinhole(fu, fv, cu, cv), dist, _check_model(path, f"{where}distortion_model", model, dist),
                       image_size=_size(path, data))


def _check_model(path: Path, key: str, model: str, dist: np.ndarray) -> str:
    if model not in DISTORTION_MODELS:
        raise ConfigError(f"camera file {path}: key {key}: distortion model {model!r} is not supported "
                          f"({', '.join(DISTORTION_MODELS)})")
    allowed = (0, 4) if model == "equidistant" else (0, *RADTAN_COUNTS)
    if len(dist) not in allowed:
        raise ConfigError(f"camera file {path}: key {key}: {model} takes {' or '.join(map(str, allowed[1:]))} "
                          f"coefficients, got {len(dist)}")
    return model


def read_camera_file(path: str | Path) -> CameraModel:
    """A camera file in one of the formats of the module docstring; `ConfigError` naming file and key."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"camera file {path}: is a folder (for EuRoC, pass mav0/cam0/sensor.yaml)")
    data = read_camera_mapping(path)
    if "camera_matrix" in data or "K" in data:
        key = "camera_matrix" if "camera_matrix" in data else "K"
        K = _numbers(path, key, data[key], 9).reshape(3, 3)
        dist_key = next((k for k in ("distortion_coefficients", "dist_coeffs", "D") if k in data), None)
        dist = _numbers(path, dist_key, data[dist_key]) if dist_key else np.zeros(0)
        model = str(data.get("distortion_model", "radtan")).lower()
        model = {"plumb_bob": "radtan", "fisheye": "equidistant"}.get(model, model)
        camera = CameraModel(K, dist, _check_model(path, "distortion_model", model, dist), image_size=_size(path, data))
    elif "intrinsics" in data:
        camera = _asl_camera(path, data, "")
    else:
        cams = sorted(k for k, v in data.items() if re.fullmatch(r"cam\d+", str(k)) and isinstance(v, dict))
        if not cams:
            raise ConfigError(f"camera file {path}: found no camera_matrix (OpenCV), intrinsics (EuRoC sensor.yaml) "
                              "or cam0 (Kalibr camchain) key")
        entry = data[cams[0]]
        if "intrinsics" not in entry:
            raise ConfigError(f"camera file {path}: key {cams[0]}.intrinsics is missing")
        camera = _asl_camera(path, entry, f"{cams[0]}.")
    camera = replace(camera, origin=f"camera file {path}")
    return check_camera(camera, f"camera file {path}")


class Undistorter:
    """Frames of a distorted camera as undistorted frames with the same K (see the module docstring)."""

    def __init__(self, camera: CameraModel, image_size: tuple[int, int]):
        self.camera = camera
        h, w = image_size
        self.image_size = (h, w)
        K, dist = camera.K, camera.dist
        if camera.model == "equidistant":
            self.maps = cv2.fisheye.initUndistortRectifyMap(K, dist, np.eye(3), K, (w, h), cv2.CV_32FC1)
        else:
            self.maps = cv2.initUndistortRectifyMap(K, dist, None, K, (w, h), cv2.CV_32FC1)

    def image(self, image: np.ndarray, nearest: bool = False) -> np.ndarray:
        if image.shape[:2] != self.image_size:
            raise InputError(f"{self.camera.origin}: an image of {image.shape[1]}x{image.shape[0]} pixels does not "
                             f"match the {self.image_size[1]}x{self.image_size[0]} the intrinsics were set up for")
        return cv2.remap(image, *self.maps, cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR)

    def frame(self, frame: Frame) -> Frame:
        """`frame` undistorted (rgb linear, depth nearest), carrying the camera's K."""
        rgb = None if frame.rgb is None else self.image(frame.rgb)
        depth = None if frame.depth is None else self.image(frame.depth, nearest=True)
        return replace(frame, rgb=rgb, depth=depth, K=self.camera.K)


def undistorted_image(camera: CameraModel, image: np.ndarray) -> np.ndarray:
    """One image undistorted with the same K (the principal point checked against its size); for
    a stream of frames keep an `Undistorter` instead (its maps are computed once)."""
    check_camera(camera, camera.origin, image.shape[:2])
    return Undistorter(camera, image.shape[:2]).image(image) if camera.distorted else image
