"""EuRoC MAV files: IMU logs (`mav0/imu0/data.csv`, read and written) and ground truth (read).

Format: one header line starting with `#`, then `timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y,
a_z [m/s^2]` comma-separated, gyro and specific force in the IMU (sensor) frame `S`.

    imu = read_euroc_imu("mav0/imu0/data.csv")
    imu.t_s, imu.gyro_rad_s, imu.accel_m_s2        # (N,), (N, 3), (N, 3)

Times: `t_ns` keeps the file's integer nanoseconds exactly; `t_s = t_ns * 1e-9` as float seconds.
Rows are returned as they are in the file (no reordering, nothing dropped); `n_non_increasing`
counts timestamps that do not increase (duplicates and steps back), for the caller to report, and
the backends' IMU stream reorders, drops and counts them; jumps in time are kept (the backends
treat them as IMU gaps). Bad files raise `InputError` naming the file and the line: too few or
ragged columns, a cell that is not a number (timestamps must be integers), NaN or infinite values.
Columns after the seventh are ignored. `euroc_imu_text` writes rows (integer ns, values in `value_fmt`)
after `EUROC_IMU_HEADER`. Ground truth (`state_groundtruth_estimate0/data.csv`, `timestamp [ns], p,
q_w q_x q_y q_z`) is read by `read_euroc_ground_truth` as `R_RS` (IMU body to the gravity-aligned world).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from ..io.paths import is_pipe, path_kind
from ..io.safe_files import write_text_atomic
from ..io.text_tables import TextTable, read_table

EUROC_IMU_COLUMNS = ("timestamp [ns]", "w_x [rad/s]", "w_y [rad/s]", "w_z [rad/s]",
                     "a_x [m/s^2]", "a_y [m/s^2]", "a_z [m/s^2]")

EUROC_IMU_HEADER = ("#timestamp [ns],w_RS_S_x [rad s^-1],w_RS_S_y [rad s^-1],w_RS_S_z [rad s^-1],"
                    "a_RS_S_x [m s^-2],a_RS_S_y [m s^-2],a_RS_S_z [m s^-2]")
EUROC_GT_COLUMNS = ("timestamp [ns]", "p_x [m]", "p_y [m]", "p_z [m]", "q_w", "q_x", "q_y", "q_z")


def euroc_imu_text(t_s: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, value_fmt: str = ".17g") -> str:
    """IMU rows `t_ns,wx,wy,wz,ax,ay,az` (no header): t_s (N,) s rounded to integer ns, (N, 3) values."""
    t_ns = np.rint(np.asarray(t_s, np.float64) * 1e9).astype(np.int64)
    rows = np.column_stack([gyro_rad_s, accel_m_s2])
    return "".join(f"{t}," + ",".join(format(float(v), value_fmt) for v in row) + "\n" for t, row in zip(t_ns, rows))


def write_euroc_imu(path: Path, t_s: np.ndarray, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray,
                    value_fmt: str = ".10f") -> None:
    """A whole EuRoC `imu0/data.csv` (header and rows), written atomically."""
    write_text_atomic(Path(path), EUROC_IMU_HEADER + "\n" + euroc_imu_text(t_s, gyro_rad_s, accel_m_s2, value_fmt))


def read_euroc_ground_truth(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """An EuRoC ground-truth CSV -> (t_s (N,), R_RS (N, 3, 3): body (IMU) to the gravity-aligned world)."""
    table = read_table(path, EUROC_GT_COLUMNS, delimiter=",", kind="an EuRoC ground-truth file")
    if len(table) == 0:
        raise InputError(f"{path}: holds no ground-truth rows")
    t_ns = table.ints(0)
    table.require_increasing(t_ns)
    quat_wxyz = table.floats(slice(4, 8))
    table.require_finite(quat_wxyz, "quaternion")
    return t_ns * 1e-9, Rotation.from_quat(quat_wxyz, scalar_first=True).as_matrix()


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


def read_euroc_imu(path: str | Path, delimiter: str | None = ",", exports: bool = False) -> EurocImu:
    """Read an EuRoC `imu0/data.csv` (`delimiter` None: whitespace-separated columns instead of
    commas); raises InputError naming the file when it is not one. `exports=True` (user IMU tables,
    `drivers.imu_csv.read_imu_log`) also takes what common exports write: a first line of column
    names without `#` (`t_s,gx,gy,gz,ax,ay,az`, skipped) and timestamps in seconds with decimals
    (kept as ns, `t_from_float_s` True, for `drivers.imu_checks` to accept or refuse by the rate)."""
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


ACCELEROMETER_COLUMNS = ("timestamp [ns]", "a_x [m s^-2]", "a_y [m s^-2]", "a_z [m s^-2]")
"""An accelerometer log without gyro: the EuRoC columns less the gyro's."""


def read_accelerometer_table(path: str | Path, delimiter: str | None = ",") -> tuple[np.ndarray, np.ndarray] | None:
    """An IMU table of exactly 4 columns (`ACCELEROMETER_COLUMNS`: an accelerometer without gyro; the
    timestamps and a line of names as `read_euroc_imu(exports=True)` takes them) as `(t_s (N,),
    accel_m_s2 (N, 3))`; None for a table of any other width (or no table: `read_euroc_imu` says why)."""
    try:
        with open(path, encoding="utf-8-sig") as fh:
            first = next((line for line in fh if line.strip() and not line.lstrip().startswith("#")), "")
    except (OSError, UnicodeDecodeError):
        return None
    if len(first.split(delimiter)) != len(ACCELEROMETER_COLUMNS):
        return None
    table = _without_names_row(read_table(path, ACCELEROMETER_COLUMNS, delimiter=delimiter,
                                          kind="an accelerometer log"))
    if len(table) == 0:
        raise InputError(f"{path} holds no accelerometer samples (only comments or blank lines)")
    t_ns, _ = _timestamps_ns(table, True)
    values = table.floats(slice(1, 4))
    table.require_finite(values, "accel value")
    return t_ns * 1e-9, values


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
