"""Where estimates go: files written row by row, so a run that stops early leaves valid files.

Each row is written whole (`io.safe_files.RowFile`): a full disk leaves every complete row and
no partial one, and raises `OutputError` naming the file.

- `TumTrajectoryWriter`: `trajectory.tum`, one line `t 0 0 0 qx qy qz qw` per estimate (TUM format,
  readable by evo): the camera orientation `R_wc` (OpenCV camera axes to world, z up), quaternion
  order x y z w; the position is not estimated and written as zeros.
- `EstimatesCsvWriter`: `estimates.csv`: time, quaternion, covariance, up vector, gyro bias, status.
- `EstimateLog`: compact arrays of every estimate in memory, for evaluation against ground truth.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from ..formats.tum import tum_trajectory_line
from ..io.safe_files import RowFile
from ..rotations import quat_xyzw
from ..types import Status
from .runner import FrameResult

ESTIMATE_COLUMNS = (
    ["t_s", "qx", "qy", "qz", "qw"]
    + [f"cov_{i}{j}_rad2" for i in range(3) for j in range(3)]
    + ["up_x", "up_y", "up_z", "bias_x_rad_s", "bias_y_rad_s", "bias_z_rad_s",
       "visual_quality", "status", "status_flags"]
)
"""estimates.csv columns: quaternion x y z w of `R_wc`; covariance (3x3 row-major, rad^2) of the right
perturbation of `R_wc`; up = world up in the camera frame (OpenCV axes); gyro bias in the IMU frame
(empty when the backend has none); status as an integer and as flag names joined by `|`."""


def status_names(status: Status) -> str:
    return "|".join(f.name for f in Status if f and f in status)


class TumTrajectoryWriter:
    def __init__(self, path: Path):
        self.path = Path(path)
        self._rows = RowFile(self.path)
        self._rows.write_row("# timestamp tx ty tz qx qy qz qw  (R_wc: camera OpenCV axes to world, z up; "
                             "position not estimated)\n", counts=False)

    def write(self, result: FrameResult) -> None:
        self._rows.write_row(tum_trajectory_line(result.t_s, quat_xyzw(result.estimate.R_wc)))

    def undo_last(self) -> None:
        self._rows.drop_last_row()

    def close(self) -> None:
        self._rows.close()


def csv_line(row: list) -> str:
    """One row in the csv module's dialect (quoting as needed, \\r\\n line end)."""
    buffer = io.StringIO()
    csv.writer(buffer).writerow(row)
    return buffer.getvalue()


class EstimatesCsvWriter:
    def __init__(self, path: Path):
        self.path = Path(path)
        self._rows = RowFile(self.path)
        self._rows.write_row(csv_line(ESTIMATE_COLUMNS), counts=False)

    def write(self, result: FrameResult) -> None:
        est = result.estimate
        bias = [] if est.gyro_bias_rad_s is None else list(est.gyro_bias_rad_s)
        row = ([f"{result.t_s:.9f}"] + [f"{v:.9f}" for v in quat_xyzw(est.R_wc)]
               + [f"{v:.6e}" for v in np.asarray(est.cov).ravel()]
               + [f"{v:.9f}" for v in est.up_c]
               + ([f"{v:.6e}" for v in bias] if bias else ["", "", ""])
               + ["" if result.visual is None else f"{result.visual.quality:.4f}",
                  int(est.status), status_names(est.status)])
        self._rows.write_row(csv_line(row))

    def undo_last(self) -> None:
        self._rows.drop_last_row()

    def close(self) -> None:
        self._rows.close()


class EstimateLog:
    """Keeps `t_s`, `R_wc`, `cov` and `status` of every estimate (about 170 bytes each) for scoring."""

    def __init__(self):
        self._t, self._R, self._cov, self._status = [], [], [], []

    def write(self, result: FrameResult) -> None:
        self._t.append(result.t_s)
        self._R.append(np.asarray(result.estimate.R_wc, np.float64))
        self._cov.append(np.asarray(result.estimate.cov, np.float64))
        self._status.append(int(result.estimate.status))

    def close(self) -> None:
        pass

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = len(self._t)
        return (np.asarray(self._t, float), np.asarray(self._R).reshape(n, 3, 3),
                np.asarray(self._cov).reshape(n, 3, 3), np.asarray(self._status, int))
