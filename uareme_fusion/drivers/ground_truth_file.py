"""Ground truth from a trajectory file, for `eval --gt FILE` on sources without their own.

    truth = read_ground_truth_file("groundtruth.txt", time_offset_s=0.0, R_ci=np.eye(3))

Formats (told apart by the first data line: commas mean EuRoC):
- TUM (`timestamp tx ty tz qx qy qz qw`, seconds, whitespace): the camera's `R_wc`;
- EuRoC ground truth (`timestamp [ns], p xyz, q_RS w x y z, ...`, commas): the body (IMU) frame's
  `R_wi`, turned into the camera's `R_wc = R_wi R_ci^T` with the run's camera-IMU rotation.
Both worlds are taken as gravity-aligned (z up), as in EuRoC, TUM RGB-D with its IMU and our own
outputs; `time_offset_s` is added to the file's stamps to put them on the source's clock (the same
convention as `--imu-time-offset-s`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..formats.euroc import read_euroc_ground_truth
from ..formats.tum import read_tum_trajectory
from .base import GroundTruth


def _is_euroc(path: Path) -> bool:
    with open(path, encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.strip() and not line.lstrip().startswith("#"):
                return "," in line
    raise InputError(f"{path}: the ground-truth file holds no rows")


def read_ground_truth_file(path: str | Path, time_offset_s: float = 0.0, R_ci: np.ndarray | None = None) -> GroundTruth:
    """The file's attitudes as the camera's `R_wc` on the source's clock; see the module docstring."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"--gt {path}: no such file")
    if not np.isfinite(time_offset_s):
        raise InputError(f"--gt-time-offset-s must be a finite number of seconds, got {time_offset_s}")
    if _is_euroc(path):
        t_s, R_wi = read_euroc_ground_truth(path)
        R_wc = R_wi @ (np.eye(3) if R_ci is None else np.asarray(R_ci, float)).T
    else:
        t_s, _, quat_xyzw = read_tum_trajectory(path)
        R_wc = Rotation.from_quat(quat_xyzw).as_matrix()
    if len(t_s) == 0:
        raise InputError(f"{path}: the ground-truth file holds no rows")
    return GroundTruth(np.asarray(t_s, float) + time_offset_s, R_wc, gravity_aligned=True)


def with_ground_truth_file(source, path: str | Path, time_offset_s: float = 0.0):
    """`source`, whose `ground_truth()` now reads `path` (in place of its own); returned for chaining."""
    truth = read_ground_truth_file(path, time_offset_s, source.info.R_ci)
    source.ground_truth = lambda: truth
    return source
