"""`uareme-fusion bench WHAT`: speed benchmarks that print absolute figures and ratios."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from .app import app, fail

BENCHMARKS = ("solver",)


@app.command()
def bench(
    what: str = typer.Argument("solver", help=f"Which benchmark: {', '.join(BENCHMARKS)}."),
    repeats: int = typer.Option(100, min=5, help="Timed runs per figure."),
    json_out: Path = typer.Option(None, "--json", help="Also write the figures to this JSON file."),
) -> None:
    """Time a stage on this machine (one core) and print medians, p90 and ratios to references."""
    if what not in BENCHMARKS:
        raise typer.BadParameter(f"unknown benchmark '{what}'; choose from {', '.join(BENCHMARKS)}")
    if json_out is not None and (json_out.is_dir() or not json_out.parent.is_dir()):
        raise fail(f"--json {json_out}: cannot write a file there (a folder, or its folder does not exist)")
    from ..benchmarks import solver

    results = solver.run(repeats=repeats)
    if json_out is not None:
        json_out.write_text(json.dumps(results, indent=2))
