"""Entry point: ``dracc``.  Catches :class:`DraccError` once and maps it to an exit code."""

from __future__ import annotations

import signal
import sys
import traceback

try:  # Ctrl-C while the libraries load (seconds on a busy machine): one line, no traceback
    from dracc.cli import SIGNALLED, quick_exit, raise_interrupt
    from dracc.cli.app import ABORT, CLICK_ERROR, EXIT, QUICK_EXIT, VERBOSE, app, err
    from dracc.core.errors import DraccError, ExitCode

    # Commands register themselves on ``app`` when imported.
    from dracc.cli import inspect_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import simulate_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import analyze_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import audit_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import fleet_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import fix_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import records_cmd  # noqa: F401,E402  isort: skip
    from dracc.cli import watch_cmd  # noqa: F401,E402  isort: skip
except KeyboardInterrupt:
    sys.stderr.write("error: interrupted while starting; nothing was written\n")
    sys.exit(130)


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; return (and exit with) a documented :class:`ExitCode`."""
    args = sys.argv[1:] if argv is None else list(argv)
    VERBOSE["on"] = "--verbose" in args or "-v" in args
    if argv is None:  # the real process: a kill (SIGTERM) unwinds like Ctrl-C, nothing partial
        signal.signal(signal.SIGTERM, raise_interrupt)
    code = _run(args)
    if argv is None:
        if QUICK_EXIT["on"] and code == ExitCode.OK:
            quick_exit(code)
        if code != ExitCode.OK:
            # a failed run has unwound (atomic writes rolled back, the one line said) and
            # has nothing left to do; the interpreter's shutdown would only race the native
            # libraries' worker threads: pyarrow's I/O thread dropping the last reference to
            # a CSV reader takes the GIL to free its Python row handler, and a thread that
            # takes the GIL while the interpreter finalizes is ended by pthread_exit, whose
            # unwinding through C++ is std::terminate (SIGABRT, exit 134, 2 runs in 90 of
            # a CSV that failed at once, on a loaded machine).  The same holds for a library
            # cut off in its module init by an interrupt (exit -6).  End here, with the code.
            quick_exit(code)
        sys.exit(int(code))
    return int(code)


def _run(args: list[str]) -> int:
    try:
        result = app(args=args, prog_name="dracc", standalone_mode=False)
        if result == ExitCode.INTERRUPTED:  # typer turns KeyboardInterrupt into a silent 130
            raise KeyboardInterrupt
        return int(result) if isinstance(result, int) else ExitCode.OK
    except EXIT as e:
        return int(e.exit_code)
    except ABORT:
        err.print("error: interrupted", style="red", highlight=False)
        return ExitCode.INTERRUPTED
    except CLICK_ERROR as e:
        e.show()
        return ExitCode.USAGE
    except DraccError as e:
        if VERBOSE["on"]:
            traceback.print_exc()
        err.print(f"error: {e}", style="red", highlight=False, markup=False)
        return int(e.exit_code)
    except KeyboardInterrupt:
        err.print("error: interrupted; nothing partial was written", style="red", highlight=False)
        return ExitCode.INTERRUPTED
    except BrokenPipeError:
        return ExitCode.OK
    except Exception as e:  # a bug: one line unless --verbose
        if SIGNALLED["on"]:  # the interrupt, turned into another exception on its way up
            err.print(
                "error: interrupted; nothing partial was written", style="red", highlight=False
            )
            return ExitCode.INTERRUPTED
        if VERBOSE["on"]:
            traceback.print_exc()
        err.print(
            f"error: internal error ({type(e).__name__}: {e}); run with --verbose and report it",
            style="red",
            highlight=False,
            markup=False,
        )
        return ExitCode.INTERNAL


if __name__ == "__main__":  # pragma: no cover
    main()
