"""The typer app and what every command shares: consoles, root options, progress, typer's exits.
The option types and checks are in :mod:`dracc.cli.options`."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from dracc import __version__
from dracc.cli import forget_caught_interrupt, started
from dracc.core.errors import IngestError


def _click_exceptions() -> tuple[tuple[Any, ...], ...]:
    """The Exit/Abort/ClickException classes the CLI layer may raise: typer's own (typer >=
    0.20 vendors click and no longer installs it) and, for older typer, click's."""
    exits: list[Any] = [typer.Exit]
    aborts: list[Any] = [typer.Abort]
    errors: list[Any] = []
    try:
        import typer._click.exceptions as vendored

        errors.append(vendored.ClickException)
    except ImportError:
        pass
    try:
        import click.exceptions  # typer < 0.20 runs on click itself

        exits.append(click.exceptions.Exit)
        aborts.append(click.exceptions.Abort)
        errors.append(click.exceptions.ClickException)
    except ImportError:
        pass
    return tuple(exits), tuple(aborts), tuple(errors)


#: what typer raises for an exit, an abort (Ctrl-C at a prompt) and a usage error
EXIT, ABORT, CLICK_ERROR = _click_exceptions()


class _Typer(typer.Typer):
    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().__call__(*args, **kwargs)
        finally:  # interrupted or not: exit with the code main() says (see forget_caught_interrupt)
            forget_caught_interrupt()


app = _Typer(
    name="dracc",
    help="Voyage log analyser for ships: dead reckoning with honest 2M circles, "
    "INS accuracy from deviations from the mean of three, fix fusion and reports.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


class _Console(Console):
    """A rich console that prints the control characters of a text it is given (ESC, CR,
    C1 from a log's source keys or file names) as visible escapes (``\\x1b``); line breaks
    stay.  Renderables (Text, Table) are built with :func:`dracc.core.safetext.printable`."""

    def print(self, *objects: Any, **kwargs: Any) -> None:
        from dracc.core.safetext import printable

        super().print(
            *(printable(o, keep="\n") if isinstance(o, str) else o for o in objects), **kwargs
        )


#: data goes to stdout; messages, progress and errors to stderr.  Rich wraps, crops and
#: highlights nothing, and reads no ``:name:`` as an emoji (a vessel named ``:ship:`` stays
#: so): the commands lay their text out themselves (:mod:`dracc.report.textout`), on a
#: terminal at its width (asked at every print: a resized window is followed), on a pipe
#: or in a file with tables at their natural width and notes wrapped at ``$COLUMNS`` or 100
out = _Console(soft_wrap=True, emoji=False, highlight=False)
err = _Console(stderr=True, soft_wrap=True, emoji=False, highlight=False)

VERBOSE = {"on": False}

#: set by a command once everything it writes is written and closed: the process then ends
#: at once (:func:`dracc.cli.quick_exit`) instead of freeing a voyage's frames piece by piece
QUICK_EXIT = {"on": False}


def _version(value: bool) -> None:
    if value:
        typer.echo(f"dracc {__version__}")
        raise typer.Exit


@app.callback()
def root(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
    verbose: bool = typer.Option(
        False, "--verbose", "-v", help="Show tracebacks and debug messages on stderr."
    ),
) -> None:
    """dracc: voyage log analyser for ships."""
    VERBOSE["on"] = verbose
    started()


@contextmanager
def progress(description: str, total: float | None) -> Iterator[Callable[..., None]]:
    """A rich progress bar on stderr (a no-op when stderr is not a terminal); yields ``advance(n)``."""
    if not err.is_terminal or VERBOSE.get("quiet", False):  # only where a person watches
        yield lambda n=1: None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.percentage:>3.0f}%"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
    ) as bar:
        task = bar.add_task(description, total=total)
        yield lambda n=1: bar.advance(task, n)


@contextmanager
def staged_progress(
    description: str, weights: Mapping[str, float]
) -> Iterator[Callable[[str, float], None]]:
    """One bar for a job of named stages, each its share (``weights``, in their order) of
    100 %.  Yields ``on_progress(stage, fraction)``; the bar never goes back."""
    offsets, done = {}, 0.0
    for stage, weight in weights.items():
        offsets[stage], done = done, done + weight
    with progress(description, 100.0) as advance:
        state = {"done": 0.0}

        def on_progress(stage: str, fraction: float) -> None:
            target = offsets.get(stage, state["done"]) + weights.get(stage, 0.0) * min(
                max(fraction, 0.0), 1.0
            )
            if target > state["done"]:
                advance(target - state["done"])
                state["done"] = target

        yield on_progress


def paths_exist(paths: list[Path]) -> list[Path]:
    """Check input paths up front so the user gets one clear line, not a traceback."""
    for p in paths:
        if str(p) != "-" and not p.exists():  # '-': standard input
            raise IngestError(f"{p}: no such file")
    return paths
