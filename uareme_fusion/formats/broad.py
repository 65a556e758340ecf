"""Reader for BROAD trials (Laidig et al., Data 2021, CC BY 4.0): IMU data with optical reference.

File layout (HDF5): `imu_gyr` (N, 3) rad/s, `imu_acc` (N, 3) m/s^2, `imu_mag` (N, 3) uT, `opt_quat`
(N, 4) unit quaternion in order w x y z (NaN where the optical system lost the markers), `movement`
(N,) bool marking the samples to score, attribute `sampling_rate` in Hz.

Conventions: `R_ref_imu` (N, 3, 3) maps IMU coordinates to the ENU reference frame (z up), i.e. it
plays the role of `R_wi`; rows with a NaN quaternion are NaN (the optical system lost the markers).
Missing datasets, wrong shapes, a bad sampling rate and NaN/Inf IMU samples raise `InputError`
naming the file and the dataset.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError

REQUIRED_DATASETS = ("imu_gyr", "imu_acc", "opt_quat", "movement")


@dataclass(frozen=True)
class BroadTrial:
    """One BROAD trial; times `t_s` (N,) = sample index / sampling rate, seconds."""

    name: str
    t_s: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    quat_wxyz: np.ndarray
    movement: np.ndarray
    sampling_rate_hz: float

    @property
    def R_ref_imu(self) -> np.ndarray:
        """(N, 3, 3) IMU-to-ENU rotations from the optical reference; NaN where it is missing."""
        ok = np.all(np.isfinite(self.quat_wxyz), axis=1)
        R = np.full((self.quat_wxyz.shape[0], 3, 3), np.nan)
        R[ok] = Rotation.from_quat(self.quat_wxyz[ok], scalar_first=True).as_matrix()
        return R


def _numeric(path: Path, f, key: str) -> np.ndarray:
    try:
        return np.asarray(f[key], float)
    except (TypeError, ValueError, OSError):  # h5py: OSError when it has no conversion to float
        raise InputError(f"BROAD file {path}: {key} is not numeric (dtype {f[key].dtype})") from None


def read_broad(path: str | Path) -> BroadTrial:
    """Read one BROAD `.hdf5` trial; `InputError` naming the file if it is unreadable or incomplete."""
    import h5py

    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except (OSError, ValueError) as exc:
        raise InputError(f"Cannot read BROAD file {path}: {exc}") from None
    with f:
        missing = [k for k in REQUIRED_DATASETS if k not in f]
        if missing or "sampling_rate" not in f.attrs:
            what = ", ".join(missing + ([] if "sampling_rate" in f.attrs else ["attribute sampling_rate"]))
            raise InputError(f"BROAD file {path} lacks {what}")
        gyro, accel, quat = (_numeric(path, f, key) for key in ("imu_gyr", "imu_acc", "opt_quat"))
        movement = np.asarray(f["movement"], bool)
        try:
            rate = float(np.asarray(f.attrs["sampling_rate"]).reshape(-1)[0])
        except (TypeError, ValueError, IndexError):
            raise InputError(f"BROAD file {path}: sampling_rate must be a number of Hz, got "
                             f"{f.attrs['sampling_rate']!r}") from None
    n = gyro.shape[0] if gyro.ndim else 0
    if gyro.shape != (n, 3) or accel.shape != (n, 3) or quat.shape != (n, 4) or movement.shape != (n,):
        raise InputError(
            f"BROAD file {path}: expected imu_gyr/imu_acc (N, 3), opt_quat (N, 4), movement (N,); got "
            f"{gyro.shape}, {accel.shape}, {quat.shape}, {movement.shape}"
        )
    if not (np.isfinite(rate) and rate > 0):
        raise InputError(f"BROAD file {path}: sampling_rate must be positive, got {rate}")
    for key, values in (("imu_gyr", gyro), ("imu_acc", accel)):
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            raise InputError(f"BROAD file {path}: {key} holds NaN or infinite values in {int(bad.sum())} row(s) "
                             f"(first: sample {int(np.flatnonzero(bad)[0])})")
    return BroadTrial(path.stem, np.arange(n) / rate, gyro, accel, quat, movement, rate)
