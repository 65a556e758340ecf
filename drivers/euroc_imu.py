"""Reader for EuRoC MAV IMU files (`mav0/imu0/data.csv`), as recorded and as the simulator writes.

Format: one header line starting with `#`, then `timestamp [ns], w_x, w_y, w_z [rad/s], a_x, a_y,
a_z [m/s^2]` comma-separated, gyro and specific force in the IMU (sensor) frame `S`.

    imu = read_euroc_imu("mav0/imu0/data.csv")
    imu.t_s, imu.gyro_rad_s, imu.accel_m_s2        # (N,), (N, 3), (N, 3)
    for sample in imu.samples(): ...               # uareme_fusion.types.ImuSample

Times: `t_ns` keeps the file's integer nanoseconds exactly; `t_s = t_ns * 1e-9` as float seconds.
Rows are returned as they are in the file (no reordering, nothing dropped); `n_non_increasing`
counts timestamps that do not increase, for the caller to report.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.types import ImuSample


@dataclass(frozen=True)
class EurocImu:
    """IMU log: `t_ns` (N,) int64, `t_s` (N,) float s, `gyro_rad_s`, `accel_m_s2` (N, 3) in the IMU frame."""

    path: Path
    t_ns: np.ndarray
    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray

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


def read_euroc_imu(path: str | Path) -> EurocImu:
    """Read an EuRoC `imu0/data.csv`; raises InputError naming the file when it is not one."""
    path = Path(path)
    if path.is_dir():
        for candidate in (path / "data.csv", path / "imu0" / "data.csv", path / "mav0" / "imu0" / "data.csv"):
            if candidate.is_file():
                path = candidate
                break
    if not path.is_file():
        raise InputError(f"EuRoC IMU file {path} does not exist")
    try:
        t_ns = np.loadtxt(path, delimiter=",", comments="#", usecols=0, dtype=np.int64, ndmin=1)
        values = np.loadtxt(path, delimiter=",", comments="#", usecols=range(1, 7), dtype=float, ndmin=2)
    except (ValueError, IndexError) as exc:
        raise InputError(f"{path} is not an EuRoC IMU file (expected 7 comma-separated columns: "
                         f"timestamp [ns], gyro xyz [rad/s], accel xyz [m/s^2]): {exc}") from None
    if len(t_ns) == 0:
        raise InputError(f"{path} holds no IMU samples")
    if not np.all(np.isfinite(values)):
        bad = int(np.sum(~np.isfinite(values).all(axis=1)))
        raise InputError(f"{path}: {bad} rows hold non-finite gyro or accel values")
    return EurocImu(path, t_ns, t_ns * 1e-9, values[:, :3], values[:, 3:])
