"""`uareme-fusion batch SOURCE... --out DIR [--workers N] [--ray ADDRESS] [--resume]`: many recordings,
each run as `run` does into DIR/<name>/, one row each in DIR/batch.csv (`pipeline.batch`)."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from ..pipeline.batch import read_source_list, run_batch
from .app import StdoutConsole, app, err_console
from .run_cmd import _o, run_config


@app.command("batch")
def batch_command(
    sources: List[str] = typer.Argument(..., help="Sources as 'run' takes them, or @FILE: one source a line."),
    out: Path = typer.Option(..., "--out", help="Folder for DIR/<name>/ per source and DIR/batch.csv."),
    workers: Optional[int] = typer.Option(None, "--workers", min=1, max=1024,
                                          help="Worker processes (default: the number of cores)."),
    ray: Optional[str] = typer.Option(None, "--ray", help="Run on a Ray cluster: local (start one on this "
                                      "machine) or its address (auto, HOST:6379, ray://HOST:10001); needs the "
                                      "ray extra, and DIR on a folder every node sees."),
    resume: bool = typer.Option(False, "--resume", help="Skip the sources whose summary.json says their run "
                                "ended; run the others again."),
    force: bool = typer.Option(False, "--force", help="Replace the results of earlier runs in DIR/<name>/."),
    backend: Optional[str] = _o["backend"], normals: Optional[str] = _o["normals"],
    config: Optional[Path] = _o["config"], preset: Optional[str] = _o["preset"],
    max_frames: Optional[int] = _o["max_frames"], threads: Optional[int] = _o["threads"],
    offline: Optional[bool] = _o["offline"], cues: Optional[str] = _o["cues"],
) -> None:
    """Run many sources, each as 'run' does, on local processes or a Ray cluster; exit 1 when any failed."""
    cfg = run_config(config, backend=backend, normals=normals, mekf_preset=preset, max_frames=max_frames,
                     threads=threads, offline=offline, cues=cues)
    listed = read_source_list(sources)
    columns = (TextColumn("[bold]batch"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[failed]} failed"),
               TimeElapsedColumn())
    with Progress(*columns, console=err_console, transient=False) as bar:
        task = bar.add_task("batch", total=len(dict.fromkeys(listed)), failed=0)
        failed = 0

        def advance(row: dict) -> None:
            nonlocal failed
            failed += row["status"] != "ok"
            bar.update(task, advance=1, failed=failed)

        rows = run_batch(listed, out, cfg, workers=workers, ray_address=ray, resume=resume, force=force,
                         on_row=advance)
    print_batch_table(rows, out)
    if failed:
        raise typer.Exit(1)


def print_batch_table(rows: list[dict], out: Path) -> None:
    table = Table(title=f"batch: {len(rows)} sources into {out}")
    for column in ("source", "status", "frames", "fps", "wall s", "error"):
        table.add_column(column, overflow="fold")
    for row in rows:
        status = "[green]ok[/]" if row["status"] == "ok" else "[bold red]failed[/]"
        table.add_row(row["source"], status, str(row["frames"]), f"{row['fps']:.1f}", f"{row['wall_s']:.1f}",
                      row["error"].replace("[", r"\["))
    console = StdoutConsole()
    console.print(table)
    failed = sum(r["status"] != "ok" for r in rows)
    console.print(f"{len(rows) - failed} ok, {failed} failed; one row per source in {out / 'batch.csv'}",
                  markup=False, highlight=False)
