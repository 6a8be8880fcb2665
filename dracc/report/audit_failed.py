"""Tonight's reports when ``dracc audit`` ends without a verdict (exit 2, 3, 4, 5, 130).

The cron line of the README mails the ``--summary`` file whenever the exit code is not 0;
before issue 32 a run that failed left the files of an earlier night in place, and the
mail said "exit 4" over last night's "8 findings".  :func:`reports_on_failure` wraps a
run: when it raises (a :class:`~dracc.core.errors.DraccError`, an interrupt, a bug) the
``--summary``, ``--json`` and ``--html`` it was given are replaced, each atomically, by a
short document of the failure (:class:`~dracc.pipeline.audit.failed.FailedNight`: the
message, the exit code, the night and the time, the inputs named), and the error goes on
up to ``main`` as before.  A file that cannot be written is removed, so that an earlier
night's report is never taken for tonight's.

The audit document of a failed night is ``dracc.audit/1`` with ``status: "failed"`` and an
``error`` object (``audit.schema.json``); nothing is computed here.
"""

from __future__ import annotations

import html
import os
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path

from dracc import __version__
from dracc.core import atomic
from dracc.core.safetext import printable
from dracc.pipeline.audit.failed import FailedNight, failed_night
from dracc.report.audit_json import SCHEMA
from dracc.report.output import STDOUT, emit_json, json_text
from dracc.report.page import PAGE_END, page_head


def _inputs(f: FailedNight) -> list[tuple[str, str]]:
    logs = ", ".join(f.logs) if f.logs else "none"
    rows = [("logs", logs)]
    rows += [(k, v) for k, v in (("config", f.config), ("db", f.db)) if v is not None]
    return rows


def failed_summary(f: FailedNight) -> str:
    """The plain-text summary: the first line says why, the last the exit code (as the
    summary of an audited night ends)."""
    night = f.night or "not determined (the logs' own dates would have said it)"
    lines = [
        f"dracc audit: FAILED, exit {f.exit_code} ({f.kind}): {f.message}",
        f"night: {night}; vessel: {f.vessel or 'as configured'}",
        f"ended: {f.failed_utc}",
        *(f"{k}: {v}" for k, v in _inputs(f)),
        "no verdict for this night: nothing was checked or recorded; this summary "
        "replaces the report of an earlier night",
        f"exit {f.exit_code} ({f.kind})",
    ]
    return "\n".join(printable(line) for line in lines) + "\n"


def failed_document(f: FailedNight) -> dict:
    """The audit document of a failed night (``dracc.audit/1``, ``status: "failed"``)."""
    return {
        "schema": SCHEMA,
        "dracc_version": __version__,
        "status": "failed",
        "error": {
            "message": f.message,
            "exit_code": f.exit_code,
            "kind": f.kind,
            "type": f.error_type,
            "inputs": {"logs": list(f.logs), "config": f.config, "db": f.db},
        },
        "vessel": f.vessel,
        "night": f.night,
        "verdict": "failed",
        "exit_code": f.exit_code,
        "state": "not recorded",
        "audited_utc": f.failed_utc,
        "logs": {
            "files": list(f.logs),
            "lines": None,
            "rejected": None,
            "rejected_rate": None,
            "ignored": {},
            "period": {"start_utc": None, "end_utc": None},
        },
        "findings": [],
        "not_checked": [],
        "analysis": None,
    }


def failed_page(f: FailedNight) -> str:
    """The audit page of a failed night: the failure first, then what was asked."""
    e = html.escape
    rows = "".join(
        f"<tr><th>{e(k)}</th><td>{e(printable(v))}</td></tr>"
        for k, v in (
            ("night", f.night or "not determined"),
            ("vessel", f.vessel or "as configured"),
            ("ended", f.failed_utc),
            *_inputs(f),
        )
    )
    return (
        page_head(f"dracc audit: failed, exit {f.exit_code}", "th{text-align:left}")
        + f"\n<p id='verdict'><b>FAILED, exit {f.exit_code} ({e(f.kind)})</b>: "
        f"{e(printable(f.message))}</p>\n<table id='inputs'>{rows}</table>\n"
        "<p>No verdict for this night: nothing was checked or recorded. This page replaces "
        "the report of an earlier night.</p>\n" + PAGE_END
    )


def _write_or_remove(path: Path, render) -> None:
    """Write ``render()`` to ``path`` atomically; when that fails, remove ``path``."""
    try:
        atomic.write_text(path, render())
    except Exception:
        with suppress(OSError):
            os.unlink(path)


def write_failed_reports(
    f: FailedNight,
    *,
    summary: Path | None = None,
    json_out: str | Path | None = None,
    html_out: Path | None = None,
) -> None:
    """Replace each report given by the failure's (``--json -``: the document on stdout).
    SIGINT and SIGTERM wait for the end of the writes (milliseconds)."""
    with atomic.deferred_signals():
        if summary is not None:
            _write_or_remove(summary, lambda: failed_summary(f))
        if json_out is not None and str(json_out) == STDOUT:
            with suppress(OSError, ValueError):
                emit_json(failed_document(f), json_out)
        elif json_out is not None:
            _write_or_remove(Path(json_out), lambda: json_text(failed_document(f)))
        if html_out is not None:
            _write_or_remove(html_out, lambda: failed_page(f))


@dataclass(frozen=True)
class AuditRequest:
    """What ``dracc audit run`` was asked: the inputs and where tonight's reports go
    (``json_out`` may be ``-``, stdout).  One object for the run and its failure path."""

    logs: Sequence[Path]
    date: str | None = None
    vessel: str | None = None
    config: Path | None = None
    db: Path | None = None
    summary_out: Path | None = None
    json_out: str | Path | None = None
    html_out: Path | None = None


@contextmanager
def reports_on_failure(request: AuditRequest, signalled: dict | None = None) -> Iterator[None]:
    """Run the block; when it raises, write the failure's reports, then re-raise.
    ``signalled``: the CLI's flag that a signal asked the run to stop (an exception raised
    while unwinding from it is the interrupt)."""
    try:
        yield
    except (Exception, KeyboardInterrupt) as error:
        f = failed_night(
            error,
            logs=request.logs,
            date=request.date,
            vessel=request.vessel,
            config=request.config,
            db=request.db,
            signalled=bool(signalled and signalled.get("on")),
        )
        write_failed_reports(
            f, summary=request.summary_out, json_out=request.json_out, html_out=request.html_out
        )
        raise
