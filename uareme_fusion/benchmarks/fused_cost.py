"""What issue 17's fused figure counts: the filter's cost per IMU sample in a run with frames,
excluding the visual update, and the warm-up that keeps compilation out of it.

"Excluding the visual update" leaves in everything else the filter does for a frame: propagation to
the frame time, the accelerometer (and at-rest) updates that fall due there, status flags and the
returned `Estimate`. `run_scenario` times `process_imu` + `propagate_to` (its IMU time) and
`process_frame` (its frame time); the frame time holds the visual update and, around it, the rest.
`VisualUpdateTimedMekf` measures the visual update proper so that it can be taken out:
`Mekf._visual_update`, which is handed the accelerometer rows it stacks into the same Kalman update
(`Mekf._take_accel_rows`, before it: the accelerometer update's cost, which the figure counts). On
the compiled path those rows are mostly computed before the frame, in the call that propagates to it
(`propagate_to`, counted), when the update falls due there; the frame then only takes them.
The clock is part of what is measured: a read of the thread's CPU time is a system call, about 3 us
of CPU time when a solver ran before it, so about 0.5-1 us per IMU sample of the 30 fps figure is
the timing's own (a backend that does nothing, timed the same way, measured 1.2-1.4 us per sample
on the 2-core machine shared by four other jobs).
"""

from __future__ import annotations

import time

import numpy as np

from ..backends.mekf import Mekf, MekfConfig
from ..config import load_config
from ..evaluation.scenarios import RunResult
from ..types import VisualRotation


class VisualUpdateTimedMekf(Mekf):
    """`Mekf` that adds up the CPU and wall time (s) of its visual updates proper in
    `visual_update_cpu_s` / `visual_update_wall_s` (see the module docstring)."""

    def __init__(self, config: MekfConfig):
        super().__init__(config)
        self.visual_update_cpu_s = self.visual_update_wall_s = 0.0

    def _visual_update(self, visual: VisualRotation, accel_rows) -> None:
        t0, c0 = time.perf_counter(), time.thread_time()
        super()._visual_update(visual, accel_rows)
        self.visual_update_cpu_s += time.thread_time() - c0
        self.visual_update_wall_s += time.perf_counter() - t0


def timed_mekf_factory(preset: str, made: list):
    """A `run_scenario` backend factory: a `VisualUpdateTimedMekf` with `preset`, appended to `made`."""
    config = load_config(preset, MekfConfig)

    def factory() -> VisualUpdateTimedMekf:
        made.append(VisualUpdateTimedMekf(config))
        return made[-1]
    return factory


def fused_cost_us(res: RunResult, filt: VisualUpdateTimedMekf) -> tuple[float, float]:
    """(CPU, wall) us per IMU sample of `filt` in the run `res`, excluding its visual updates."""
    n = res.imu[0].size
    cpu = res.imu_cpu_s + res.visual_cpu_s - filt.visual_update_cpu_s
    wall = res.imu_time_s + res.visual_time_s - filt.visual_update_wall_s
    return 1e6 * cpu / n, 1e6 * wall / n


def warm_fused_path(preset: str = "handheld") -> None:
    """Run every compiled kernel a fused run takes (numba loads or compiles them at their first call)
    on one second of a camera at rest with frames, so that no timed run pays for it."""
    filt = Mekf(preset)
    R_cm = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    visual = VisualRotation(R_cm, 1e-4 * np.eye(3), cost=0.0, iterations=1, n_valid=1000)
    t_imu = np.arange(1, 401) / 200.0
    gyro, accel = np.zeros((t_imu.size, 3)), np.tile([0.0, -9.81, 0.0], (t_imu.size, 1))
    for k, t_frame in enumerate(np.arange(1, 60) / 30.0):
        batch = (t_imu > t_frame - 1 / 30.0) & (t_imu <= t_frame)
        filt.process_imu(t_imu[batch], gyro[batch], accel[batch])
        filt.process_frame(t_frame, visual if k % 5 else None)
