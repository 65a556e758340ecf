"""`uareme-fusion demo`: built-in synthetic data through the method, no files needed."""

from __future__ import annotations

from pathlib import Path

import typer

from .app import app, fail


@app.command()
def demo(
    out: Path = typer.Option(Path("uareme-demo"), help="Folder for the demo's plot."),
) -> None:
    """Run the method on built-in synthetic data and print what it gets right (under a minute)."""
    if out.exists() and not out.is_dir():
        raise fail(f"--out {out} exists and is not a folder")
    from ..demo import run_demo

    run_demo(out_dir=out)
