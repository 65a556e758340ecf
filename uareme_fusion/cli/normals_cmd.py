"""`uareme-fusion normals INPUT --out DIR`: learned normal and confidence images and arrays per frame."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from .app import app, err_console
from .run_cmd import _o


@app.command("normals")
def normals_command(
    input_path: Path = typer.Argument(..., metavar="INPUT", help="An image, a folder of images or a video."),
    out: Path = typer.Option(..., "--out", help="Folder for <stem>_normals.png, <stem>_confidence.png, <stem>.npz."),
    model: Optional[Path] = typer.Option(None, "--model", help="A drop-in model file (TorchScript or state "
                                         "dict, RGB in [0, 1] -> normal + kappa); default: the shipped weights."),
    kappa_cap: float = typer.Option(75.0, "--kappa-cap", min=1e-3, help="kappa cap; white in the confidence image."),
    intrinsics: Optional[str] = _o["intrinsics"],
    threads: int = typer.Option(1, "--threads", min=1, max=256, help="torch CPU threads (1: fast beside other "
                                                                      "busy programs)."),
    force: bool = typer.Option(False, "--force", help="Write into a non-empty --out (files of the same name are replaced)."),
) -> None:
    """Surface normals (coloured X-Y-Z to R-G-B, OpenCV camera frame) and confidence (white = confident)."""
    from ..drivers.intrinsics import parse_intrinsics
    from ..normals.export import export_normals
    from ..normals.learned import LearnedNormals, LearnedNormalsConfig
    from ..pipeline.session import prepare_output_folder

    prepare_output_folder(out, force)
    camera = parse_intrinsics(intrinsics) if intrinsics is not None else None
    estimator = LearnedNormals(model=model, config=LearnedNormalsConfig(kappa_cap=kappa_cap, threads=threads))
    columns = [TextColumn("[bold]normals"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()]
    with Progress(*columns, console=err_console) as progress:
        task = progress.add_task("normals", total=None)
        written = export_normals(input_path, out, estimator, kappa_cap,
                                 progress=lambda done, total: progress.update(task, completed=done, total=total),
                                 camera=camera)
    typer.echo(f"wrote {written} frame(s) to {out}")
