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

from ..formats.tum import TUM_ROW
from ..io.safe_files import RowFile
from ..rotations import quat_xyzw
from ..types import Estimates, FrameResult, Status, stacked_steady

ESTIMATE_COLUMNS = (
    ["t_s", "qx", "qy", "qz", "qw"]
    + [f"cov_{i}{j}_rad2" for i in range(3) for j in range(3)]
    + ["up_x", "up_y", "up_z", "bias_x_rad_s", "bias_y_rad_s", "bias_z_rad_s",
       "visual_quality", "status", "status_flags", "share_accel", "share_visual"]
    + [f"cov_steady_{i}{j}_rad2" for i in range(3) for j in range(3)]
)
"""estimates.csv columns: quaternion x y z w of `R_wc`; covariance (3x3 row-major, rad^2) of the right
perturbation of `R_wc`; up = world up in the camera frame (OpenCV axes); gyro bias in the IMU frame
(empty when the backend has none); status as an integer and as flag names joined by `|`; the shares
(0..1, summing to 1) of the accelerometer and of the camera in the tilt information the EKF fuses at
that estimate, each source's information per second on tilt as far as the filter trusts it
(`backends/mekf/source_trust.py`: a camera whose vertical keeps disagreeing with a quiet accelerometer
gets a small share); empty for a source the backend has not seen or a backend that does not weigh
sources (single, smoother); the steady part of the covariance (`Estimate.cov_steady`, 3x3 row-major,
rad^2: the error shared by the stream's frames, the calibration's or what the stream does not show
varying, `backends/stream_steady.py`; the rest, cov - cov_steady, is new in each frame), empty when there
is none."""


def status_names(status: Status) -> str:
    return "|".join(f.name for f in Status if f and f in status)




class TumTrajectoryWriter:
    def __init__(self, path: Path):
        self.path = Path(path)
        self._rows = RowFile(self.path)
        self._rows.write_row("# timestamp tx ty tz qx qy qz qw  (R_wc: camera OpenCV axes to world, z up; "
                             "position not estimated)\n", counts=False)

    def write(self, result: FrameResult) -> None:
        self._rows.write_row(TUM_ROW % (result.t_s, *quat_xyzw(result.estimate.R_wc)))

    def write_many(self, estimates: Estimates) -> None:
        """The rows of many estimates, written (and, on a full disk, taken back) together."""
        values = np.concatenate([estimates.t_s[:, None], quat_xyzw(estimates.R_wc, assume_valid=True)], axis=1)
        self._rows.write_row((TUM_ROW * len(estimates)) % tuple(values.ravel().tolist()), counts=len(estimates))

    def undo_last(self) -> None:
        self._rows.drop_last_row()

    def close(self) -> None:
        self._rows.close()


def csv_line(row: list) -> str:
    """One row in the csv module's dialect (quoting as needed, \\r\\n line end)."""
    buffer = io.StringIO()
    csv.writer(buffer).writerow(row)
    return buffer.getvalue()


_CSV_NUMBERS = ",".join(["%.9f"] * 5 + ["%.6e"] * 9 + ["%.9f"] * 3)
"""estimates.csv's numeric columns up to the up vector (`ESTIMATE_COLUMNS`); none needs csv quoting."""


def share_cells(shares) -> str:
    """The `share_accel,share_visual` cells of an `Estimate.tilt_shares` (empty for None or NaN)."""
    if shares is None:
        return ","
    return ",".join("" if not np.isfinite(x) else f"{x:.4f}" for x in shares)


def steady_cells(cov_steady) -> str:
    """The nine `cov_steady_ij_rad2` cells of an `Estimate.cov_steady` (empty for None)."""
    if cov_steady is None:
        return "," * 8
    return ",".join(f"{x:.6e}" for x in np.asarray(cov_steady, float).ravel().tolist())


_IMU_ONLY_SHARES = share_cells(None) + "," + steady_cells(None)
"""The share and steady cells of estimates from an IMU-only stream in bulk: empty (no camera)."""


class EstimatesCsvWriter:
    def __init__(self, path: Path):
        self.path = Path(path)
        self._rows = RowFile(self.path)
        self._rows.write_row(csv_line(ESTIMATE_COLUMNS), counts=False)
        self._names: dict[int, str] = {}

    def write(self, result: FrameResult) -> None:
        est = result.estimate
        bias = None if est.gyro_bias_rad_s is None else np.asarray(est.gyro_bias_rad_s, float)[None]
        quality = "" if result.visual is None else f"{result.visual.quality:.4f}"
        self._rows.write_row(self._lines(np.array([result.t_s]), np.asarray(est.R_wc, float)[None],
                                         np.asarray(est.cov, float)[None], bias, [quality], [int(est.status)],
                                         [share_cells(est.tilt_shares) + "," + steady_cells(est.cov_steady)]))

    def write_many(self, estimates: Estimates) -> None:
        """The rows of many estimates (no visual rotation), written (and taken back) together."""
        n = len(estimates)
        self._rows.write_row(self._lines(estimates.t_s, estimates.R_wc, estimates.cov, estimates.gyro_bias_rad_s,
                                         [""] * n, estimates.status.tolist(), [_IMU_ONLY_SHARES] * n), counts=n)

    def _lines(self, t_s, R_wc, cov, bias, quality: list[str], status: list[int], shares: list[str]) -> str:
        """csv rows (\\r\\n ends, as `csv_line`) of M estimates: `t_s` (M,), `R_wc` and `cov` (M, 3, 3),
        `bias` (M, 3) or None (a NaN row: empty cells), visual quality cells and status ints."""
        n = t_s.shape[0]
        numbers = np.concatenate([t_s[:, None], quat_xyzw(R_wc, assume_valid=True), cov.reshape(n, 9), R_wc[:, 2, :]], axis=1)
        with_bias = bias is not None and bool(np.isfinite(bias).all())
        row = _CSV_NUMBERS + (",%.6e,%.6e,%.6e" if with_bias else ",,,") + "\0"
        values = np.concatenate([numbers, bias], axis=1) if with_bias else numbers
        heads = ((row * n) % tuple(values.ravel().tolist())).split("\0")
        if bias is not None and not with_bias:  # some estimates have a bias: theirs, empty cells for the others
            heads = [head if not np.isfinite(b).all() else ("%s,%.6e,%.6e,%.6e" % (head[:-3], *b))
                     for head, b in zip(heads, bias.tolist())]
        names = self._status_names
        return "".join([f"{head},{q},{s},{names(s)},{sh}\r\n"
                        for head, q, s, sh in zip(heads, quality, status, shares)])

    def _status_names(self, status: int) -> str:
        names = self._names.get(status)
        if names is None:
            names = self._names[status] = status_names(Status(status))
        return names

    def undo_last(self) -> None:
        self._rows.drop_last_row()

    def close(self) -> None:
        self._rows.close()


class EstimateLog:
    """Keeps `t_s`, `R_wc`, `cov` and `status` of every estimate (about 170 bytes each) for scoring."""

    def __init__(self):
        self._t, self._R, self._cov, self._status = [], [], [], []
        self._steady: dict[int, np.ndarray] = {}  # estimate index -> its cov_steady, where it has one

    def write(self, result: FrameResult) -> None:
        if result.estimate.cov_steady is not None:
            self._steady[len(self._t)] = np.asarray(result.estimate.cov_steady, np.float64)
        self._t.append(result.t_s)
        self._R.append(np.asarray(result.estimate.R_wc, np.float64))
        self._cov.append(np.asarray(result.estimate.cov, np.float64))
        self._status.append(int(result.estimate.status))

    def write_many(self, estimates: Estimates) -> None:
        self._t.extend(estimates.t_s.tolist())
        self._R.extend(estimates.R_wc)
        self._cov.extend(estimates.cov)
        self._status.extend(estimates.status.tolist())

    def close(self) -> None:
        pass

    def steady(self) -> np.ndarray | None:
        """`Estimate.cov_steady` of every estimate (N, 3, 3), NaN where one has none; None when none has."""
        return stacked_steady(len(self._t), self._steady)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n = len(self._t)
        return (np.asarray(self._t, float), np.asarray(self._R).reshape(n, 3, 3),
                np.asarray(self._cov).reshape(n, 3, 3), np.asarray(self._status, int))
