"""The typer application object and the error boundary of the command line.

Command modules (`uareme_fusion/cli/*_cmd.py`) register themselves on `app`; each parses its options
and calls one library function. The command group turns the project's errors (`UaremeError`, e.g. an
`InputError` for a bad file), command-line usage errors (a bad option value, a missing argument) and
`OSError`s (a path that cannot be read or written) into one red line on stderr and exit status 2, so
a user mistake never shows a traceback. A file that cannot be written (`OutputError`: disk full,
I/O error) exits 1, a failing environment. Ctrl-C, SIGTERM and SIGHUP stop a command the same way
(`pipeline.stop_signals`) and exit with 128 + the signal number after the command's own cleanup ran.
A standard output closed early (`| head`) is not an error: the files are complete, the exit is 0.
"""

from __future__ import annotations

import os
import sys

import typer
from rich.console import Console
from typer.core import TyperGroup

from ..errors import OutputError, UaremeError
from ..io.safe_files import ENVIRONMENT_ERRNOS
from ..pipeline import stop_signals

err_console = Console(stderr=True, highlight=False, soft_wrap=True)


class StdoutConsole(Console):
    """rich's Console on stdout, except that a reader that went away (`| head`) silences it instead
    of exiting 1 (rich's default): what a command prints there is a report, its files are the result."""

    def on_broken_pipe(self) -> None:
        _silence_stdout()


def error_line(message: str) -> None:
    """Print one error line on stderr."""
    err_console.print(f"[bold red]error:[/] {message}", markup=True, emoji=False)


# Usage errors from the copy of click that recent typer versions carry inside, and from click itself
# when it is installed (older typer versions use it; it is not a dependency of this package).
try:
    import click

    _USAGE_ERRORS = tuple({click.UsageError, typer.BadParameter.__base__})
except ImportError:
    _USAGE_ERRORS = (typer.BadParameter.__base__,)


def _usage_error_line(exc) -> None:
    """One line for a command-line mistake (bad option value, missing argument, unknown command)."""
    where = exc.ctx.command_path if exc.ctx is not None else "uareme-fusion"
    error_line(f"{exc.format_message()} (see '{where} --help')".replace("[", r"\["))


class _ErrorBoundaryGroup(TyperGroup):
    def make_context(self, info_name, args, parent=None, **extra):
        try:
            return super().make_context(info_name, args, parent=parent, **extra)
        except _USAGE_ERRORS as exc:  # options of the group itself
            _usage_error_line(exc)
            raise typer.Exit(2) from None

    def invoke(self, ctx):
        try:
            with stop_signals.handle_stop_signals():
                return super().invoke(ctx)
        except OutputError as exc:
            error_line(str(exc).replace("[", r"\["))
            raise typer.Exit(1) from None
        except BrokenPipeError:
            _silence_stdout()
            raise typer.Exit(0) from None
        except UaremeError as exc:
            error_line(str(exc).replace("[", r"\["))
            raise typer.Exit(2) from None
        except _USAGE_ERRORS as exc:  # typer's own parsing and typer.BadParameter
            _usage_error_line(exc)
            raise typer.Exit(2) from None
        except OSError as exc:  # a path the user gave that cannot be read or written
            where = f"{exc.filename}: " if exc.filename else ""
            error_line(f"{where}{exc.strerror or exc}".replace("[", r"\["))
            raise typer.Exit(1 if exc.errno in ENVIRONMENT_ERRNOS else 2) from None
        except KeyboardInterrupt as exc:
            err_console.print(f"[yellow]{stop_signals.describe(exc)}[/]")
            raise typer.Exit(stop_signals.exit_code(exc)) from None


def _silence_stdout() -> None:
    """Point stdout at /dev/null, so the interpreter's last flush cannot fail again (Python's advice
    for SIGPIPE: https://docs.python.org/3/library/signal.html#note-on-sigpipe)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _flags_without_type(option_class) -> None:
    """Help without `<bool>` beside on/off flags (`--panes`, `--help`): typer's rich help prints a
    type for every option, and a flag takes no value."""
    show_type = option_class.display_type_rich

    def display_type_rich(self, ctx):
        return None if getattr(self, "is_flag", False) else show_type(self, ctx)

    option_class.display_type_rich = display_type_rich


try:  # the option class of recent typer versions; older ones print no type for flags
    from typer.core import TyperOption

    if hasattr(TyperOption, "display_type_rich"):
        _flags_without_type(TyperOption)
except ImportError:
    pass


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
    try:
        app()
    finally:
        try:
            sys.stdout.flush()
        except BrokenPipeError:  # a reader that went away (`| head -c 0`): the files are complete
            _silence_stdout()
