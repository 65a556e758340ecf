"""Ground truth from a trajectory file, for `eval --gt FILE` on sources without their own.

    t_s, R_wc = read_ground_truth_file("groundtruth.txt", time_offset_s=0.0, R_ci=np.eye(3))

Formats (told apart by the first data line: commas mean EuRoC):
- TUM (`timestamp tx ty tz qx qy qz qw`, seconds, whitespace): the camera's `R_wc`;
- EuRoC ground truth (`timestamp [ns], p xyz, q_RS w x y z, ...`, commas): the body (IMU) frame's
  `R_wi`, turned into the camera's `R_wc = R_wi R_ci^T` with the run's camera-IMU rotation.
Both worlds are taken as gravity-aligned (z up), as in EuRoC, TUM RGB-D with its IMU and our own
outputs; `time_offset_s` is added to the file's stamps to put them on the source's clock (the same
convention as `--imu-time-offset-s`). `drivers.ground_truth_file` gives a source this truth.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..io.text_tables import sniff_delimiter
from .euroc import read_euroc_ground_truth
from .tum import read_tum_trajectory


def read_ground_truth_file(path: str | Path, time_offset_s: float = 0.0,
                           R_ci: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The file's stamps `t_s` (N,) on the source's clock, in time order, and the camera's `R_wc` (N, 3, 3)
    at them; see the module docstring."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"--gt {path}: no such file")
    if not np.isfinite(time_offset_s):
        raise InputError(f"--gt-time-offset-s must be a finite number of seconds, got {time_offset_s}")
    if sniff_delimiter(path) == ",":
        t_s, R_wi = read_euroc_ground_truth(path)
        R_wc = R_wi @ (np.eye(3) if R_ci is None else np.asarray(R_ci, float)).T
    else:
        t_s, _, quat_xyzw = read_tum_trajectory(path)
        R_wc = Rotation.from_quat(quat_xyzw).as_matrix() if len(t_s) else np.zeros((0, 3, 3))
    if len(t_s) == 0:
        raise InputError(f"{path}: the ground-truth file holds no rows")
    order = np.argsort(np.asarray(t_s, float), kind="stable")
    return np.asarray(t_s, float)[order] + time_offset_s, np.asarray(R_wc, float)[order]
