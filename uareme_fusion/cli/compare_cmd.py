"""`uareme-fusion compare SOURCE --out DIR`: single, smoother (paper, gyro-aided) and mekf side by side."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from ..compare import compare, load_sequence, synthetic_sequence
from .app import app, fail

MAX_SYNTHETIC_DURATION_S = 3600.0
"""The synthetic sequence is held in memory: an hour at 15 fps is about 54000 frames."""


@app.command("compare")
def compare_command(
    source: Optional[Path] = typer.Argument(None, help="Dataset folder written by 'uareme-fusion simulate'."),
    out: Path = typer.Option(..., "--out", help="Folder for compare.md, compare.json and compare.png."),
    synthetic: Optional[str] = typer.Option(
        None, help="Build the sequence in memory from this simulator trajectory (walk, shake, static, bus, ...)."),
    seed: int = typer.Option(0, min=0, help="Seed of the synthetic sequence."),
    duration_s: float = typer.Option(20.0, "--duration-s", min=0.1, max=MAX_SYNTHETIC_DURATION_S,
                                     help="Length of the synthetic sequence, seconds."),
    drop_fraction: float = typer.Option(0.1, help="Synthetic: fraction of frames without a visual rotation."),
    bad_fraction: float = typer.Option(0.05, help="Synthetic: fraction of frames with random normals."),
) -> None:
    """Run every backend on the same visual rotations and IMU; write a table and an error plot."""
    if (source is None) == (synthetic is None):
        raise fail("give either a dataset folder SOURCE or --synthetic SCENARIO (not both)")
    if synthetic is not None:
        seq = synthetic_sequence(synthetic, seed=seed, duration_s=duration_s, drop_fraction=drop_fraction,
                                 bad_fraction=bad_fraction)
    else:
        seq = load_sequence(source)
    doc = compare(seq, out)
    typer.echo((out / "compare.md").read_text())
    typer.echo(f"wrote {out / 'compare.md'}, {out / 'compare.json'}, {out / 'compare.png'} "
               f"({len(doc['backends'])} backends)")
