"""`uareme-fusion simulate SCENARIO --out DIR`: write a synthetic sequence with exact ground truth."""

from __future__ import annotations

import re
from pathlib import Path

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from ..errors import InputError
from ..sim.dataset import INCOMPLETE_MARKER, SequenceOptions, prepare_out_dir, write_sequence
from ..sim.scenarios import SCENARIO_NAMES, SCENARIOS
from .app import app, err_console, fail

_SCENARIO_HELP = "Scenario, one of: " + "; ".join(f"{n} ({SCENARIOS[n].description})" for n in SCENARIO_NAMES)


def parse_size(text: str) -> tuple[int, int]:
    """'320x240' -> (320, 240); InputError naming --size otherwise."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not match:
        raise InputError(f"--size must look like WIDTHxHEIGHT (e.g. 320x240), got {text!r}")
    return int(match.group(1)), int(match.group(2))


@app.command()
def simulate(
    scenario: str = typer.Argument(..., help=_SCENARIO_HELP, show_default=False),
    out: Path = typer.Option(..., "--out", help="Output folder (TUM RGB-D layout + imu0/data.csv + normals/ + scene.json)."),
    frames: int = typer.Option(100, "--frames", help="Number of camera frames."),
    size: str = typer.Option("320x240", "--size", help="Image size WIDTHxHEIGHT in pixels."),
    seed: int = typer.Option(0, "--seed", help="Seed of the scene, trajectory, noise: same seed, same files."),
    imu_rate: float = typer.Option(200.0, "--imu-rate", help="IMU rate in Hz (100-1000)."),
    fps: float = typer.Option(30.0, "--fps", help="Camera frame rate in Hz."),
    fov_deg: float = typer.Option(None, "--fov-deg",
                                  help="Horizontal field of view in degrees (45-95); default: the scenario's."),
    force: bool = typer.Option(False, "--force", help="Overwrite a non-empty output folder."),
) -> None:
    """Render a synthetic Manhattan-world sequence with ground-truth pose, normals and IMU."""
    try:
        if scenario not in SCENARIOS:
            raise InputError(f"unknown scenario {scenario!r}; valid: {', '.join(SCENARIO_NAMES)}")
        width, height = parse_size(size)
        options = SequenceOptions(frames=frames, width=width, height=height, fps=fps, seed=seed,
                                  imu_rate_hz=imu_rate, hfov_deg=fov_deg)
        options.validate()
        prepare_out_dir(out, force)
        columns = (TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
        with Progress(*columns, transient=False) as bar:
            task = bar.add_task(f"simulate {scenario}", total=frames)
            try:
                write_sequence(scenario, out, options, progress=lambda done, total: bar.update(task, completed=done))
            except KeyboardInterrupt:
                err_console.print(f"{out} is incomplete ({out / INCOMPLETE_MARKER} says so; 'run' refuses it)",
                                  markup=False, emoji=False, style="yellow")
                raise
    except InputError as exc:
        raise fail(str(exc)) from None
    typer.echo(f"wrote {frames} frames of {scenario} (seed {seed}) to {out}")
