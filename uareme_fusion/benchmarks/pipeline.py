"""End-to-end pipeline benchmark: frames per second and per-stage milliseconds for 640x480 input
(learned normals at their internal size, 160x120 by default, the solver, the EKF with a 200 Hz IMU, the file sinks),
and the memory growth over a long stream.

Frames are rendered by the simulator before timing starts and replayed from memory, so the figures
are the pipeline's own (a video decoder adds about 2 ms per 640x480 frame). The memory run loops a
few rendered frames of a camera held still (`static`), with the IMU simulated for the whole stream,
and reads the resident set size (RSS) every `sample_every` frames after a warm-up.

The throughput is measured twice: alone, and with one other CPU-bound process running beside it
(`busy_neighbour`), as on a robot or laptop where other programs run; their ratio is the figure of
issue 16 (goal >= 0.5).
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..drivers.base import Source, SourceInfo
from ..pipeline import RunConfig
from ..pipeline.session import run_source
from ..sim.imu import simulate_imu
from ..sim.render import Renderer, intrinsics_from_fov
from ..sim.scenarios import SCENARIOS, build_scenario
from ..types import Frame, ImuBatch


def rss_mb() -> float:
    """Resident set size of this process, MB (Linux /proc; NaN elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
    except OSError:
        return float("nan")
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


class ReplaySource(Source):
    """Pre-rendered frames of a scenario replayed (looped when the stream is longer) with its IMU."""

    def __init__(self, scenario: str, seconds: float, fps: float = 30.0, width: int = 640, height: int = 480,
                 distinct_frames: int | None = None, imu_rate_hz: float = 200.0, seed: int = 0):
        n = int(round(seconds * fps))
        distinct = n if distinct_frames is None else min(n, distinct_frames)
        world = build_scenario(scenario, seconds + 1.0, seed)
        K = intrinsics_from_fov(width, height, SCENARIOS[scenario].hfov_deg)
        renderer = Renderer(world.scene, K, width, height)
        rng = np.random.default_rng(seed)
        self.rgb = [Renderer.to_uint8(world.render_radiance(renderer, k / fps)[0], 1.0, 2.0, rng)
                    for k in range(distinct)]
        self.t_frame = np.arange(n) / fps
        self.imu = simulate_imu(world.trajectory, rate_hz=imu_rate_hz, seed=seed)
        self.R_wc_true = world.trajectory.sample(self.t_frame[:distinct]).R_wc
        self.K = K
        self.info = SourceInfo(name=f"replay:{scenario}", n_frames=n, fps=fps, K=K, has_imu=True,
                               image_size=(height, width))

    def events(self):
        t_imu, gyro, accel = self.imu
        ends = np.searchsorted(t_imu, self.t_frame, side="right")
        start = 0
        for k, t in enumerate(self.t_frame):
            if ends[k] > start:
                yield ImuBatch(t_imu[start:ends[k]], gyro[start:ends[k]], accel[start:ends[k]])
                start = ends[k]
            yield Frame(float(t), rgb=self.rgb[k % len(self.rgb)], K=self.K, index=k)


class MemoryProbe:
    """A sink that samples RSS every `every` estimates after `warmup` of them."""

    def __init__(self, every: int = 300, warmup: int = 300):
        self.every, self.warmup, self.count, self.samples = every, warmup, 0, []

    def write(self, result) -> None:
        self.count += 1
        if self.count >= self.warmup and (self.count - self.warmup) % self.every == 0:
            self.samples.append((self.count, rss_mb()))

    def close(self) -> None:
        pass


FPS_GOAL = 40.0
"""640x480, both cues, learned normals, EKF and file sinks (issue 29's ">= 40 fps on this 2-core machine"; issue 12
asked 20)."""


class CpuClock:
    """A sink that reads the process's CPU time at each estimate: `ms_per_frame` between the first
    and the last one (start-up excluded) is what a frame costs on an idle core, whatever else runs
    on the machine (wall-clock ms grow with the machine's load)."""

    def __init__(self):
        self.first_s = self.last_s = None
        self.count = 0

    def write(self, result) -> None:
        now = time.process_time()
        self.first_s = now if self.first_s is None else self.first_s
        self.last_s, self.count = now, self.count + 1

    @property
    def ms_per_frame(self) -> float:
        return 1e3 * (self.last_s - self.first_s) / (self.count - 1) if self.count > 1 else float("nan")

    def close(self) -> None:
        pass


THREE_CUES_FPS_GOAL = 40.0
"""640x480 with all three cues (normals, lines, sky), learned normals, EKF (issue 26)."""
THREE_CUES = "normals,lines,sky"

BUSY_GOAL_RATIO = 0.5
"""fps with a busy neighbour over fps alone (issue 16)."""


@contextmanager
def busy_neighbour():
    """One other CPU-bound process (a Python busy loop) running while the block runs."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        time.sleep(0.2)  # let it get scheduled
        yield proc
    finally:
        proc.kill()
        proc.wait()


def throughput(seconds: float = 10.0, normals: str = "learned", threads: int | None = None,
               source: Source | None = None, cues: str = "normals,lines") -> dict:
    """fps and per-stage ms over a rendered room walk at 640x480 (30 fps, 200 Hz IMU)."""
    source = source or ReplaySource("room", seconds)
    cfg = RunConfig(normals=normals, mekf_preset="handheld", cues=cues,
                    **({} if threads is None else {"threads": threads}))
    clock = CpuClock()
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_source(source, Path(tmp), cfg, extra_sinks=[clock])
    pipeline_ms = {k: v for k, v in summary["timing_ms"].items() if k not in ("source", "total")}
    pipeline_total = sum(pipeline_ms.values())
    cpu_ms = clock.ms_per_frame
    sky = summary.get("sky_detector")
    return {"frames": summary["frames"], "timing_ms": pipeline_ms, "pipeline_ms": pipeline_total,
            "fps": 1e3 / pipeline_total, "cpu_ms_per_frame": cpu_ms, "cpu_fps": 1e3 / cpu_ms,
            "frames_without_visual": summary["frames_without_visual"], "status_counts": summary["status_counts"],
            "warm_up_ms": 1e3 * summary["warm_up_s"],
            "sky_looked_percent": 100.0 * sky["looked"] / max(sky["frames"], 1) if sky else float("nan")}


def memory(minutes: float = 10.0, normals: str = "learned", fps: float = 30.0) -> dict:
    """RSS growth (MB) from after the warm-up to the end of a `minutes` stream, and its slope."""
    source = ReplaySource("static", minutes * 60.0, fps=fps, distinct_frames=30)
    probe = MemoryProbe()
    with tempfile.TemporaryDirectory() as tmp:
        summary = run_source(source, Path(tmp), RunConfig(normals=normals, mekf_preset="handheld"),
                             extra_sinks=[probe])
    frames, rss = np.array(probe.samples).T if probe.samples else (np.zeros(0), np.zeros(0))
    slope = float(np.polyfit(frames, rss, 1)[0] * 1000) if len(frames) > 2 else float("nan")
    return {"stream_minutes": minutes, "frames": summary["frames"],
            "rss_start_mb": float(rss[0]) if len(rss) else float("nan"),
            "rss_end_mb": float(rss[-1]) if len(rss) else float("nan"),
            "growth_mb": float(rss[-1] - rss[0]) if len(rss) else float("nan"),
            "slope_mb_per_1000_frames": slope, "wall_s": summary["wall_s"]}


def run(seconds: float = 10.0, memory_minutes: float = 10.0, normals: str = "learned",
        threads: int | None = None) -> dict:
    """Print and return the figures against the goals (>= 40 fps, >= 0.5x of it beside a busy
    process, < 20 MB growth)."""
    source = ReplaySource("room", seconds)
    result = {"throughput": throughput(seconds, normals, threads, source)}
    with busy_neighbour():
        result["throughput_busy"] = throughput(seconds, normals, threads, source)
    tp, busy = result["throughput"], result["throughput_busy"]
    result["busy_ratio"] = busy["fps"] / tp["fps"]
    stages = ", ".join(f"{k} {v:.1f}" for k, v in tp["timing_ms"].items())
    from ..normals.learned import DEFAULT_THREADS

    shown = f"{DEFAULT_THREADS} (default)" if threads is None else str(threads)
    print(f"pipeline, 640x480 input, {normals} normals ({shown} torch threads), mekf + 200 Hz IMU, "
          f"{tp['frames']} frames:")
    print(f"  ms per frame: {stages}; total {tp['pipeline_ms']:.1f} ms; before the stream (`warm_up_s`: here the "
          f"backend's warm-up, numba loading the EKF's kernels once per process) {tp['warm_up_ms']:.0f} ms")
    print(f"  {tp['fps']:.1f} fps (goal >= {FPS_GOAL:g}: ratio {tp['fps'] / FPS_GOAL:.2f}); CPU {tp['cpu_ms_per_frame']:.1f} ms "
          f"per frame = {tp['cpu_fps']:.1f} fps on an idle core (load average {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores)")
    print(f"  beside one busy process: {busy['fps']:.1f} fps, {result['busy_ratio']:.2f}x of alone "
          f"(goal >= {BUSY_GOAL_RATIO}: ratio {result['busy_ratio'] / BUSY_GOAL_RATIO:.2f}); "
          f"normals {busy['timing_ms'].get('normals', float('nan')):.1f} ms")
    result["throughput_normals_only"] = alone = throughput(seconds, normals, threads, source, cues="normals")
    print(f"  normals only (--cues normals): {alone['fps']:.1f} fps, solver {alone['timing_ms']['solver']:.1f} ms; "
          f"the line cue costs {tp['timing_ms']['solver'] - alone['timing_ms']['solver']:.1f} ms per frame")
    result["throughput_three_cues"] = three = throughput(seconds, normals, threads, source, cues=THREE_CUES)
    print(f"  all three cues (--cues {THREE_CUES}; the sky detector on {three['sky_looked_percent']:.0f} % of the "
          f"frames, `solver/sky_cadence.py`): {three['fps']:.1f} fps; CPU {three['cpu_ms_per_frame']:.1f} ms per "
          f"frame = {three['cpu_fps']:.1f} fps on an idle core (goal >= {THREE_CUES_FPS_GOAL:g}: ratio "
          f"{three['cpu_fps'] / THREE_CUES_FPS_GOAL:.2f}), {three['cpu_ms_per_frame'] / tp['cpu_ms_per_frame']:.2f}x "
          f"the CPU of normals,lines")
    if memory_minutes > 0:
        result["memory"] = mem = memory(memory_minutes, normals)
        print(f"memory over a {mem['stream_minutes']:g}-minute stream ({mem['frames']} frames, "
              f"{mem['wall_s']:.0f} s wall): RSS {mem['rss_start_mb']:.1f} -> {mem['rss_end_mb']:.1f} MB, "
              f"growth {mem['growth_mb']:.2f} MB (goal < 20), slope {mem['slope_mb_per_1000_frames']:.3f} MB "
              "per 1000 frames")
    return result
