"""`uareme-fusion demo`: the method on built-in synthetic data, no files needed.

Part 1 (solver): synthetic Manhattan normal maps with correlated noise and outliers, solved
without a prior; prints the rotation error against the truth and the calibrated uncertainty.
Part 2 (the whole pipeline): a rendered room (handheld) and a rendered bus (accelerating, braking,
a corner and a roundabout) with their IMU, through learned normals, the solver and the EKF; tilt
error of vision only, IMU only (our filter and vqf when installed) and fused, as a table, a plot and
the bus's horizon overlay video.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from .benchmarks.peers import vqf_6d_R_wi
from .drivers.base import ImuBatch, Source
from .scoring.statistics import error_stats
from .io.safe_files import save_figure_atomic
from .rotations import angle_between, exp_so3, nees, tilt_error_deg, up_in_camera
from .sim.normal_maps import manhattan_normal_map
from .solver import solve_manhattan
from .solver.manhattan import up_candidate


def solver_demo(console: Console, seed: int = 0) -> dict:
    """Solve three synthetic 640x480 maps (clean, noisy, with outliers) and print a table."""
    rng = np.random.default_rng(seed)
    R_true = exp_so3([1.2, 0.3, -0.2])
    cases = {
        "3 deg noise": dict(noise_deg=3.0),
        "10 deg correlated": dict(noise_deg=10.0, correlation_px=8.0),
        "+30% outliers": dict(noise_deg=10.0, correlation_px=8.0, outlier_fraction=0.3),
        "blank wall*": dict(noise_deg=3.0, axes=(2,)),
    }
    table = Table(title="Manhattan solver on synthetic 640x480 normal maps (no prior)")
    for col in ("map", "error (deg)", "reported std (deg)", "NEES", "up axis (camera)", "ms"):
        table.add_column(col)
    figures = {}
    t0 = time.perf_counter()  # the first solve loads the compiled kernels (about a second): not a solve's cost
    warm = manhattan_normal_map(R_true, np.random.default_rng(seed + 1), height=48, width=64, noise_deg=3.0)
    solve_manhattan(warm.normals, warm.kappa)
    figures["warm_up_ms"] = 1e3 * (time.perf_counter() - t0)
    for name, options in cases.items():
        nm = manhattan_normal_map(R_true, rng, height=480, width=640, **options)
        result = solve_manhattan(nm.normals, nm.kappa).symmetric_to(R_true)
        if "axes" in options:  # only the wall's normal is observable: score that axis
            error = float(np.degrees(np.arccos(min(1.0, abs(result.R_cm[:, 2] @ R_true[:, 2])))))
        else:
            error = float(np.degrees(angle_between(result.R_cm, R_true)))
        std = np.degrees(np.sqrt(np.diag(result.cov)))
        _, up_c = up_candidate(result.R_cm)
        ms = sum(result.timing_ms.values())
        figures[name] = {"error_deg": error, "std_deg": std.tolist(), "ms": ms}
        table.add_row(name, f"{error:.3f}", " ".join(f"{s:.3f}" for s in std),
                      f"{nees(result.R_cm, R_true, result.cov):.2f}",
                      " ".join(f"{v:+.2f}" for v in up_c), f"{ms:.1f}")
    console.print(table)
    console.print(f"ms: one solve, after a first warm-up solve that loaded the compiled kernels "
                  f"({figures['warm_up_ms']:.0f} ms, once per process, not in the table).")
    console.print("* A blank wall leaves rotation about its normal unobservable: the error shown is that of the "
                  f"wall's axis, and the std about the normal is capped at {np.degrees(1.0):.0f} deg instead of "
                  "a NaN, so a filter simply ignores that direction.")
    return figures


def _vqf_tilt_deg(seq, R_wc_true_at_frames) -> np.ndarray | None:
    """Tilt error (deg) of vqf's 6D filter on the sequence's IMU at the frame times, or None."""
    try:
        R_wi = vqf_6d_R_wi(seq.imu_gyro_rad_s, seq.imu_accel_m_s2, float(np.median(np.diff(seq.imu_t_s))))
    except ImportError:
        return None
    idx = np.clip(np.searchsorted(seq.imu_t_s, seq.t_frame_s), 0, len(seq.imu_t_s) - 1)
    return tilt_error_deg(up_in_camera(R_wi[idx]), up_in_camera(R_wc_true_at_frames))  # IMU = camera frame here


class _TeeImu(Source):
    """The wrapped source, keeping its IMU samples so other estimators can run on the same data."""

    def __init__(self, inner: Source):
        self.inner, self.info, self.batches = inner, inner.info, []

    def events(self):
        for event in self.inner.events():
            if isinstance(event, ImuBatch):
                self.batches.append(event)
            yield event

    def ground_truth(self):
        return self.inner.ground_truth()

    def imu_arrays(self):
        return tuple(np.concatenate([getattr(b, k) for b in self.batches])
                     for k in ("t_s", "gyro_rad_s", "accel_m_s2"))

    def close(self):
        self.inner.close()


class _Collector:
    """Keeps every result of a short demo run."""

    def __init__(self):
        self.results = []

    def write(self, result) -> None:
        self.results.append(result)

    def close(self) -> None:
        pass


DEMO_SCENES = {"room": ("handheld", 12.0), "bus": ("vehicle", 30.0)}
"""Scenario: (EKF preset, seconds) of the rendered demo sequences, at `DEMO_FPS` and `DEMO_SIZE`."""
DEMO_SIZE = (320, 240)
"""(width, height) in pixels of the rendered demo frames."""
DEMO_FPS = 15.0


def scene_sequence(scene: str, seed: int = 0, normals: str = "learned", scale_seconds: float = 1.0,
                   size: tuple[int, int] = DEMO_SIZE, fps: float = DEMO_FPS, sinks=(), threads: int | None = None,
                   progress=None):
    """The rendered `scene` (a key of `DEMO_SCENES`, with its EKF preset) through the whole pipeline, into
    `sinks` too: `(VisualSequence, results, stats)`, the sequence holding each frame's visual rotation, the IMU
    and the ground truth (for other estimators on the same data, `tools/demo_replay.py`), `results` the
    pipeline's per-frame results and `stats` its run statistics. `progress(scene, n_frames)` gives the run's
    `on_result`."""
    from .drivers.simulated import SimulatedSource
    from .evaluation.sequence import VisualSequence
    from .pipeline import RunConfig
    from .pipeline.session import build_pipeline

    preset, seconds = DEMO_SCENES[scene]
    source = _TeeImu(SimulatedSource(scene, seconds=seconds * scale_seconds, fps=fps, width=size[0],
                                      height=size[1], seed=seed))
    collector = _Collector()
    pipeline = build_pipeline(source, RunConfig(normals=normals, mekf_preset=preset,
                                                 **({} if threads is None else {"threads": threads})),
                              [collector, *sinks])
    stats = pipeline.run(source, on_result=None if progress is None else progress(scene, source.info.n_frames))
    t = np.array([r.t_s for r in collector.results])
    R_true, _ = source.ground_truth().at(t)
    seq = VisualSequence(scene, t, [r.visual for r in collector.results], *source.imu_arrays(), R_true)
    return seq, collector.results, stats


def fusion_demo(console: Console, out_dir: Path | None, seed: int = 0, normals: str = "learned",
                scale_seconds: float = 1.0, progress=None, threads: int | None = None,
                size: tuple[int, int] = DEMO_SIZE, fps: float = DEMO_FPS) -> dict:
    """Rendered room and bus through the whole pipeline (normals -> solver -> EKF with IMU): tilt of
    vision only, IMU only (our filter, and vqf when installed) and fused; a table, a plot and the
    horizon overlay video of the bus. `scale_seconds` scales the scenes' lengths, `size` (width,
    height) and `fps` are those of the rendered frames (a smaller configuration for tests)."""
    from .backends.mekf import MekfMode
    from .backends.factory import make_backend
    from .evaluation.compare import BackendRun, errors_over_time, run_backend
    from .sinks.drawing import HorizonVideoSink

    figures, tilts = {}, {}
    table = Table(title=f"Tilt error (deg), rendered scenes, {normals} normals, {fps:g} fps")
    for col in ("scene", "estimator", "mean", "p95", "max", "ARE mean"):
        table.add_column(col)
    for scene, (preset, _) in DEMO_SCENES.items():
        video = ([HorizonVideoSink(out_dir / "demo_bus_horizon.mp4", fps, panes=True)]
                 if out_dir is not None and scene == "bus" else [])
        seq, results, stats = scene_sequence(scene, seed, normals, scale_seconds, size, fps, video, threads, progress)
        t, R_true = seq.t_frame_s, seq.R_wc_true
        imu_only = make_backend("mekf", mekf_preset=preset, overrides={"mode": MekfMode.IMU_ONLY})
        runs = {"vision only (single frame)": run_backend(make_backend("single"), seq),
                "IMU only (our filter)": run_backend(imu_only, seq),
                f"fused (mekf, {preset})": BackendRun("mekf", [r.estimate for r in results])}
        rows = {}
        for name, run in runs.items():
            err = errors_over_time(run, R_true)
            ok = err["initialised"]
            rows[name] = (err["tilt_deg"][ok], error_stats(err["are_deg"][ok], ("mean",))["mean"])
        vqf_tilt = _vqf_tilt_deg(seq, R_true)
        if vqf_tilt is not None:
            rows["IMU only (vqf 6D)"] = (vqf_tilt, float("nan"))
        figures[scene] = {"frames": stats.frames, "fps": stats.as_dict()["fps"],
                          "timing_ms": stats.as_dict()["timing_ms"]}
        tilts[scene] = {}
        for name, (tilt, are) in rows.items():
            figures[scene][name] = {**error_stats(tilt, ("mean", "p95", "max")), "are_mean": are}
            tilts[scene][name] = (t[-len(tilt):], tilt)
            table.add_row(scene, name, *(f"{figures[scene][name][k]:.2f}" for k in ("mean", "p95", "max")),
                          "" if np.isnan(are) else f"{are:.2f}")
    console.print(table)
    console.print("In the bus the accelerometer reads gravity plus the bus's acceleration, so IMU-only filters "
                  "tilt in every turn and brake; vision alone loses frames; fused, the Manhattan structure "
                  "keeps the tilt right and the gyro bridges what vision misses.")
    if out_dir is not None:
        figures["plot"] = str(_plot_tilt(tilts, out_dir / "demo_tilt.png"))
        console.print(f"wrote {figures['plot']} and {out_dir / 'demo_bus_horizon.mp4'}")
    return figures


TILT_PLOT_LINEAR_DEG = 10.0
"""The demo's tilt plot is linear below this (every degree labelled), logarithmic above."""
TILT_PLOT_TICKS_DEG = (0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 20, 50, 100, 180)


def _plot_tilt(tilts: dict, path: Path) -> Path:
    """The tilt plot, drawn on matplotlib's Agg canvas directly (no global backend is changed)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FixedLocator, FormatStrFormatter

    path.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(10, 3.2 * len(tilts)))
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(tilts), 1, squeeze=False)
    for ax, (scene, rows) in zip(axes[:, 0], tilts.items()):
        for name, (t, tilt) in rows.items():
            ax.plot(t, tilt, lw=1, label=name)
        ax.set(xlabel="time (s)", ylabel="tilt error (deg)", title=f"{scene}: vision, IMU, fused")
        # linear up to 10 deg, where the methods differ by a few degrees; logarithmic above for failures
        ax.set_yscale("symlog", linthresh=TILT_PLOT_LINEAR_DEG, linscale=2.0)
        ax.yaxis.set_major_locator(FixedLocator(TILT_PLOT_TICKS_DEG))
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.set_ylim(0, max(TILT_PLOT_LINEAR_DEG, *(float(np.nanmax(v[1], initial=0)) * 1.2 for v in rows.values())))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure_atomic(path, fig, dpi=100)
    return path


def default_out_dir() -> Path:
    """Where the demo writes its plot and video without --out: `uareme-demo` in the system's temporary
    folder (never the current folder)."""
    return Path(tempfile.gettempdir()) / "uareme-demo"


def run_demo(console: Console | None = None, out_dir: Path | None = None, normals: str = "learned",
             progress=None, threads: int | None = None) -> dict:
    """Both parts; the plot and the video go to `out_dir` (default `default_out_dir()`), said first."""
    console = console or Console()
    out_dir = default_out_dir() if out_dir is None else out_dir
    console.print(f"The demo writes its plot and video to {out_dir} (choose with --out).")
    return {"solver": solver_demo(console), "scenes": fusion_demo(console, out_dir, normals=normals,
                                                                  progress=progress, threads=threads)}
