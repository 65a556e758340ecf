"""What issue 17's fused figure counts: the filter's cost per IMU sample in a run with frames, without
and with the visual update, measured on a replay of a simulated run.

A fused run is recorded as `run_scenario` drives it (`RecordingMekf`: its IMU batches, frame times
and the solver's visual rotations), then replayed through a fresh filter as a pipeline drives one:
`process_imu` and `propagate_to` (the prediction the solver starts from), then `process_frame`.
Two ways: in a loop, the library's calls alone one after the other (how issue 17 measured the
library's cost with 1/30 s batches); and between solver calls, the solver run on a normal map
before each of those two timed blocks, as in a run, so that the filter finds the caches as a run
leaves them (about 2.5x the loop's cost: after a solver call each Python step, numpy call and numba
call of the filter costs several times what it costs warm).
Each block is timed with `time.perf_counter_ns` (tens of nanoseconds a read; the thread's CPU-time
clock is a system call that costs about a microsecond after a solver call, as much as the filter).
`Mekf._fuse_visual` (the visual update proper: on the compiled path one call that stacks a due
accelerometer update in and writes the estimate) is timed inside and taken out of the issue's
figure; the figure with it is given beside. Propagation, the accelerometer updates that fall due
between frames or at a frame without a rotation, checks, flags and the returned `Estimate` count;
an accelerometer update that falls due at a frame with a rotation rides in that frame's visual
update and is taken out with it. Wall time on a shared machine: the median of a few replays.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..backends.mekf import Mekf, MekfConfig
from ..config import load_config
from ..evaluation.scenarios import VISUAL_CORRELATION_PX, VISUAL_NOISE_DEG
from ..sim.normal_maps import manhattan_normal_map
from ..solver import solve_manhattan
from ..types import NormalMap, VisualRotation


@dataclass
class FusedInputs:
    """What a fused run fed its filter, frame by frame: `(t_frame_s, (t_s, gyro, accel) or None,
    VisualRotation or None)`, and the number of IMU samples."""

    frames: list = field(default_factory=list)
    n_imu: int = 0


class RecordingMekf(Mekf):
    """`Mekf` that records what it is fed into `inputs` (a `FusedInputs`), for `replay_cost_us`."""

    def __init__(self, config: MekfConfig):
        super().__init__(config)
        self.inputs = FusedInputs()
        self._batch = None

    def process_imu(self, t_s, gyro_rad_s, accel_m_s2) -> None:
        self._batch = (np.array(t_s, float), np.array(gyro_rad_s, float), np.array(accel_m_s2, float))
        self.inputs.n_imu += self._batch[0].size
        super().process_imu(t_s, gyro_rad_s, accel_m_s2)

    def process_frame(self, t_s: float, visual: VisualRotation | None):
        self.inputs.frames.append((float(t_s), self._batch, visual))
        self._batch = None
        return super().process_frame(t_s, visual)


def recording_mekf_factory(preset: str, made: list):
    """A `run_scenario` backend factory: a `RecordingMekf` with `preset`, appended to `made`."""
    config = load_config(preset, MekfConfig)

    def factory() -> RecordingMekf:
        made.append(RecordingMekf(config))
        return made[-1]
    return factory


class VisualUpdateTimedMekf(Mekf):
    """`Mekf` that adds up the wall time (ns) of its visual updates proper (`_fuse_visual`) in
    `visual_update_ns`."""

    def __init__(self, config: MekfConfig):
        super().__init__(config)
        self.visual_update_ns = 0

    def _fuse_visual(self, visual: VisualRotation) -> bool:
        t0 = time.perf_counter_ns()
        wrote_estimate = super()._fuse_visual(visual)
        self.visual_update_ns += time.perf_counter_ns() - t0
        return wrote_estimate


def replay_cost_us(inputs: FusedInputs, config: MekfConfig, normal_map: NormalMap | None) -> tuple[float, float]:
    """One replay of `inputs` through a fresh filter with `config`, the solver run on `normal_map`
    before each timed block, or nothing between them when None (see the module docstring): `(us
    per IMU sample without the visual update, with it)`."""
    filt = VisualUpdateTimedMekf(config)
    clock = time.perf_counter_ns
    total_ns = 0
    for t_frame, batch, visual in inputs.frames:
        if normal_map is not None:
            solve_manhattan(normal_map.normals, normal_map.kappa)  # what ran before the frame's samples
        t0 = clock()
        if batch is not None:
            filt.process_imu(*batch)
        filt.propagate_to(t_frame)
        total_ns += clock() - t0
        if normal_map is not None:
            solve_manhattan(normal_map.normals, normal_map.kappa, R_init=filt.predicted_R_cm(t_frame))
        t0 = clock()
        filt.process_frame(t_frame, visual)
        total_ns += clock() - t0
    n = max(inputs.n_imu, 1)
    return 1e-3 * (total_ns - filt.visual_update_ns) / n, 1e-3 * total_ns / n


REPLAYS = ("loop", "between_solver")
"""The two ways `fused_cost_us` replays a run (see the module docstring)."""


def fused_cost_us(inputs: FusedInputs, config: MekfConfig, repeats: int = 3) -> dict[str, tuple[float, float]]:
    """{way of `REPLAYS`: medians over `repeats` replays of `replay_cost_us`}, the two ways alternated."""
    normal_map = manhattan_normal_map(np.eye(3), np.random.default_rng(0), 120, 160, noise_deg=VISUAL_NOISE_DEG,
                                      correlation_px=VISUAL_CORRELATION_PX)
    between = {"loop": None, "between_solver": normal_map}  # what runs between the timed blocks
    costs = np.array([[replay_cost_us(inputs, config, between[way]) for way in REPLAYS]
                      for _ in range(repeats)])  # (repeats, way, without / with)
    medians = np.median(costs, axis=0)
    return {way: (float(medians[k, 0]), float(medians[k, 1])) for k, way in enumerate(REPLAYS)}
