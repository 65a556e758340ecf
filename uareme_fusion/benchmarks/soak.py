"""Soak benchmark (issue 8): one simulated hour through the full pipeline, in accelerated time.

`SimulatedSource("room", seconds, render=False, imu_rate_hz=400)` streams the simulator's normals
(optionally with angular noise) and a 400 Hz IMU; the solver, the EKF (`mekf`) and the file sinks
(`trajectory.tum`, `estimates.csv` in a temporary folder) run on every frame, exactly as in
`uareme-fusion run`. A probe sink, whose own buffers are allocated and touched before the run,
measures three things without growing itself:
- memory: the resident set size (RSS, MB) after a warm-up and every `sample_every` frames after it;
- state: the sizes of the pipeline's and the backend's containers (lists, dicts, arrays, the IMU
  reorder buffer), at the end of the warm-up and at the end of the run (`container_sizes`);
- accuracy: tilt error (deg) per minute of stream against the simulator's truth, and the first and
  last minute's estimates kept for ARE (deg) after one constant alignment fitted on the first minute
  (so yaw drift over the hour shows in the last minute's ARE).
Goals: RSS growth < 5 MB after warm-up, no container larger at the end than at the end of the
warm-up, and the last minute's tilt and ARE within 1 degree of the first minute's.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ..drivers.simulated import SimulatedSource
from ..pipeline import RunConfig
from ..pipeline.session import build_pipeline
from ..sinks.estimate_files import EstimatesCsvWriter, TumTrajectoryWriter
from ..rotations import align_constant, are_deg, tilt_error_deg, up_in_camera
from .pipeline import rss_mb

RSS_GROWTH_GOAL_MB = 5.0
ACCURACY_MARGIN_DEG = 1.0
"""The last minute's tilt mean and ARE mean may exceed the first minute's by at most this, degrees."""
WINDOW_S = 60.0
"""Length of the accuracy windows (first and last minute, per-minute tilt), s."""


def container_sizes(obj, prefix: str = "", depth: int = 3) -> dict[str, int]:
    """Element counts of the containers an object holds: `len` of lists, tuples, dicts, sets and
    deques, `size` of numpy arrays, found among its attributes and, `depth` levels down, among the
    attributes of the objects they hold (e.g. the EKF's IMU reorder buffer). Names are dotted paths."""
    sizes: dict[str, int] = {}
    for name, value in vars(obj).items():
        path = f"{prefix}{name}"
        if isinstance(value, np.ndarray):
            sizes[path] = int(value.size)
        elif isinstance(value, (list, tuple, set, Mapping)) or hasattr(value, "maxlen"):
            sizes[path] = len(value)
        elif depth > 0 and hasattr(value, "__dict__") and not isinstance(value, type):
            sizes.update(container_sizes(value, f"{path}.", depth - 1))
    return sizes


class SoakProbe:
    """A sink measuring memory, state and accuracy (see the module docstring) in bounded memory.

    `truth` maps frame times (N,) to true `R_wc` (N, 3, 3); `objects` are what `container_sizes`
    inspects (name -> object)."""

    def __init__(self, truth, objects: dict, fps: float, n_frames: int, warmup_frames: int, sample_every: int):
        self.truth, self.objects = truth, objects
        self.warmup, self.every = warmup_frames, sample_every
        self.per_window = max(1, int(round(WINDOW_S * fps)))
        self.n_frames = n_frames
        self.count = 0
        self.sizes_start: dict[str, int] = {}
        self.sizes_end: dict[str, int] = {}
        self.sizes_max: dict[str, int] = {}
        # Preallocated and touched now, so that filling them later does not grow the RSS.
        n_samples = n_frames // max(sample_every, 1) + 2
        self.rss = np.full((n_samples, 2), np.nan)
        self._n_rss = 0
        self._t = np.full(self.per_window, np.nan)
        self._R = np.full((self.per_window, 3, 3), np.nan)
        self._fill = 0
        self.first: tuple[np.ndarray, np.ndarray] | None = None
        self.last: tuple[np.ndarray, np.ndarray] | None = None
        # Per minute: start time, tilt mean and max (deg).
        self.windows = [dict(t0_s=np.nan, tilt_mean_deg=np.nan, tilt_max_deg=np.nan)
                        for _ in range(n_frames // self.per_window + 2)]
        self._n_windows = 0

    def write(self, result) -> None:
        est = result.estimate
        self._t[self._fill] = result.t_s
        self._R[self._fill] = est.R_wc
        self._fill += 1
        self.count += 1
        if self._fill == self.per_window or self.count == self.n_frames:
            self._close_window()
        if self.count >= self.warmup and (self.count - self.warmup) % self.every == 0:
            self._sample()

    def _sample(self) -> None:
        if self._n_rss < len(self.rss):
            self.rss[self._n_rss] = (self.count, rss_mb())
            self._n_rss += 1
        sizes = self.sizes()
        if not self.sizes_start:
            self.sizes_start = dict(sizes)
        self.sizes_end = sizes
        for k, v in sizes.items():
            self.sizes_max[k] = max(v, self.sizes_max.get(k, 0))

    def sizes(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for name, obj in self.objects.items():
            out.update(container_sizes(obj, f"{name}."))
        return out

    def _close_window(self) -> None:
        n = self._fill
        t, R = self._t[:n].copy(), self._R[:n].copy()
        tilt = tilt_error_deg(up_in_camera(R), up_in_camera(self.truth(t)))
        if self._n_windows < len(self.windows):
            self.windows[self._n_windows].update(t0_s=float(t[0]), tilt_mean_deg=float(tilt.mean()),
                                                 tilt_max_deg=float(tilt.max()))
            self._n_windows += 1
        if self.first is None:
            self.first = (t, R)
        self.last = (t, R)
        self._fill = 0

    def close(self) -> None:
        if self._fill:
            self._close_window()

    def rss_samples(self) -> np.ndarray:
        return self.rss[: self._n_rss]

    def minute_windows(self) -> list[dict]:
        return self.windows[: self._n_windows]


def accuracy(probe: SoakProbe, truth) -> dict:
    """Tilt and ARE (deg) of the first and last window; ARE aligned once, on the first window."""
    (t0, R0), (t1, R1) = probe.first, probe.last
    T0, T1 = truth(t0), truth(t1)
    A = align_constant(R0, T0)
    out = {}
    for name, R, T in (("first", R0, T0), ("last", R1, T1)):
        tilt = tilt_error_deg(up_in_camera(R), up_in_camera(T))
        are = are_deg(A @ R, T, align=False)
        out[name] = {"t0_s": float(t0[0] if name == "first" else t1[0]), "frames": len(R),
                     "tilt_mean_deg": float(tilt.mean()), "tilt_p95_deg": float(np.percentile(tilt, 95)),
                     "are_mean_deg": float(are.mean()), "are_max_deg": float(are.max())}
    return out


def soak(seconds: float = 3600.0, fps: float = 30.0, imu_rate_hz: float = 400.0, normals_noise_deg: float = 2.0,
         preset: str = "building", warmup_s: float = 60.0, sample_every: int = 900, seed: int = 0) -> dict:
    """Run the soak and return its figures (see the module docstring); nothing is printed."""
    source = SimulatedSource("room", seconds=seconds, fps=fps, render=False, imu_rate_hz=imu_rate_hz,
                             normals_noise_deg=normals_noise_deg, seed=seed)

    def truth(t_s):
        return source.trajectory.sample(np.asarray(t_s, float)).R_wc

    cfg = RunConfig(normals="source", mekf_preset=preset)
    n_frames = source.info.n_frames
    warmup = min(max(1, int(round(warmup_s * fps))), n_frames)
    with tempfile.TemporaryDirectory() as tmp, source:
        out = Path(tmp)
        sinks = [TumTrajectoryWriter(out / "trajectory.tum"), EstimatesCsvWriter(out / "estimates.csv")]
        pipeline = build_pipeline(source, cfg, sinks)
        probe = SoakProbe(truth, {"pipeline": pipeline}, fps, n_frames, warmup, sample_every)
        pipeline.sinks.append(probe)
        start = time.perf_counter()
        stats = pipeline.run(source)
        wall_s = time.perf_counter() - start
        file_mb = sum(p.stat().st_size for p in out.iterdir()) / 2**20
    rss = probe.rss_samples()
    grown = {k: (probe.sizes_start.get(k, 0), v) for k, v in probe.sizes_end.items()
             if v > probe.sizes_start.get(k, 0)}
    return {
        "simulated_s": seconds, "fps": fps, "imu_rate_hz": imu_rate_hz, "normals_noise_deg": normals_noise_deg,
        "preset": preset, "frames": stats.frames, "imu_samples": stats.imu_samples, "stopped": stats.stopped,
        "frames_without_visual": stats.frames_without_visual, "status_counts": dict(stats.status_counts),
        "wall_s": wall_s, "speedup": seconds / wall_s if wall_s > 0 else float("nan"),
        "timing_ms": stats.times.mean_ms(stats.estimates), "output_files_mb": file_mb,
        "rss_after_warmup_mb": float(rss[0, 1]) if len(rss) else float("nan"),
        "rss_end_mb": float(rss[-1, 1]) if len(rss) else float("nan"),
        "rss_max_mb": float(rss[:, 1].max()) if len(rss) else float("nan"),
        "rss_growth_mb": float(rss[-1, 1] - rss[0, 1]) if len(rss) else float("nan"),
        "state_sizes_start": probe.sizes_start, "state_sizes_end": probe.sizes_end,
        "state_sizes_max": probe.sizes_max, "state_grown": grown,
        "accuracy": accuracy(probe, truth), "minutes": probe.minute_windows(),
    }


def run(seconds: float = 3600.0, fps: float = 30.0, imu_rate_hz: float = 400.0, normals_noise_deg: float = 2.0,
        preset: str = "building", warmup_s: float = 60.0) -> dict:
    """Run the soak, print its figures against the goals and return them."""
    r = soak(seconds, fps, imu_rate_hz, normals_noise_deg, preset, warmup_s)
    acc = r["accuracy"]
    first, last = acc["first"], acc["last"]
    ok_rss = r["rss_growth_mb"] < RSS_GROWTH_GOAL_MB
    ok_state = not r["state_grown"]
    ok_acc = (last["tilt_mean_deg"] <= first["tilt_mean_deg"] + ACCURACY_MARGIN_DEG
              and last["are_mean_deg"] <= first["are_mean_deg"] + ACCURACY_MARGIN_DEG)
    stages = ", ".join(f"{k} {v:.2f}" for k, v in r["timing_ms"].items())
    print(f"soak: sim:room {r['simulated_s'] / 60:g} min at {fps:g} fps, {imu_rate_hz:g} Hz IMU, normals noise "
          f"{normals_noise_deg:g} deg, mekf preset {preset}, file sinks")
    print(f"  {r['frames']} frames, {r['imu_samples']} IMU samples, stopped: {r['stopped']}; "
          f"wall {r['wall_s']:.0f} s ({r['speedup']:.1f}x real time); ms per frame: {stages}")
    print(f"  RSS after {warmup_s:g} s warm-up {r['rss_after_warmup_mb']:.1f} MB -> end {r['rss_end_mb']:.1f} MB "
          f"(max {r['rss_max_mb']:.1f}): growth {r['rss_growth_mb']:.2f} MB (goal < {RSS_GROWTH_GOAL_MB:g}: "
          f"{'ok' if ok_rss else 'FAIL'}); outputs {r['output_files_mb']:.1f} MB on disk")
    print(f"  state: {len(r['state_sizes_end'])} containers inspected; grown since warm-up: "
          f"{r['state_grown'] or 'none'} ({'ok' if ok_state else 'FAIL'})")
    held = {k: v for k, v in r["state_sizes_max"].items() if "held" in k or "pending" in k or "samples" in k}
    print(f"  largest IMU buffers seen (elements): {held}")
    print(f"  first minute: tilt mean {first['tilt_mean_deg']:.3f} deg (p95 {first['tilt_p95_deg']:.3f}), "
          f"ARE mean {first['are_mean_deg']:.3f} deg (max {first['are_max_deg']:.3f})")
    print(f"  last minute:  tilt mean {last['tilt_mean_deg']:.3f} deg (p95 {last['tilt_p95_deg']:.3f}), "
          f"ARE mean {last['are_mean_deg']:.3f} deg (max {last['are_max_deg']:.3f}) with the first minute's "
          f"alignment ({'ok' if ok_acc else 'FAIL'}: within {ACCURACY_MARGIN_DEG:g} deg of the first)")
    worst = max(r["minutes"], key=lambda w: w["tilt_max_deg"]) if r["minutes"] else None
    if worst:
        print(f"  worst minute for tilt starts at {worst['t0_s']:.0f} s: max {worst['tilt_max_deg']:.3f} deg")
    r["goals_met"] = {"rss": ok_rss, "state": ok_state, "accuracy": ok_acc}
    return r
