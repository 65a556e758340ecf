"""The typer application object and the error boundary of the command line.

Command modules (`uareme_fusion/cli/*_cmd.py`) register themselves on `app`; each parses its options
and calls one library function. The command group turns the project's errors (`UaremeError`, e.g. an
`InputError` for a bad file) into one red line on stderr and exit status 2, so a user mistake never
shows a traceback; Ctrl-C exits with 130 after the command's own cleanup ran.
"""

from __future__ import annotations

import typer
from rich.console import Console
from typer.core import TyperGroup

from ..errors import UaremeError

err_console = Console(stderr=True, highlight=False, soft_wrap=True)


def error_line(message: str) -> None:
    """Print one error line on stderr."""
    err_console.print(f"[bold red]error:[/] {message}", markup=True)


class _ErrorBoundaryGroup(TyperGroup):
    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except UaremeError as exc:
            error_line(str(exc).replace("[", r"\["))
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            err_console.print("[yellow]interrupted[/]")
            raise typer.Exit(130) from None


app = typer.Typer(
    name="uareme-fusion",
    cls=_ErrorBoundaryGroup,
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print one error line and return the Exit to raise: `raise fail("...")`."""
    error_line(message.replace("[", r"\["))
    return typer.Exit(code)


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


def main() -> None:
    """Console-script entry point."""
    app()
