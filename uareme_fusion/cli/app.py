"""The typer application object and the error boundary of the command line.

Command modules (`uareme_fusion/cli/*_cmd.py`) register themselves on `app`; each parses its options
and calls one library function. `main()` turns the project's `InputError`s into one line on stderr
and exit status 2, so a user mistake never shows a traceback.
"""

from __future__ import annotations

import sys

import typer
from rich.console import Console

from ..errors import UaremeError

app = typer.Typer(
    name="uareme-fusion",
    help="Camera orientation and gravity from video of man-made scenes, fused with an IMU.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
err_console = Console(stderr=True)


def _print_version(value: bool) -> None:
    if value:
        from .. import __version__

        typer.echo(f"uareme-fusion {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_print_version, is_eager=True, help="Print the version."),
) -> None:
    """Camera orientation and gravity from video of man-made scenes, fused with an IMU."""


def fail(message: str, code: int = 2) -> "typer.Exit":
    """Print one error line and return the Exit to raise."""
    err_console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    return typer.Exit(code)


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except UaremeError as exc:
        err_console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print("[yellow]interrupted[/]")
        sys.exit(130)
