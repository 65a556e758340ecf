"""Camera-IMU rotation `R_ci` from what users write, and its naming back as axis letters.

    R_ci = parse_imu_rotation("android")        # a phone: IMU x right, y up, z out of the screen
    R_ci = parse_imu_rotation("flu")            # IMU x forward, y left, z up (ROS body)
    R_ci = parse_imu_rotation("0.5,-0.5,0.5,-0.5")          # quaternion x,y,z,w
    R_ci = parse_imu_rotation("1,0,0, 0,-1,0, 0,0,-1")      # 3x3, row-major
    R_ci = parse_imu_rotation("camchain-imucam.yaml")       # Kalibr: cam0's T_cam_imu

Convention: `v_c = R_ci @ v_i`, camera frame OpenCV (x right, y down, z forward). Axis letters
name where the IMU's x, y and z axes point as seen from the camera: r(ight), l(eft), d(own), u(p),
f(orward), b(ackward). `rdf` is the identity; a phone's device frame (Android `SensorManager`, iOS
Core Motion: x right, y up, z out of the screen towards the user) seen by its rear camera, with the
video upright in the device's natural orientation, is `rub`. Kalibr's `T_cam_imu` maps IMU to
camera coordinates, so its rotation block is `R_ci`. Every failure is a `ConfigError` naming the
option and what is wrong.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import ConfigError
from ..rotations import rotation_problem

AXIS_LETTERS = {"r": (1, 0, 0), "l": (-1, 0, 0), "d": (0, 1, 0), "u": (0, -1, 0), "f": (0, 0, 1), "b": (0, 0, -1)}
"""Camera-frame direction of each axis letter (OpenCV: x right, y down, z forward)."""
NAMED_CONVENTIONS = {"camera": "rdf", "opencv": "rdf", "android": "rub", "ios": "rub", "ros": "flu"}
"""Names users know, as axis letters of the IMU seen from the camera (see the module docstring)."""
RIGHT_HANDED_CODES = tuple(a + b + c for a in AXIS_LETTERS for b in AXIS_LETTERS for c in AXIS_LETTERS
                           if round(np.linalg.det(np.array([AXIS_LETTERS[a], AXIS_LETTERS[b], AXIS_LETTERS[c]]))) == 1)
"""The 24 axis-letter codes of rotations (signed permutations with det +1)."""
ORTHONORMAL_TOL = 1e-4
"""Largest |R^T R - I| entry accepted for a rotation given as numbers."""
OPTION = "--imu-rotation"


def parse_imu_rotation(text: str, option: str = OPTION) -> np.ndarray:
    """`R_ci` (3, 3) from a name, axis letters, 9 or 4 numbers, or a Kalibr camchain file (module docstring)."""
    spec = str(text).strip()
    key = spec.lower()
    if key in NAMED_CONVENTIONS:
        return axis_letters_rotation(NAMED_CONVENTIONS[key], option)
    if re.fullmatch(r"[rldufb]{3}", key):
        return axis_letters_rotation(key, option)
    if Path(spec).suffix.lower() in (".yaml", ".yml"):
        return kalibr_rotation(Path(spec), option)
    numbers = re.split(r"[\s,;]+", spec.strip("[]() "))
    try:
        values = np.array([float(v) for v in numbers if v], float)
    except ValueError:
        values = None
    if values is None or len(values) not in (4, 9) or not np.all(np.isfinite(values)):
        raise ConfigError(f"{option} {spec!r}: expected one of {', '.join(NAMED_CONVENTIONS)}, three axis letters "
                          "from r/l/d/u/f/b (e.g. rub, flu), 9 numbers of a 3x3 (row-major), a quaternion "
                          "x,y,z,w or a Kalibr camchain .yaml")
    if len(values) == 4:
        if not 0.9 < np.linalg.norm(values) < 1.1:
            raise ConfigError(f"{option} {spec!r}: a quaternion x,y,z,w must have norm 1, got "
                              f"{np.linalg.norm(values):.4f}")
        return Rotation.from_quat(values).as_matrix()
    return checked_rotation(values.reshape(3, 3), f"{option} {spec!r}")


def checked_rotation(R: np.ndarray, where: str) -> np.ndarray:
    """`R` when it is a rotation matrix (orthonormal to `ORTHONORMAL_TOL`, det +1), else a ConfigError."""
    problem = rotation_problem(R, ORTHONORMAL_TOL)
    if problem is not None:
        raise ConfigError(f"{where}: {problem}")
    return np.asarray(R, float)


def axis_letters_rotation(letters: str, option: str = OPTION) -> np.ndarray:
    """`R_ci` whose columns are the camera-frame directions of the IMU's x, y, z axes."""
    R = np.array([AXIS_LETTERS[c] for c in letters.lower()], float).T
    if abs(np.linalg.det(R) - 1.0) > 1e-9:
        kind = "repeat an axis" if abs(np.linalg.det(R)) < 0.5 else "make a left-handed frame"
        raise ConfigError(f"{option} {letters!r}: these axis letters {kind}; use a right-handed set such as "
                          "rdf, rub, flu or frd")
    return R


def axis_letters(R_ci: np.ndarray) -> tuple[str, float]:
    """The axis letters of the signed permutation nearest `R_ci`, and the angle between them, degrees
    (the first code in `RIGHT_HANDED_CODES` on a tie). All 24 angles in one scipy call: a run's
    IMU-rotation check asks this every few frame pairs."""
    angles_deg = np.degrees(Rotation.from_matrix(_CODE_ROTATIONS_T @ np.asarray(R_ci, float)).magnitude())
    best = int(np.argmin(angles_deg))
    return RIGHT_HANDED_CODES[best], float(angles_deg[best])


_CODE_ROTATIONS_T = np.stack([axis_letters_rotation(code).T for code in RIGHT_HANDED_CODES])
"""(24, 3, 3): the transposed `R_ci` of each code in `RIGHT_HANDED_CODES`, in order."""


def convention_name(letters: str) -> str:
    """'rub (android/ios device frame)' for a code that has known names, the code otherwise."""
    names = [name for name, code in NAMED_CONVENTIONS.items() if code == letters and name not in ("opencv",)]
    return f"{letters} ({'/'.join(names)})" if names else letters


def kalibr_rotation(path: Path, option: str = OPTION) -> np.ndarray:
    """`R_ci` from the first camera with a `T_cam_imu` in a Kalibr camchain-imucam YAML file."""
    from ..config import read_yaml

    try:
        data, where = read_yaml(path)
    except ConfigError as exc:
        raise ConfigError(f"{option}: {exc}") from None
    for name in sorted(data):
        cam = data[name]
        if isinstance(cam, dict) and "T_cam_imu" in cam:
            T = np.asarray(cam["T_cam_imu"], float)
            if T.shape != (4, 4):
                raise ConfigError(f"{option} {where}: {name}.T_cam_imu must be a 4x4 matrix, got shape {T.shape}")
            return checked_rotation(T[:3, :3], f"{option} {where} [{name}.T_cam_imu]")
    raise ConfigError(f"{option} {where}: no camera with a T_cam_imu (expected a Kalibr camchain-imucam.yaml)")


def with_imu_geometry(source, R_ci: np.ndarray | None = None, imu_time_offset_s: float | None = None):
    """`source` with its `info.R_ci` and/or `info.imu_time_offset_s` replaced by what the user gave
    (None keeps the source's own); the same object, returned for chaining."""
    changes = {}
    if R_ci is not None:
        changes["R_ci"] = np.asarray(R_ci, float).copy()
    if imu_time_offset_s is not None:
        if not np.isfinite(imu_time_offset_s):
            raise ConfigError(f"--imu-time-offset-s must be a finite number of seconds, got {imu_time_offset_s}")
        changes["imu_time_offset_s"] = float(imu_time_offset_s)
    if changes:
        source.info = dataclasses.replace(source.info, **changes)
    return source
