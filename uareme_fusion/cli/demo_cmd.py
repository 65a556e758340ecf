"""`uareme-fusion demo`: built-in synthetic data through the method, no files needed."""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path
from typing import Optional

import typer

from .app import app, fail
from .progress import frame_progress


@app.command()
def demo(
    out: Optional[Path] = typer.Option(None, help="Folder for the demo's plot and overlay video (default: "
                                       "uareme-demo in the system's temporary folder, printed first)."),
    normals: str = typer.Option("learned", help="learned (the shipped network) or source (the simulator's exact normals)."),
    threads: Optional[int] = typer.Option(None, "--threads", min=1, max=256,
                                          help="torch CPU threads of the learned normals (default 1)."),
) -> None:
    """Run the method on built-in synthetic data and print what it gets right (about a minute)."""
    if out is not None and out.exists() and not out.is_dir():
        raise fail(f"--out {out} exists and is not a folder")
    if normals not in ("learned", "source"):
        raise fail(f"--normals {normals!r}: use learned or source")
    from ..demo import run_demo

    with ExitStack() as stack:
        def progress(scene, total):
            return stack.enter_context(frame_progress(f"demo {scene}", total))

        run_demo(out_dir=out, normals=normals, progress=progress, threads=threads)
