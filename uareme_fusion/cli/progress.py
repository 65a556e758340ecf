"""A rich progress bar fed by the pipeline's per-result callback: frames, fps, ETA when the length is known.

Its fps is the summary's (`RunStats.fps`): estimates per second since the run began, warm-up included."""

from __future__ import annotations

from contextlib import contextmanager

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

from .app import err_console


@contextmanager
def frame_progress(description: str, total: int | None):
    """Yields `on_result(result, stats)` that advances a progress bar on stderr.

    The bar appears with the first result, so a run that fails while it is being set up (a bad
    preset, normals the source cannot feed) prints its error line alone."""
    columns = [TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
               TextColumn("{task.fields[fps]:.1f} fps"), TimeElapsedColumn()]
    if total:
        columns.append(TimeRemainingColumn())
    progress = Progress(*columns, console=err_console, transient=False)
    task = progress.add_task(description, total=total or None, fps=0.0, start=False)
    started = False

    def on_result(result, stats):
        nonlocal started
        if not started:
            progress.start()
            progress.start_task(task)
            started = True
        progress.update(task, completed=stats.estimates, fps=stats.fps)

    try:
        yield on_result
    finally:
        if started:
            progress.stop()
