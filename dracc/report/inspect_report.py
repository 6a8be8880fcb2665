"""``dracc inspect`` on the terminal: the inspection report (:mod:`dracc.ingest.inspect`)
as a sources table, every sentence type read and the account of the lines, tables of the
lines not used (rejected by reason, ignored by type), and the time-base decisions."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table
from rich.text import Text

from dracc.core.safetext import printable


def render_inspection(rep: dict[str, Any], out: Console) -> None:
    """The report of :func:`dracc.ingest.inspect.inspect_logs` as rich tables on ``out``.  Every text from the log (source keys, talkers, sentence
    types, file names, rejected lines, notes) is shown as Text, never markup, with its
    control characters escaped (:func:`dracc.core.safetext.printable`): a source key
    holding ESC sequences cannot command the terminal."""

    def cell(x: object) -> Text:
        return Text(printable(x))

    t = Table(title=f"sources ({rep['lines']} lines read)")
    for c in (
        "source",
        "role",
        "talkers",
        "sentences",
        "records",
        "rate Hz",
        "first UTC",
        "last UTC",
        "gaps",
        "max gap s",
        "dup",
        "back",
    ):
        t.add_column(
            c,
            justify="right"
            if c in ("records", "rate Hz", "gaps", "max gap s", "dup", "back")
            else "left",
        )
    for key, s in rep["sources"].items():
        t.add_row(
            *(
                cell(x)
                for x in (
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
            )
        )
    out.print(t)
    sent = rep.get("sentences") or {}
    if sent:
        out.print(
            cell("sentences read: " + " ".join(f"{k}:{v}" for k, v in sent.items())),
            highlight=False,
        )
    acc = rep.get("accounting")
    if acc:
        kinds = sorted({k for i in rep.get("inputs", []) for k in i.get("time_only") or {}})
        out.print(cell(_account(acc, kinds)), highlight=False)
    if rep["rejected"]:
        out.print(_rejected(rep["rejected"], rep["rejected_examples"]))
    ignored = rep.get("ignored") or {}
    if ignored:  # valid input dracc does not use: counts only (examples in the JSON)
        out.print(
            cell("ignored (valid, not used): " + " ".join(f"{k}:{v}" for k, v in ignored.items())),
            highlight=False,
        )
    tm = rep["time"]
    out.print(
        f"time base: {tm['duplicates']} duplicates, {tm['backsteps']} back-steps, {tm['gaps']} gaps, "
        f"{tm['rollovers']} midnight rollovers, {tm['implausible_dates']} implausible dates",
        highlight=False,
        markup=False,
    )
    for d in tm["decisions"] + rep["notes"] + rep["roles"]:
        out.print(cell(f"  - {d}"), highlight=False)


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
    if acc["shared"] > 0:
        text += f" - {acc['shared']} sentences sharing a line with another"
    elif acc["shared"] < 0:  # a reader counting a sentence nowhere: said, never hidden
        text += f" + {-acc['shared']} lines not accounted for"
    return text


def _rejected(counts: dict[str, int], examples: dict[str, list[dict[str, Any]]]) -> Table:
    """The rejected lines by reason, with the first two examples each."""
    r = Table(title="lines not used, by reason")
    for c in ("reason", "count", "first examples (file:line text)"):
        r.add_column(c)
    for reason, n in counts.items():
        ex = examples.get(reason, [])[:2]
        # one example per line: the escapes keep a line's own CR/LF from breaking it up
        r.add_row(
            Text(printable(reason)),
            Text(str(n)),
            Text(
                "\n".join(
                    printable(f"{Path(e['file']).name}:{e['line']} {e['text'][:70]}") for e in ex
                )
            ),
        )
    return r
