"""`uareme-fusion run SOURCE --out DIR` and `uareme-fusion eval SOURCE --out DIR`."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console
from rich.table import Table

from ..config import load_config, validate_config
from ..pipeline import RunConfig
from ..pipeline.session import make_output_folder, run_source
from .app import app, fail
from .progress import frame_progress

SOURCE_HELP = ("A video file, webcam:N, an image, folder or glob of images, a dataset folder (TUM RGB-D, "
               "ICL-NUIM, EuRoC, one written by 'simulate'), a BROAD .hdf5 or IMU .csv, sim:SCENARIO, or oak[:ID].")
STOP_EXIT_CODES = {"end": 0, "max_frames": 0, "source_error": 1, "input_error": 2, "interrupted": 130}


def run_config(config: Optional[Path], **overrides) -> RunConfig:
    """The run configuration: the YAML file when given, then every option the user set on the command line."""
    cfg = load_config(config, RunConfig) if config is not None else RunConfig()
    given = {k: v for k, v in overrides.items() if v is not None}
    return validate_config({**cfg.model_dump(), **given}, RunConfig, "command-line options") if given else cfg


def execute(source: str, out: Path, cfg: RunConfig, imu: Optional[Path], fps: Optional[float], evaluate: bool,
            command: str, extra_sinks_factory=None, record_dir: Optional[Path] = None) -> dict:
    """Open the source, run it with a progress bar, report how it ended; exits non-zero when it failed.

    With `record_dir` the source's frames and IMU are also written there as they pass (our dataset
    layout: a live session replays exactly with `run RECORD_DIR`)."""
    from ..drivers import open_source, record

    out_dir = make_output_folder(out)
    opened = open_source(source, imu=None if imu is None else str(imu), fps=fps)
    with (opened if record_dir is None else record(opened, record_dir)) as src:
        sinks = extra_sinks_factory(src, out_dir, cfg) if extra_sinks_factory else []
        total = src.info.n_frames if src.info.has_frames else None
        if cfg.max_frames and total:
            total = min(total, cfg.max_frames)
        with frame_progress(command, total) as on_result:
            summary = run_source(src, out_dir, cfg, evaluate=evaluate, extra_sinks=sinks, on_result=on_result,
                                 command=command)
    print_summary(summary)
    code = STOP_EXIT_CODES.get(summary["stopped"], 1)
    if code:
        raise fail(f"{summary['error']} (outputs so far kept in {out_dir})", code)
    return summary


def print_summary(summary: dict) -> None:
    console = Console()
    table = Table(title=f"{summary['command']}: {summary['source']}", show_header=False)
    table.add_row("frames / estimates", f"{summary['frames']} / {summary['estimates']}")
    table.add_row("without visual rotation", str(summary["frames_without_visual"]))
    table.add_row("normals / backend", f"{summary['normals']} / {summary['backend']}")
    table.add_row("speed", f"{summary['fps']:.1f} fps")
    table.add_row("ms per frame", ", ".join(f"{k} {v:.1f}" for k, v in summary["timing_ms"].items()))
    if summary["status_counts"]:
        table.add_row("status flags", ", ".join(f"{k} {v}" for k, v in summary["status_counts"].items()))
    if "are_deg" in summary and summary["are_deg"]:
        a, t = summary["are_deg"], summary["tilt_deg"]
        table.add_row("ARE deg (mean / median / max)", f"{a['mean']:.2f} / {a['median']:.2f} / {a['max']:.2f}")
        table.add_row("tilt deg (mean / p95 / max)", f"{t['mean']:.2f} / {t['p95']:.2f} / {t['max']:.2f}")
        table.add_row("NEES mean", f"{summary['nees']['mean']:.2f}")
    table.add_row("outputs", ", ".join(summary["outputs"]))
    console.print(table)


def _options():
    return dict(
        imu=typer.Option(None, "--imu", help="IMU CSV in EuRoC format (t ns, gyro rad/s, accel m/s^2) merged by time."),
        backend=typer.Option(None, "--backend", help="mekf (default), smoother or single."),
        normals=typer.Option(None, "--normals",
                             help="auto (default), learned, depth, source, a model file (.pt) or a folder of normal maps."),
        config=typer.Option(None, "--config", help="YAML run configuration (keys of RunConfig)."),
        preset=typer.Option(None, "--preset", help="EKF preset: building, vehicle, handheld or a YAML path."),
        max_frames=typer.Option(None, "--max-frames", help="Stop after this many frames."),
        fps=typer.Option(None, "--fps", help="Frame rate of an image folder without timestamps (default 30)."),
        cues=typer.Option(None, "--cues", help="Visual cues: normals, lines or both (comma-separated; default both)."),
        record=typer.Option(None, "--record", help="Also write the source's frames and IMU to this folder "
                                                     "(replay it later with 'run FOLDER')."),
    )


_o = _options()


@app.command("run")
def run_command(
    source: str = typer.Argument(..., help=SOURCE_HELP),
    out: Path = typer.Option(..., "--out", help="Folder for trajectory.tum, estimates.csv and summary.json."),
    imu: Optional[Path] = _o["imu"], backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"],
    record: Optional[Path] = _o["record"], cues: Optional[str] = _o["cues"],
) -> None:
    """Estimate the camera orientation over a source; write trajectory.tum, estimates.csv, summary.json."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames, cues=cues)
    execute(source, out, cfg, imu, fps, evaluate=False, command="run", record_dir=record)


@app.command("eval")
def eval_command(
    source: str = typer.Argument(..., help="A source with ground truth (dataset folder, sim:SCENARIO, BROAD)."),
    out: Path = typer.Option(..., "--out", help="Folder for the outputs of 'run' plus the scores in summary.json."),
    imu: Optional[Path] = _o["imu"], backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], fps: Optional[float] = _o["fps"], cues: Optional[str] = _o["cues"],
) -> None:
    """As 'run', then score against the source's ground truth: ARE, tilt, NEES, per-stage ms, fps."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames, cues=cues)
    execute(source, out, cfg, imu, fps, evaluate=True, command="eval")
