"""The typer app and what every command shares: consoles, common options, progress."""

from __future__ import annotations

import os
import signal
import sys

_STARTING = b"error: interrupted while starting; nothing was written\n"


def _exit_while_starting(signum, frame) -> None:
    """SIGTERM or SIGINT while the libraries load: nothing has been written, so the
    process ends here, at once, with the documented exit 130 and one line.  Raising
    KeyboardInterrupt in the middle of an import is not reliable: importlib may swallow
    it ("Exception ignored in ... _ModuleLock"), and the run goes on as if no signal had
    come; the default action for SIGTERM ends the process with 143."""
    try:
        os.write(2, _STARTING)
    finally:
        os._exit(130)


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def cli_process() -> bool:
    """True in the ``dracc`` process itself (the ``dracc`` script, ``python -m dracc``),
    False where a program (a test, a notebook) imports the CLI."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    if spec is not None:
        return spec.name in ("dracc", "dracc.__main__")
    return os.path.basename(sys.argv[0] if sys.argv else "") in ("dracc", "dracc.exe")


# The first thing the CLI does, before the libraries load (about a second on a busy
# machine): a SIGTERM there used to kill the process by the signal (exit 143).  Once the
# command starts (``root`` below), Ctrl-C raises KeyboardInterrupt again and SIGTERM
# does the same (``main`` installs its handler), so that temporary files and open
# transactions are cleaned up.
if cli_process() and signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
    signal.signal(signal.SIGTERM, _exit_while_starting)
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _exit_while_starting)


def started() -> None:
    """The command starts: signals unwind (KeyboardInterrupt) from here on."""
    if signal.getsignal(signal.SIGINT) is _exit_while_starting:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGTERM) is _exit_while_starting:
        signal.signal(signal.SIGTERM, _raise_interrupt)


def forget_caught_interrupt() -> None:
    """CPython (3.11) remembers a KeyboardInterrupt that left an ``eval`` of a string
    (``collections.namedtuple`` builds classes so, in many imports) as unhandled even
    when dracc caught it afterwards, and then ends the process by SIGINT (exit -2)
    whatever exit code ``sys.exit`` gave.  Every ``eval`` of a string starts by clearing
    that memory: this one does only that."""
    eval("None")  # noqa: S307 - a constant: clears CPython's "unhandled interrupt" flag


import datetime as dt  # noqa: E402
import functools  # noqa: E402
import re  # noqa: E402
from collections.abc import Iterable, Iterator  # noqa: E402
from contextlib import contextmanager  # noqa: E402
from pathlib import Path, PurePath  # noqa: E402

import typer  # noqa: E402
from rich.console import Console  # noqa: E402
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn  # noqa: E402

from dracc import __version__  # noqa: E402
from dracc.core.errors import ConfigError, OptionError  # noqa: E402


class _Typer(typer.Typer):
    def __call__(self, *args, **kwargs):
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
    """A rich console that never sends a control character it was given in a text to the
    terminal: ESC (colours, cursor moves, OSC titles), CR, backspace, C1 controls from a
    log's source keys or file names are printed as visible escapes (``\\x1b``); line
    breaks stay.  Rich's own styling is added after this, at rendering.  Renderables
    (Text, Table) are built with :func:`dracc.core.safetext.printable` where they are made."""

    def print(self, *objects, **kwargs) -> None:
        from dracc.core.safetext import printable

        super().print(
            *(printable(o, keep="\n") if isinstance(o, str) else o for o in objects), **kwargs
        )


#: data goes to stdout; messages, progress and errors to stderr
out = _Console(soft_wrap=True)
err = _Console(stderr=True, soft_wrap=True)

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


# Shared option definitions (one place for help texts and names).
ConfigOption = typer.Option(
    None, "--config", "-c", exists=False, help="TOML configuration file (see README)."
)
LogsArgument = typer.Argument(
    ..., help="Log files (NMEA text, CSV or MCAP); several files of one voyage merge by time."
)


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


def paths_exist(paths: list[Path]) -> list[Path]:
    """Check input paths up front so the user gets one clear line, not a traceback."""
    from dracc.core.errors import IngestError

    for p in paths:
        if not p.exists():
            raise IngestError(f"{p}: no such file")
    return paths


OptionalPath = Path | None


# ------------------------------------------------------------- bad option values: exit 2
#
# A value given on the command line that dracc cannot use is a usage error (exit 2,
# README "Exit codes"), whichever check finds it: typer's own types and ranges (a click
# usage error), a check of the CLI below (OptionError), or the validation of the
# configuration the options were merged into (ConfigError, turned into OptionError by
# option_values).  A bad configuration file stays exit 4, unreadable input exit 3.


@contextmanager
def option_values() -> Iterator[None]:
    """Read the command-line option values inside this block: a :class:`ConfigError`
    raised here names a bad option value and becomes an :class:`OptionError` (exit 2).
    Load the configuration file before the block (its errors stay exit 4)."""
    try:
        yield
    except ConfigError as e:
        raise OptionError(str(e)) from e


def options_only(command):
    """Decorator for a command that reads no configuration file (``simulate``): every
    :class:`ConfigError` it raises comes from its options, a usage error (exit 2)."""

    @functools.wraps(command)
    def run(*args, **kwargs):
        with option_values():
            return command(*args, **kwargs)

    return run


def check_choice(
    value: str | None, known: Iterable[str], option: str, none_known: str = "nothing to choose from"
) -> str | None:
    """``value`` if it is one of ``known`` (or None); else an OptionError listing them
    (``none_known`` says why the list is empty)."""
    known = list(known)
    if value is None or value in known:
        return value
    if not known:
        raise OptionError(f"{option} {value!r}: {none_known}")
    raise OptionError(f"{option} {value!r}: expected one of {', '.join(known)}")


def check_date(value: str | None, option: str = "--date") -> str | None:
    """A calendar date ``YYYY-MM-DD`` (or None); else an OptionError."""
    if value is None:
        return None
    try:
        if not re.fullmatch(r"\d{4}-\d{2}-\d{2}", value.strip()):
            raise ValueError
        return dt.date.fromisoformat(value.strip()).isoformat()
    except ValueError:
        raise OptionError(f"{option} {value!r}: expected a date YYYY-MM-DD") from None


def check_pattern(value: str | None, option: str = "--pattern") -> str | None:
    """A relative glob for the files inside a folder (``*.nmea``, ``**/*.nmea``) or None."""
    if value is None:
        return None
    if not value.strip() or PurePath(value).is_absolute() or PurePath(value).drive:
        raise OptionError(
            f"{option} {value!r}: expected a glob relative to the folder, "
            "e.g. '*.nmea' or '**/*.nmea'"
        )
    return value
