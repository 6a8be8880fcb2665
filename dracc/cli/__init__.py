"""The command-line interface: a thin typer layer over :mod:`dracc.pipeline.analysis` and friends.

Importing this package prepares the process before any library loads: one BLAS thread,
and what a signal does while the libraries load (:func:`started` ends that); and how
the process ends after a command that wrote everything (:func:`quick_exit`).  The typer
app is in :mod:`dracc.cli.app`, the entry point in :mod:`dracc.cli.main`, the shared
options in :mod:`dracc.cli.options`, each command in ``*_cmd.py``.
"""

import os
import signal
import sys
from types import FrameType

# dracc's linear algebra is small (2x2 and 3x3 covariances, normal equations of a few dozen
# unknowns), so one BLAS thread does it.  Idle OpenBLAS threads spin after each call: on
# a day's log they burnt 0.4 s of CPU that the ingest workers needed (bench_analyze.py).
# Read when numpy loads, so set here, before any command imports it; a user's value wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

_STARTING = b"error: interrupted while starting; nothing was written\n"


def _exit_while_starting(signum: int, frame: FrameType | None) -> None:
    """SIGTERM or SIGINT while the libraries load: nothing has been written, so the
    process ends here, at once, with the documented exit 130 and one line.  Raising
    KeyboardInterrupt in the middle of an import is not reliable: importlib may swallow
    it ("Exception ignored in ... _ModuleLock"), and the run goes on as if no signal had
    come; the default action for SIGTERM ends the process with 143."""
    try:
        os.write(2, _STARTING)
    finally:
        os._exit(130)


#: set when a signal has asked the run to stop: an exception raised by the unwinding
#: (a C extension's module init turns the KeyboardInterrupt into "ImportError:
#: initialization failed") is then the interrupt, not a bug
SIGNALLED = {"on": False}


def raise_interrupt(signum: int, frame: FrameType | None) -> None:
    """Signal handler (SIGTERM once started): unwind like Ctrl-C, so that atomic writes
    and transactions roll back."""
    SIGNALLED["on"] = True
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
# command starts (``dracc.cli.app.root``), Ctrl-C raises KeyboardInterrupt again and
# SIGTERM does the same (``main`` installs its handler), so that temporary files and open
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
        signal.signal(signal.SIGTERM, raise_interrupt)


def forget_caught_interrupt() -> None:
    """CPython (3.11) remembers a KeyboardInterrupt that left an ``eval`` of a string
    (``collections.namedtuple`` builds classes so, in many imports) as unhandled even
    when dracc caught it afterwards, and then ends the process by SIGINT (exit -2)
    whatever exit code ``sys.exit`` gave.  Every ``eval`` of a string starts by clearing
    that memory: this one does only that."""
    eval("None")  # noqa: S307 - a constant: clears CPython's "unhandled interrupt" flag


def quick_exit(code: int) -> None:
    """End the process now.  The command has written, closed and renamed everything; what
    normal interpreter shutdown would add is freeing the frames of a voyage object by
    object and running exit hooks with nothing left to do: 0.1-0.3 s after a day's log
    (benchmarks/bench_analyze.py).  Only the standard streams need flushing; a SIGINT or
    SIGTERM is held from here (in the shutdown it was exit 143 without a word, issue 33)."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing more can be said
            pass
    os._exit(int(code))
