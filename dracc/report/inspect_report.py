"""``dracc inspect`` on the terminal: the inspection report (:mod:`dracc.ingest.inspect`)
as a sources table, every sentence type read and the account of the lines, tables of the
lines not used (rejected by reason, ignored by type), and the time-base decisions; laid
out by :mod:`dracc.report.textout`."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rich.console import Console

from dracc.core.safetext import printable
from dracc.math.clock import SourceClock
from dracc.report.json_report import clock_dict
from dracc.report.rows import clock_text
from dracc.report.textout import Layout, Page, layout

#: the sources table: name, right-aligned, priority (0: always shown; higher: left out
#: sooner on a narrow terminal, see :mod:`dracc.report.textout`)
_COLUMNS = (
    ("source", False, 0),
    ("role", False, 0),
    ("talkers", False, 3),
    ("sentences", False, 2),
    ("records", True, 1),
    ("rate Hz", True, 2),
    ("first UTC", False, 3),
    ("last UTC", False, 3),
    ("gaps", True, 1),
    ("max gap s", True, 2),
    ("dup", True, 2),
    ("back", True, 2),
)


#: what the sources table's rate is (dracc.ingest.inspect.rate_of_source)
RATE_NOTE = (
    "rate Hz: of each source's most frequent sentence type (rate_sentence in the JSON), "
    "its epoch rate where it sends each type once an epoch; not its sentences of all "
    "types a second"
)


def with_clocks(rep: dict[str, Any], clocks: Mapping[str, SourceClock]) -> dict[str, Any]:
    """The report with ``sources[KEY].clock`` (as in the analysis JSON) for every source."""
    for key, s in rep["sources"].items():
        s["clock"] = clock_dict(clocks.get(key))
    return rep


def render_inspection(
    rep: dict[str, Any], out: Console, clocks: Mapping[str, SourceClock] | None = None
) -> None:
    """The report of :func:`dracc.ingest.inspect.inspect_logs` as plain tables on ``out``,
    laid out for it (:mod:`dracc.report.textout`: natural width on a pipe, fewer columns
    on a narrow terminal, lines wrapped on spaces).  Every text from the log (source keys,
    talkers, sentence types, file names, rejected lines, notes) is shown as text, never
    markup, with its control characters escaped (:func:`dracc.core.safetext.printable`):
    a source key holding ESC sequences cannot command the terminal."""
    inspection_page(rep, layout(out), clocks).print(out)


def render_inspection_text(rep: dict[str, Any], width: int = 100, tty: bool = False) -> str:
    """The inspection as plain text laid out for ``width`` columns (``tty``: a terminal)."""
    return inspection_page(rep, Layout(width, tty)).text()


def inspection_page(
    rep: dict[str, Any], lay: Layout, clocks: Mapping[str, SourceClock] | None = None
) -> Page:
    """The inspection's lines laid out for ``lay`` (``clocks``: each source's clock)."""
    page = Page(lay)
    rows = [
        (
            key,
            s["role"] or "-",
            " ".join(s["talkers"]) or "-",
            " ".join(f"{k}:{v}" for k, v in s["sentences"].items()),
            str(s["records"]),
            f"{s['rate_hz']:.2f}" if s["rate_hz"] else "-",
            s["first_utc"] or "-",
            s["last_utc"] or "-",
            str(s["gaps"]),
            f"{s['max_gap_s']:.1f}",
            str(s["duplicates"]),
            str(s["backsteps"]),
        )
        for key, s in rep["sources"].items()
    ]
    headers, right, prio = zip(*_COLUMNS, strict=True)
    page.table(
        headers, rows, right=right, priorities=prio, title=f"sources ({rep['lines']} lines read)"
    )
    if any(s["rate_hz"] for s in rep["sources"].values()):
        page.wrapped(RATE_NOTE, hang=2)
    sent = rep.get("sentences") or {}
    if sent:
        page.wrapped("sentences read: " + " ".join(f"{k}:{v}" for k, v in sent.items()), hang=2)
    acc = rep.get("accounting")
    if acc:
        kinds = sorted({k for i in rep.get("inputs", []) for k in i.get("time_only") or {}})
        page.wrapped(_account(acc, kinds), hang=2)
    if rep["rejected"]:
        page.blank()
        page.table(
            ("reason", "count", "first examples (file:line text)"),
            _rejected(rep["rejected"], rep["rejected_examples"]),
            right=(False, True, False),
            priorities=(0, 0, 1),
            title="lines not used, by reason",
        )
        page.blank()
    ignored = rep.get("ignored") or {}
    if ignored:  # valid input dracc does not use: counts only (examples in the JSON)
        text = "ignored (valid, not used): " + " ".join(f"{k}:{v}" for k, v in ignored.items())
        page.wrapped(text, hang=2)
    tm = rep["time"]
    shared = tm.get("shared_stamps") or 0  # samples of a source faster than its stamps
    page.wrapped(
        f"time base: {tm['duplicates']} duplicates, {tm['backsteps']} back-steps, "
        f"{tm['gaps']} gaps, {tm['rollovers']} midnight rollovers, "
        f"{tm['implausible_dates']} implausible dates"
        + (f", {shared} records sharing a stamp (not duplicates)" if shared else ""),
        hang=2,
    )
    for d in tm["decisions"] + rep["notes"] + rep["roles"]:
        page.wrapped(f"  - {printable(d)}", hang=4)
    if clocks:
        page.wrapped("clocks (stamped after the instant described: late):", hang=2)
        for key in rep["sources"]:
            page.wrapped(f"  {printable(key)}: {clock_text(clocks.get(key))}", hang=4)
    return page


def _account(acc: dict[str, int], time_only: list[str]) -> str:
    """The account of the NMEA text lines in one sentence (``time_only``: the types of
    the time-only sentences)."""
    kinds = f" ({', '.join(time_only)})" if time_only else ""
    text = (
        f"{acc['lines']} lines = {acc['sentences']} sentences with records "
        f"+ {acc['time_only']} time-only{kinds} + {acc['ignored']} ignored "
        f"+ {acc['rejected']} rejected"
    )
    if acc.get("qualifiers"):
        text = text.replace(" ignored ", f" ignored + {acc['qualifiers']} qualifying others ", 1)
    if acc.get("n2k"):
        text = text.replace(" ignored ", f" ignored + {acc['n2k']} NMEA 2000 lines ", 1)
    if acc["shared"] > 0:
        text += f" - {acc['shared']} sentences sharing a line with another"
    elif acc["shared"] < 0:  # a reader counting a sentence nowhere: said, never hidden
        text += f" + {-acc['shared']} lines not accounted for"
    return text


def _rejected(
    counts: dict[str, int], examples: dict[str, list[dict[str, Any]]]
) -> list[tuple[str, str, str]]:
    """The rows of the rejected lines by reason, with the first two examples each (one
    example per line: the escapes keep a line's own CR/LF from breaking it up)."""
    return [
        (
            printable(reason),
            str(n),
            "\n".join(
                printable(f"{Path(e['file']).name}:{e['line']} {e['text'][:70]}")
                for e in examples.get(reason, [])[:2]
            ),
        )
        for reason, n in counts.items()
    ]
