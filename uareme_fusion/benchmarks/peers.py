"""IMU-only orientation filters from other projects, run the same way wherever we compare with them."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def vqf_6d_R_wi(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, dt_s: float) -> np.ndarray:
    """vqf's 6D (gyro + accelerometer) orientation per sample: `R_wi` (N, 3, 3), IMU to a z-up world
    whose yaw is vqf's own. Raises ImportError when vqf (the `bench` extra) is not installed."""
    from vqf import VQF

    quat_wxyz = VQF(dt_s).updateBatch(np.ascontiguousarray(gyro_rad_s), np.ascontiguousarray(accel_m_s2))["quat6D"]
    return Rotation.from_quat(quat_wxyz, scalar_first=True).as_matrix()
