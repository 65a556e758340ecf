"""The simulator as a live source: `sim:room`, `sim:bus`, ... rendered frame by frame.

    with SimulatedSource("bus", seconds=20, fps=30, width=320, height=240, seed=0) as src: ...
    with SimulatedSource("room", seconds=3600, render=False) as src: ...   # soak runs: normals only

Each frame carries exact normals (`Frame.normals`, kappa `GT_KAPPA` where a surface was hit), the
IMU (gyro + accelerometer from `sim.imu.simulate_imu`, `ImuNoise` defaults) comes between frames, and
`ground_truth()` gives `R_wc` at the frame times in the gravity-aligned world (z up).

- `render=True`: ray-cast RGB + depth + normals at `width` x `height` (default 320 x 240), with the
  scenario's sensor noise, exposure changes, motion blur and dropped (black) frames as in `simulate`
  (a dropped frame's normals have kappa 0). Cost: the renderer's, tens of ms per frame.
- `render=False`: no image (`rgb` None, no depth); normals from `sim.normal_maps.manhattan_normal_map`
  of the true `R_cm` at `width` x `height` (default 64 x 48), `normals_noise_deg` of angular noise
  (default 0: exact). About 1 ms per frame, for hour-long accelerated soak runs.

Memory stays bounded whatever `seconds` is: frames, their poses and the IMU are made in chunks of
`CHUNK_S` seconds (the IMU bias random walk carries over between chunks). Times: frame i at
`i / fps` s; IMU samples at `k / imu_rate_hz` s on the same clock (no offset); `R_ci` identity unless
given (`v_c = R_ci v_i`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np

from uareme_fusion.errors import InputError
from uareme_fusion.formats.datasets import GT_KAPPA
from uareme_fusion.sim.imu import ImuNoise, simulate_imu
from uareme_fusion.sim.normal_maps import manhattan_normal_map
from uareme_fusion.sim.options import SequenceOptions
from uareme_fusion.sim.render import Renderer, intrinsics_from_fov
from uareme_fusion.sim.scenarios import SCENARIOS, build_scenario
from uareme_fusion.sim.trajectory import Trajectory, make_trajectory
from uareme_fusion.types import Frame, ImuBatch, NormalMap

from .base import GroundTruth, Source, SourceInfo
from .interleave import interleave

CHUNK_S = 2.0
"""Seconds of trajectory, IMU and frame poses made at once."""
RENDER_SIZE = (320, 240)
NORMALS_ONLY_SIZE = (64, 48)
EXPOSURE_STEP = 0.08
"""Per-frame std of the log exposure gain's random walk (scenarios with exposure changes)."""
BLUR_SUBFRAMES = 5


@dataclasses.dataclass(frozen=True)
class _ShiftedTrajectory:
    """`traj` seen from `t0_s` for `duration_s` (what `simulate_imu` needs of a trajectory)."""

    traj: Trajectory
    t0_s: float
    duration_s: float

    def sample(self, t_s):
        return self.traj.sample(np.asarray(t_s, float) + self.t0_s)


class SimulatedSource(Source):
    """A simulated scenario streamed live; see the module docstring."""

    def __init__(self, scenario: str, seconds: float = 10.0, fps: float = 30.0, width: int | None = None,
                 height: int | None = None, seed: int = 0, render: bool = True, imu: bool = True,
                 imu_rate_hz: float = 200.0, imu_noise: ImuNoise | None = None, hfov_deg: float | None = None,
                 normals_noise_deg: float = 0.0, R_ci=None):
        if scenario not in SCENARIOS:
            raise InputError(f"sim:{scenario}: unknown scenario; valid: {', '.join(SCENARIOS)}")
        if not (np.isfinite(seconds) and seconds > 0):
            raise InputError(f"sim seconds must be > 0, got {seconds}")
        if not (np.isfinite(normals_noise_deg) and 0 <= normals_noise_deg <= 90):
            raise InputError(f"sim normals_noise_deg must be within [0, 90], got {normals_noise_deg}")
        default_w, default_h = RENDER_SIZE if render else NORMALS_ONLY_SIZE
        n_frames = max(1, int(round(seconds * fps))) if np.isfinite(fps) and fps > 0 else 0
        self.options = SequenceOptions(frames=n_frames, width=int(width or default_w), height=int(height or default_h),
                                       fps=float(fps), seed=int(seed), imu_rate_hz=float(imu_rate_hz),
                                       hfov_deg=hfov_deg)
        self.options.validate()
        self.scenario, self.spec, self.render = scenario, SCENARIOS[scenario], bool(render)
        self.use_imu = bool(imu)
        self.imu_noise = ImuNoise() if imu_noise is None else imu_noise
        self.normals_noise_deg = float(normals_noise_deg)
        self.R_ci = np.eye(3) if R_ci is None else np.asarray(R_ci, float)
        self.duration_s = (n_frames - 1) / fps if n_frames > 1 else 1.0 / fps
        o = self.options
        self.K = intrinsics_from_fov(o.width, o.height, self.spec.hfov_deg if hfov_deg is None else hfov_deg)
        if self.render:
            self.world = build_scenario(scenario, self.duration_s, o.seed)
            self.trajectory = self.world.trajectory
        else:  # the same trajectory build_scenario makes, without building the scene
            self.world = None
            self.trajectory = make_trajectory(self.spec.trajectory, self.duration_s, o.seed,
                                              **self.spec.trajectory_params)
        self.notes: list[str] = []
        """What was left out or not used, for the run summary."""
        self.info = SourceInfo(name=f"sim:{scenario}", n_frames=n_frames, fps=o.fps, K=self.K.copy(),
                               K_origin="simulator camera", has_depth=self.render, has_imu=self.use_imu, R_ci=self.R_ci.copy(),
                               image_size=(o.height, o.width), platform=SCENARIOS[scenario].platform,
                               depth_rendered=True)

    # ----- frames -------------------------------------------------------------------------------
    def _chunks(self, n: int, per_chunk: int) -> Iterator[tuple[int, int]]:
        for start in range(0, n, per_chunk):
            yield start, min(n, start + per_chunk)

    def _frames(self) -> Iterator[Frame]:
        o = self.options
        per_chunk = max(1, int(round(CHUNK_S * o.fps)))
        if self.render:
            yield from self._rendered_frames()
            return
        rng = np.random.default_rng([o.seed, 11])
        for a, b in self._chunks(o.frames, per_chunk):
            t = np.arange(a, b) / o.fps
            R_cm = self.trajectory.R_cm(t)
            for i, (ti, R) in enumerate(zip(t, R_cm)):
                nm = manhattan_normal_map(R, rng, o.height, o.width, noise_deg=self.normals_noise_deg)
                nm = dataclasses.replace(nm, kappa=nm.kappa * np.float32(GT_KAPPA), t_s=float(ti))
                yield Frame(t_s=float(ti), K=self.K, index=a + i, normals=nm)

    def _rendered_frames(self) -> Iterator[Frame]:
        o, spec, world = self.options, self.spec, self.world
        renderer = Renderer(world.scene, self.K, o.width, o.height)
        rng = np.random.default_rng([o.seed, 7])  # image noise, exposure, drops
        log_gain = 0.0
        for i in range(o.frames):
            t = i / o.fps
            radiance, depth, normals_c, _, _, _ = world.render_radiance(renderer, t)
            if spec.motion_blur_exposure_s > 0:  # average sub-frames over the exposure
                subs = t + np.linspace(-0.5, 0.5, BLUR_SUBFRAMES) * spec.motion_blur_exposure_s
                radiance = np.mean([world.render_radiance(renderer, ts)[0] for ts in subs], axis=0)
            if spec.exposure_change:
                log_gain = float(np.clip(log_gain + rng.normal(0.0, EXPOSURE_STEP), -0.7, 0.5))
            rgb = Renderer.to_uint8(radiance, np.exp(log_gain), spec.noise_std_dn, rng)
            kappa = np.where(depth > 0, GT_KAPPA, 0.0).astype(np.float32)
            if rng.random() < spec.drop_probability:
                rgb[:] = 0
                depth = np.zeros_like(depth)
                kappa[:] = 0
            yield Frame(t_s=t, rgb=rgb, depth=depth.astype(np.float32), K=self.K, index=i,
                        normals=NormalMap(normals_c.astype(np.float32), kappa, t_s=t))

    # ----- IMU ----------------------------------------------------------------------------------
    def imu_batches(self) -> Iterator[ImuBatch]:
        """The IMU over [0, duration] in chunks of `CHUNK_S` (bias walk continued across chunks)."""
        rate = self.options.imu_rate_hz
        n_total = int(np.floor(self.duration_s * rate + 1e-9)) + 1
        per_chunk = max(2, int(round(CHUNK_S * rate)))
        noise = self.imu_noise
        for k, (a, b) in enumerate(self._chunks(n_total, per_chunk)):
            t0 = a / rate
            shifted = _ShiftedTrajectory(self.trajectory, t0, (b - 1 - a) / rate)
            t, gyro, accel, gyro_bias, accel_bias = simulate_imu(
                shifted, rate, noise, seed=[self.options.seed, 3, k], R_ci=self.R_ci, return_bias=True)
            noise = dataclasses.replace(noise, gyro_bias_init_rad_s=tuple(gyro_bias[-1]),
                                        accel_bias_init_m_s2=tuple(accel_bias[-1]))
            yield ImuBatch(np.arange(a, a + len(t)) / rate, gyro, accel)

    def events(self) -> Iterator[Frame | ImuBatch]:
        yield from interleave(self._frames(), self.imu_batches() if self.use_imu else None)

    def ground_truth(self) -> GroundTruth:
        t = np.arange(self.options.frames) / self.options.fps
        return GroundTruth(t, self.trajectory.sample(t).R_wc, gravity_aligned=True)
