"""The typer app and what every command shares: consoles, common options, progress."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from .. import __version__

app = typer.Typer(
    name="dracc",
    help="Voyage log analyser for ships: dead reckoning with honest 2M circles, "
    "INS accuracy from deviations from the mean of three, fix fusion and reports.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

#: data goes to stdout; messages, progress and errors to stderr
out = Console(soft_wrap=True)
err = Console(stderr=True, soft_wrap=True)

VERBOSE = {"on": False}

#: set by a command once everything it writes is written and closed: the process then ends
#: at once (see ``main._quick_exit``) instead of freeing a voyage's frames piece by piece
QUICK_EXIT = {"on": False}


def _version(value: bool) -> None:
    if value:
        typer.echo(f"dracc {__version__}")
        raise typer.Exit()


@app.callback()
def root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version and exit."),
    verbose: bool = typer.Option(False, "--verbose", "-v", help="Show tracebacks and debug messages on stderr."),
) -> None:
    """dracc: voyage log analyser for ships."""
    VERBOSE["on"] = verbose


# Shared option definitions (one place for help texts and names).
ConfigOption = typer.Option(None, "--config", "-c", exists=False, help="TOML configuration file (see README).")
LogsArgument = typer.Argument(..., help="Log files (NMEA text, CSV or MCAP); several files of one voyage merge by time.")


def progress_enabled() -> bool:
    """Progress bars only where a person watches stderr."""
    return err.is_terminal and not VERBOSE.get("quiet", False)


@contextmanager
def progress(description: str, total: float | None):
    """A rich progress bar on stderr (a no-op when stderr is not a terminal).

    Yields ``advance(n)``.
    """
    if not progress_enabled():
        yield lambda n=1: None
        return
    with Progress(TextColumn("{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                  TimeElapsedColumn(), console=err, transient=True) as bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)


def paths_exist(paths: list[Path]) -> list[Path]:
    """Check input paths up front so the user gets one clear line, not a traceback."""
    from ..errors import IngestError

    for p in paths:
        if not p.exists():
            raise IngestError(f"{p}: no such file")
    return paths


OptionalPath = Path | None
