"""A night whose audit did not run to its end: what the reports say instead.

``dracc audit`` runs from cron, whose line mails the summary file when the exit code is
not 0.  Every exit path therefore leaves tonight's reports: a run that ends with a
configuration error (exit 4), with logs that hold nothing usable (exit 3), a usage error
found while running (exit 2), an internal error (exit 5), a report that cannot be
written (exit 6: the disk full, the folder read-only) or an interrupt (SIGINT or SIGTERM,
exit 130) is described by a :class:`FailedNight` (the error's message, the exit
code, the night and the time, the inputs named), which :mod:`dracc.report.audit_failed`
renders as a short summary, audit document and page.
"""

from __future__ import annotations

import datetime as dt
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from dracc.core.errors import DraccError, ExitCode
from dracc.pipeline.audit.logs import yesterday_utc

#: the kind of failure per exit code (the words of the summary's first line)
KINDS = {
    ExitCode.USAGE: "usage error",
    ExitCode.INPUT: "no usable data",
    ExitCode.CONFIG: "configuration error",
    ExitCode.INTERNAL: "internal error",
    ExitCode.OUTPUT: "output error",
    ExitCode.INTERRUPTED: "interrupted",
}


@dataclass(frozen=True)
class FailedNight:
    """Why tonight's audit ended without a verdict, and what it was asked to audit."""

    message: str  #: the error, as ``error: …`` on stderr says it
    exit_code: int  #: the process's exit code (2, 3, 4, 5, 6 or 130)
    kind: str  #: :data:`KINDS` of the exit code
    error_type: str  #: the exception's class name (``ConfigError``, ``KeyboardInterrupt``)
    night: str | None  #: YYYY-MM-DD, None when the logs' own dates would have said it
    vessel: str | None  #: ``--vessel``, None when the configuration would have said it
    failed_utc: str  #: when the run ended, ISO 8601 with ``Z``
    logs: tuple[str, ...]  #: the log files and folders named on the command line
    config: str | None  #: ``--config``
    db: str | None  #: ``--db``


def exit_code_of(error: BaseException, signalled: bool = False) -> ExitCode:
    """The exit code ``dracc.cli.main`` gives for ``error``."""
    if isinstance(error, KeyboardInterrupt) or signalled:
        return ExitCode.INTERRUPTED
    if isinstance(error, DraccError):
        return ExitCode(error.exit_code)
    return ExitCode.INTERNAL


def _night(date: str | None, logs: Sequence[Path], now: dt.datetime) -> str | None:
    if date:
        try:
            return dt.date.fromisoformat(date).isoformat()
        except ValueError:
            return None
    if any(Path(p).is_dir() for p in logs):  # as run_audit: a folder audits yesterday
        return yesterday_utc(now)
    return None


def failed_night(
    error: BaseException,
    *,
    logs: Sequence[Path],
    date: str | None = None,
    vessel: str | None = None,
    config: Path | None = None,
    db: Path | None = None,
    signalled: bool = False,
    now: dt.datetime | None = None,
) -> FailedNight:
    """Describe a run of ``dracc audit`` that ended with ``error``."""
    now = now or dt.datetime.now(dt.timezone.utc)
    code = exit_code_of(error, signalled)
    if code == ExitCode.INTERRUPTED:
        signal_text = str(error)  # "signal 15" from the SIGTERM handler, "" for Ctrl-C
        message = f"interrupted ({signal_text})" if signal_text else "interrupted"
    elif code == ExitCode.INTERNAL:
        message = f"internal error ({type(error).__name__}: {error})"
    else:
        message = str(error) or type(error).__name__
    return FailedNight(
        message=message,
        exit_code=int(code),
        kind=KINDS.get(code, "error"),
        error_type=type(error).__name__,
        night=_night(date, logs, now),
        vessel=vessel,
        failed_utc=now.strftime("%Y-%m-%dT%H:%M:%SZ"),
        logs=tuple(os.path.abspath(p) for p in logs),
        config=None if config is None else os.path.abspath(config),
        db=None if db is None else os.path.abspath(db),
    )
