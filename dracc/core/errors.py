"""The error tree and the documented exit codes.

Every error a user can cause is a :class:`DraccError`; the CLI catches it once,
prints ``error: <message>`` on stderr and exits with the error's code.
"""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    """Process exit codes; stable, documented in the README."""

    OK = 0  #: done, and (audit) everything within limits
    FINDINGS = 1  #: the audit found values outside the configured limits
    USAGE = 2  #: bad command line (unknown option, missing argument)
    INPUT = 3  #: input unreadable or holding no usable data
    CONFIG = 4  #: configuration file invalid
    INTERNAL = 5  #: a bug in dracc: please report it, with --verbose output
    OUTPUT = (
        6  #: an output cannot be written: disk full, read-only, not allowed, a folder in the way
    )
    INTERRUPTED = 130  #: stopped by Ctrl-C / SIGINT / SIGTERM; nothing partial written


class DraccError(Exception):
    """Root of every error dracc raises on purpose."""

    exit_code: ExitCode = ExitCode.INPUT


class IngestError(DraccError):
    """A log cannot be read (missing, not a log, damaged beyond use, --strict)."""

    exit_code = ExitCode.INPUT


class ConfigError(DraccError):
    """The configuration is invalid or contradicts the data."""

    exit_code = ExitCode.CONFIG


class OptionError(DraccError):
    """A bad value on the command line (exit 2, like any usage error): the message names
    the option and the value.  The CLI raises it for option values it checks itself and
    turns a :class:`ConfigError` raised while the options are read into it
    (:func:`dracc.cli.options.option_values`); a bad configuration *file* stays exit 4."""

    exit_code = ExitCode.USAGE


class InsufficientDataError(DraccError):
    """The log is readable but lacks what a computation needs."""

    exit_code = ExitCode.INPUT


class AmbiguousSourceError(ConfigError):
    """Roles cannot be assigned automatically; the message names the candidates."""


class GeometryError(DraccError):
    """Observations that cannot fix a position (too few, parallel, or inconsistent)."""

    exit_code = ExitCode.INPUT


class NoLogsError(IngestError):
    """A folder holds no log for the night: the night is recorded without data (exit 3)."""


class StateError(DraccError):
    """The state database cannot be opened or is not a dracc audit database."""


class FleetError(DraccError):
    """The batch cannot run (no logs found, scheduler unreachable, output unusable)."""


class FixUsageError(ConfigError):
    """A bad value on the ``dracc fix`` command line (exit 2, like any usage error)."""

    exit_code = ExitCode.USAGE


class FixFileError(ConfigError):
    """An invalid observation file (exit 4, like an invalid configuration file)."""

    exit_code = ExitCode.CONFIG


class OutputError(DraccError):
    """An output cannot be written: the disk is full, the folder read-only or not ours, a
    folder stands where a file is to go, or the reverse (exit 6).  Raised by
    :mod:`dracc.core.atomic` for every report, table and recording it writes; nothing
    partial is left (the temporary files are removed, the earlier outputs kept)."""

    exit_code = ExitCode.OUTPUT


class Interrupted(DraccError):
    """Ctrl-C or SIGTERM, with what a command knows about its outputs at that moment
    (``error: interrupted; …``, exit 130)."""

    exit_code = ExitCode.INTERRUPTED
