"""Reader for EuRoC MAV IMU files (`mav0/imu0/data.csv`), as recorded and as the simulator writes.

Format: one header line starting with `#`, then `timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y,
a_z [m/s^2]` comma-separated, gyro and specific force in the IMU (sensor) frame `S`.

    imu = read_euroc_imu("mav0/imu0/data.csv")
    imu.t_s, imu.gyro_rad_s, imu.accel_m_s2        # (N,), (N, 3), (N, 3)
    for sample in imu.samples(): ...               # uareme_fusion.types.ImuSample

Times: `t_ns` keeps the file's integer nanoseconds exactly; `t_s = t_ns * 1e-9` as float seconds.
Rows are returned as they are in the file (no reordering, nothing dropped); `n_non_increasing`
counts timestamps that do not increase (duplicates and steps back), for the caller to report, and
the backends' IMU stream reorders, drops and counts them; jumps in time are kept (the backends
treat them as IMU gaps). Bad files raise `InputError` naming the file and the line: too few or
ragged columns, a cell that is not a number (timestamps must be integers), NaN or infinite values.
Columns after the seventh are ignored.

`exports=True` (user IMU tables, `imu_csv.read_imu_log`) also takes what common exports write: a first
line of column names without `#` (`t_s,gx,gy,gz,ax,ay,az`, skipped) and timestamps in seconds with
decimals (kept as ns, `t_from_float_s` True, for `imu_checks` to accept or refuse by the rate).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import dataclasses

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.io.paths import is_pipe, path_kind
from uareme_fusion.io.text_tables import TextTable, read_table
from uareme_fusion.types import ImuSample

EUROC_IMU_COLUMNS = ("timestamp [ns]", "w_x [rad/s]", "w_y [rad/s]", "w_z [rad/s]",
                     "a_x [m/s^2]", "a_y [m/s^2]", "a_z [m/s^2]")


@dataclass(frozen=True)
class EurocImu:
    """IMU log: `t_ns` (N,) int64, `t_s` (N,) float s, `gyro_rad_s`, `accel_m_s2` (N, 3) in the IMU frame."""

    path: Path
    t_ns: np.ndarray
    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    t_from_float_s: bool = False
    """The file's timestamps were seconds with decimals (`exports`), rounded to `t_ns`."""

    @property
    def n_non_increasing(self) -> int:
        return int(np.sum(np.diff(self.t_ns) <= 0))

    @property
    def rate_hz(self) -> float:
        """Median sample rate."""
        return float(1e9 / np.median(np.diff(self.t_ns))) if len(self.t_ns) > 1 else float("nan")

    def samples(self) -> Iterator[ImuSample]:
        for t, g, a in zip(self.t_s, self.gyro_rad_s, self.accel_m_s2):
            yield ImuSample(float(t), g, a)


def read_euroc_imu(path: str | Path, delimiter: str | None = ",", exports: bool = False) -> EurocImu:
    """Read an EuRoC `imu0/data.csv` (`delimiter` None: whitespace-separated columns instead of
    commas; `exports`: see the module docstring); raises InputError naming the file when it is not one."""
    path = Path(path)
    if path.is_dir():
        for candidate in (path / "data.csv", path / "imu0" / "data.csv", path / "mav0" / "imu0" / "data.csv"):
            if candidate.is_file():
                path = candidate
                break
    if path.is_dir():
        raise InputError(f"EuRoC IMU file {path}: is a folder, and an IMU file inside it (data.csv, "
                         "imu0/data.csv or mav0/imu0/data.csv) does not exist")
    if not path.is_file() and not is_pipe(path):  # a pipe (FIFO, `<(cat f.csv)`) is read to its end
        kind = path_kind(path)
        raise InputError(f"EuRoC IMU file {path} " + (f"is {kind}" if kind else "does not exist"))
    table = read_table(path, EUROC_IMU_COLUMNS, delimiter=delimiter, kind="an EuRoC IMU file")
    if exports:
        table = _without_names_row(table)
    if len(table) == 0:
        raise InputError(f"{path} holds no IMU samples (only comments or blank lines)")
    t_ns, from_float_s = _timestamps_ns(table, exports)
    values = table.floats(slice(1, 7))
    table.require_finite(values, "gyro or accel value")
    return EurocImu(path, t_ns, t_ns * 1e-9, values[:, :3], values[:, 3:], from_float_s)


def _is_number(cell: str) -> bool:
    try:
        float(cell)
        return True
    except ValueError:
        return False


def _without_names_row(table: TextTable) -> TextTable:
    """`table` without its first row when no cell of it is a number (column names without `#`)."""
    if len(table) and not any(_is_number(str(cell)) for cell in table.cells[0]):
        return dataclasses.replace(table, cells=table.cells[1:], line=table.line[1:])
    return table


def _timestamps_ns(table: TextTable, float_seconds: bool) -> tuple[np.ndarray, bool]:
    """Column 1 as integer ns, or (`float_seconds`) seconds with decimals rounded to ns: (t_ns, from_float_s)."""
    try:
        return table.ints(0), False
    except InputError as not_integers:
        if not float_seconds:
            raise
        try:
            t_s = table.floats(0)
        except InputError:
            raise not_integers from None
        fits = np.isfinite(t_s).all() and np.abs(t_s).max() < np.iinfo(np.int64).max * 1e-9
        if not fits or np.all(t_s == np.rint(t_s)):  # integral or huge: not seconds with decimals
            raise not_integers from None
        return np.rint(t_s * 1e9).astype(np.int64), True
