"""The input of a backend comparison: per-frame visual rotations with the IMU and the ground truth.

`VisualSequence` is built once per sequence (the solver runs once), then every backend runs on it
(`compare.compare`). Built here in memory from the simulator (`synthetic_sequence`); from a dataset
folder or any source in `source_sequence`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..sim.normal_maps import manhattan_normal_map
from ..types import NormalMap, VisualRotation


@dataclass(frozen=True)
class VisualSequence:
    """Per-frame visual rotations with the IMU samples and the ground truth when known.

    `t_frame_s` (N,) seconds; `visuals` N entries, None where a frame gave no visual rotation;
    IMU arrays `imu_t_s` (M,), `imu_gyro_rad_s` (M, 3), `imu_accel_m_s2` (M, 3) in the IMU frame,
    or None; `R_wc_true` (N, 3, 3) camera-to-world ground truth (world z up) or None.
    """

    name: str
    t_frame_s: np.ndarray
    visuals: list
    imu_t_s: np.ndarray | None = None
    imu_gyro_rad_s: np.ndarray | None = None
    imu_accel_m_s2: np.ndarray | None = None
    R_wc_true: np.ndarray | None = None
    notes: list = field(default_factory=list)

    @property
    def has_imu(self) -> bool:
        return self.imu_t_s is not None and len(self.imu_t_s) > 0


class ChainedSolver:
    """Solves frames in order, each solve initialised from the previous solution; `invalid` counts
    the frames without a usable cue (they give no visual rotation). With `cues` (a
    `solver.cues.CueSolver`) a frame's normals and line segments are solved together, as in `run`;
    without, its normal map alone."""

    def __init__(self, cues=None):
        self.R_prev, self.invalid, self.cues = None, 0, cues

    def solve(self, normal_map: NormalMap | None, frame=None) -> VisualRotation | None:
        from ..solver.cues import solve_frame

        if normal_map is None and (self.cues is None or frame is None):
            return None  # no map to solve: not counted as invalid
        visual = solve_frame(self.cues, frame, normal_map, self.R_prev)
        if visual is None:  # no valid normals nor segments: the frame gives no visual rotation
            self.invalid += 1
            return None
        self.R_prev = visual.R_cm
        return visual


def solve_frames(normal_maps: list) -> tuple[list, int]:
    """Visual rotations for a list of `NormalMap`s (None entries stay None), each solve initialised
    from the previous solution; returns them and the number of maps without valid normals."""
    solver = ChainedSolver()
    return [solver.solve(nm) for nm in normal_maps], solver.invalid


def synthetic_sequence(
    scenario: str = "walk",
    seed: int = 0,
    duration_s: float = 20.0,
    fps: float = 15.0,
    drop_fraction: float = 0.1,
    bad_fraction: float = 0.05,
    noise_deg: float = 10.0,
    correlation_px: float = 4.0,
    imu_rate_hz: float = 200.0,
    height: int = 120,
    width: int = 160,
) -> VisualSequence:
    """A sequence built in memory from the simulator's trajectory `scenario` and IMU, with normal
    maps from `manhattan_normal_map` at the true `R_cm = R_wc^T R_wm`.

    A `drop_fraction` of frames (never the first) gives no visual rotation; a `bad_fraction` has
    only random normals (a blank wall or black frame: the solver returns an arbitrary rotation).
    """
    from ..sim.imu import simulate_imu
    from ..sim.trajectory import make_trajectory

    if not (0 <= drop_fraction < 1 and 0 <= bad_fraction < 1 and drop_fraction + bad_fraction < 1):
        raise InputError(f"drop_fraction + bad_fraction must be in [0, 1), got {drop_fraction} + {bad_fraction}")
    if not fps > 0:
        raise InputError(f"fps must be > 0, got {fps}")
    traj = make_trajectory(scenario, duration_s, seed=seed)
    rng = np.random.default_rng(seed + 7919)
    t_frame = np.arange(0.0, duration_s, 1.0 / fps)
    R_wc_true = traj.sample(t_frame).R_wc
    R_cm_true = traj.R_cm(t_frame)
    kinds = rng.choice(3, size=len(t_frame), p=[1 - drop_fraction - bad_fraction, drop_fraction, bad_fraction])
    kinds[0] = 0
    maps = []
    for k, kind in enumerate(kinds):
        if kind == 1:
            maps.append(None)
            continue
        nm = manhattan_normal_map(R_cm_true[k], rng, height, width, noise_deg=noise_deg, correlation_px=correlation_px)
        if kind == 2:
            random = rng.standard_normal(nm.normals.shape)
            nm = type(nm)(normals=(random / np.linalg.norm(random, axis=-1, keepdims=True)).astype(np.float32),
                          kappa=nm.kappa)
        maps.append(nm)
    visuals, _ = solve_frames(maps)
    imu_t, gyro, accel = simulate_imu(traj, rate_hz=imu_rate_hz, seed=seed)
    notes = [f"synthetic '{scenario}' seed {seed}: {len(t_frame)} frames at {fps:g} fps, "
             f"{int(np.sum(kinds == 1))} dropped, {int(np.sum(kinds == 2))} with random normals"]
    return VisualSequence(f"{scenario} (seed {seed})", t_frame, visuals, imu_t, gyro, accel, R_wc_true, notes)
