"""What the simulator makes: `SequenceOptions` (frames, size, rates, seed, IMU noise and geometry)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..rotations import is_rotation
from .imu import ImuNoise

MAX_PIXELS = 4096 * 4096
MAX_TIME_OFFSET_S = 1.0
"""Largest IMU-camera clock offset the simulator writes, s."""


@dataclass(frozen=True)
class SequenceOptions:
    """How much to simulate and how; units in the names."""

    frames: int = 100
    width: int = 320
    height: int = 240
    fps: float = 30.0
    seed: int = 0
    imu_rate_hz: float = 200.0
    hfov_deg: float | None = None
    """Horizontal field of view; None takes the scenario's."""
    imu_noise: ImuNoise = field(default_factory=ImuNoise)
    R_ci: tuple = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    """Camera-from-IMU rotation (`v_c = R_ci @ v_i`)."""
    imu_time_offset_s: float = 0.0
    """Camera clock minus IMU clock, s: `t_cam = t_imu + imu_time_offset_s` (see `imu.simulate_imu`)."""

    def validate(self) -> None:
        """Raise InputError naming the option for impossible values."""
        # --fps first: a live sim source derives its frame count from it (`sim:room --fps 1e9`)
        if not 1.0 <= self.fps <= 1000.0:
            raise InputError(f"--fps must be between 1 and 1000, got {self.fps}")
        if self.frames < 1 or self.frames > 1_000_000:
            raise InputError(f"--frames must be between 1 and 1000000, got {self.frames}")
        if self.width < 8 or self.height < 8 or self.width * self.height > MAX_PIXELS:
            raise InputError(f"--size must be at least 8x8 and at most 4096x4096 pixels, got "
                             f"{self.width}x{self.height}")
        if not 100.0 <= self.imu_rate_hz <= 1000.0:
            raise InputError(f"--imu-rate must be between 100 and 1000 Hz, got {self.imu_rate_hz}")
        if self.hfov_deg is not None and not 45.0 <= self.hfov_deg <= 95.0:
            raise InputError(f"--fov-deg must be between 45 and 95 degrees, got {self.hfov_deg}")
        if not 0 <= self.seed < 2**63:
            raise InputError(f"--seed must be an integer >= 0, got {self.seed}")
        if not abs(self.imu_time_offset_s) <= MAX_TIME_OFFSET_S:
            raise InputError(f"imu_time_offset_s must be within +-{MAX_TIME_OFFSET_S:g} s, got {self.imu_time_offset_s}")
        if np.shape(self.R_ci) != (3, 3) or not is_rotation(self.R_ci):
            raise InputError(f"R_ci must be a 3x3 rotation matrix (orthonormal, det +1), got {self.R_ci}")
        noise = self.imu_noise.as_dict()
        bad = [k for k, v in noise.items() if not np.all(np.isfinite(v)) or (np.ndim(v) == 0 and v < 0)
               or np.shape(v) not in ((), (3,))]
        if bad:
            raise InputError(f"imu_noise: {', '.join(bad)} must be finite (densities >= 0, biases 3-vectors)")
