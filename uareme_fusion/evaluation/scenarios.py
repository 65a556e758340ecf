"""Simulated scenarios for the EKF: a trajectory, its IMU and the real solver's rotation per frame,
run through one backend (`run_scenario`). The EKF benchmark (`uareme-fusion bench mekf`) and the
tests use them.

Visual rotations come from the real solver on synthetic normal maps:
`solve_manhattan(manhattan_normal_map(R_cm_true, rng, 120, 160, noise_deg, correlation_px), R_init=
backend.predicted_R_cm(t))`, so their covariance is the solver's own.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..rotations import align_yaw, are_deg, nees, tilt_error_deg, up_in_camera
from ..sim.imu import simulate_imu
from ..sim.normal_maps import manhattan_normal_map
from ..sim.trajectory import make_trajectory
from ..solver import solve_manhattan
from ..backends.factory import make_backend

VISUAL_NOISE_DEG = 8.0
VISUAL_CORRELATION_PX = 4.0


@dataclass
class RunResult:
    """Per-frame arrays of one simulated run: `R_wc_est`/`R_wc_true` (N, 3, 3), `cov` (N, 3, 3)."""

    t_s: np.ndarray
    R_wc_est: np.ndarray
    R_wc_true: np.ndarray
    cov: np.ndarray
    status: list = field(default_factory=list)
    imu: tuple = ()
    imu_time_s: float = 0.0
    visual_time_s: float = 0.0
    imu_cpu_s: float = 0.0
    visual_cpu_s: float = 0.0
    n_visual: int = 0

    @property
    def tilt_deg(self) -> np.ndarray:
        return tilt_error_deg(up_in_camera(self.R_wc_est), up_in_camera(self.R_wc_true))

    @property
    def are_deg(self) -> np.ndarray:
        return are_deg(self.R_wc_est, self.R_wc_true)

    def nees(self, yaw_fit_s: float | None = None) -> np.ndarray:
        """NEES after aligning the estimate's world to the truth with one rotation about up (the
        filter's world yaw is a gauge; its tilt is absolute), fitted over the whole run, or over the
        first `yaw_fit_s` seconds where yaw is unobservable and drifts (a turning vehicle: the
        gauge is the heading at initialisation, where its variance is 0)."""
        fit = slice(None) if yaw_fit_s is None else self.t_s < self.t_s[0] + yaw_fit_s
        A_yaw = align_yaw(self.R_wc_est[fit], self.R_wc_true[fit])
        return nees(A_yaw @ self.R_wc_est, self.R_wc_true, self.cov)


def run_scenario(
    trajectory: str,
    seed: int,
    duration_s: float,
    backend_factory,
    fps: float = 30.0,
    imu_rate_hz: float = 200.0,
    drop_fraction: float = 0.0,
    use_imu: bool = True,
) -> RunResult:
    """Simulate a trajectory, its IMU and per-frame solver outputs, and run one backend on it."""
    traj = make_trajectory(trajectory, duration_s=duration_s, seed=seed)
    t_imu, gyro, accel = simulate_imu(traj, rate_hz=imu_rate_hz, seed=seed + 1000)
    rng = np.random.default_rng(seed + 2000)
    t_frames = np.arange(0.1, duration_s - 1e-6, 1.0 / fps)
    R_wc_true = traj.sample(t_frames).R_wc
    R_cm_true = np.swapaxes(R_wc_true, -1, -2) @ traj.R_wm(t_frames)
    dropped = rng.random(t_frames.size) < drop_fraction
    backend = backend_factory()
    est_R, est_cov, status = [], [], []
    imu_time = visual_time = imu_cpu = visual_cpu = 0.0
    n_visual = 0
    k = 0
    for i, t in enumerate(t_frames):
        k_next = int(np.searchsorted(t_imu, t, side="right"))
        if use_imu and k_next > k:
            t0, c0 = time.perf_counter(), time.thread_time()
            backend.process_imu(t_imu[k:k_next], gyro[k:k_next], accel[k:k_next])
            backend.propagate_to(t) if hasattr(backend, "propagate_to") else None
            imu_time += time.perf_counter() - t0
            imu_cpu += time.thread_time() - c0
        k = k_next
        visual = None
        if not dropped[i]:
            normal_map = manhattan_normal_map(R_cm_true[i], rng, 120, 160, noise_deg=VISUAL_NOISE_DEG,
                                              correlation_px=VISUAL_CORRELATION_PX)
            visual = solve_manhattan(normal_map.normals, normal_map.kappa, R_init=backend.predicted_R_cm(t))
            n_visual += 1
        t0, c0 = time.perf_counter(), time.thread_time()
        est = backend.process_frame(t, visual)
        visual_time += time.perf_counter() - t0
        visual_cpu += time.thread_time() - c0
        est_R.append(est.R_wc)
        est_cov.append(est.cov)
        status.append(est.status)
    return RunResult(t_frames, np.array(est_R), R_wc_true, np.array(est_cov), status,
                     (t_imu, gyro, accel, traj), imu_time, visual_time, imu_cpu, visual_cpu, n_visual)


def mekf_factory(preset: str, **overrides):
    """A `backend_factory` for `run_scenario`: the EKF with `preset` and `overrides`."""
    return lambda: make_backend("mekf", mekf_preset=preset, overrides=overrides)
