"""Shared test fixtures, and the compiled kernels built once before xdist's workers start."""

from pathlib import Path

import numpy as np
import pytest

from helpers import shared_data_or_skip


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """`../shared/data` beside the repository; skips the test when it is absent."""
    return shared_data_or_skip()


def pytest_configure(config):
    """In the process that starts xdist's workers (pyproject's addopts: `-n auto`), compile the numba
    kernels into their on-disk cache before the workers start. On a fresh checkout every worker would
    otherwise compile the EKF kernels (20-40 s of one core: 42 s measured on a busy 2-core machine) at
    the same time; with the cache written, each worker loads them in a fraction of a second."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return  # a worker, or a run in one process: that process compiles on first use anyway
    warm_compiled_kernels()


def warm_compiled_kernels() -> None:
    """Call each compiled kernel once with the argument types the package uses (numba's cache keys):
    the EKF's batch, segment and accelerometer-update kernels, and the float32/float64 normal moments."""
    from uareme_fusion.backends.mekf import Mekf, MekfConfig
    from uareme_fusion.solver.moments import fused_moments

    for dtype in (np.float32, np.float64):
        fused_moments(np.ones((4, 3), dtype), np.ones(4, dtype))
    t = np.arange(0.0, 1.0, 0.005)
    gyro, accel = np.zeros((t.size, 3)), np.tile([0.0, 0.0, 9.81], (t.size, 1))
    batches = Mekf(MekfConfig())  # IMU batches between frames: the batch and the update kernels
    batches.process_imu(t, gyro, accel)
    batches.process_frame(1.0, None)
    segments = Mekf(MekfConfig(mode="imu_only"))  # an IMU-only stream in bulk: the segment kernel
    segments.process_imu_segments(t, gyro, accel, np.arange(10, t.size + 1, 10))
