"""The live terminal view of ``dracc watch`` (when stdout is a TTY): the
``dracc.watch/2`` status document drawn with rich, redrawn at each status period.

One screen, read at a glance: a head line (since when, lines heard, dropped, the file
being recorded), the open findings first (a bridge wants the bad news on top), the
sources (role, records, lines a second, age, latency; a silent one marked), the DR from
the last fix with its 2M against GNSS, and the worst INS unit per channel of the
deviation statistics.
Only the status dict is read: the view has no state of its own.
"""

from __future__ import annotations

from typing import Any

from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.table import Table
from rich.text import Text

from dracc.core.safetext import printable
from dracc.ingest.live.sources import KERNEL_DROPPED

#: channels of the deviation statistics as the view names them, with their unit
_CHANNELS = {"lat": ("latitude", "m"), "lon": ("longitude", "m"), "course": ("course", "°")}


def _num(x: Any, digits: int = 1, unit: str = "") -> str:
    if x is None:
        return "-"
    return f"{x:.{digits}f}{(' ' + unit) if unit else ''}"


def _head(st: dict[str, Any]) -> Text:
    dropped = sum(st.get("dropped", {}).values())
    t = Text()
    t.append("dracc watch", style="bold")
    t.append(f"  since {st['started_utc']}  now {st['now_utc']}  ")
    t.append(f"{st['received']:,} lines heard")
    t.append(f", {dropped:,} dropped" if dropped else "", style="yellow")
    kernel = st.get("dropped", {}).get(KERNEL_DROPPED, 0)
    if kernel:  # not dracc's choice: the machine could not keep up
        t.append(f" ({kernel:,} by the kernel: its receive buffer was full)", style="bold red")
    if st.get("recording"):
        t.append(f"  recording {printable(st['recording'])}")
    return t


def _findings(st: dict[str, Any]) -> RenderableType:
    open_ = [f for f in st["findings"] if f.get("cleared_utc") is None]
    if not open_:
        cleared = len(st["findings"])
        return Text(
            "no open findings" + (f" ({cleared} cleared)" if cleared else ""), style="green"
        )
    table = Table(title=f"{len(open_)} open finding(s)", title_justify="left", expand=False)
    for col in ("raised", "check", "source", "finding"):
        table.add_column(col, overflow="fold")
    for f in open_:
        check = f["check"] + (f"/{f['name']}" if f.get("name") else "")
        table.add_row(
            f["raised_utc"][11:19],
            check,
            printable(str(f.get("source") or "-")),
            printable(f["message"] + _consequences(f)),
            style="red",
        )
    return table


def _consequences(f: dict[str, Any]) -> str:
    """The checks a finding caused, named after its message ('' without any)."""
    under = f.get("consequences") or ()
    said = "; ".join(f"{c['check']}/{c['name']} {c.get('source') or ''}".rstrip() for c in under)
    return f" (consequences: {said})" if said else ""


def _sources(st: dict[str, Any]) -> Table:
    table = Table(title="sources", title_justify="left")
    for col, right in (
        ("source", False),
        ("role", False),
        ("records", True),
        ("lines/s", True),
        ("age s", True),
        ("latency s", True),
    ):
        table.add_column(col, justify="right" if right else "left")
    silent = {
        f["source"] for f in st["findings"] if f.get("name") == "dropout" and not f["cleared_utc"]
    }
    for key, s in st["sources"].items():
        table.add_row(
            printable(key),
            s.get("role") or "-",
            f"{s['records']:,}",
            _num(s["lines_per_s"], 2),
            _num(s["age_s"], 1),
            _num(s.get("latency_s"), 3),
            style="red" if key in silent else None,
        )
    return table


def _dr(st: dict[str, Any]) -> Text:
    dr = st.get("dead_reckoning")
    if dr is None:
        why = (st.get("analysis") or {}).get("error") or "waiting for the first analysis"
        return Text(f"dead reckoning: {why}", style="dim")
    t = Text("dead reckoning: ", style="bold")
    t.append(
        f"{dr['epoch_utc'][11:19]}  {_num(dr['since_fix_s'], 0, 's')} since the fix "
        f"({dr.get('fix_source') or '-'}), 2M {_num(dr['radius_2m_m'], 0, 'm')}"
    )
    if dr.get("error_m") is not None:
        inside = dr.get("inside_2m")
        t.append(
            f", {dr['reference']} {_num(dr['error_m'], 0, 'm')} away "
            f"({'inside' if inside else 'OUTSIDE'})",
            style=None if inside else "red",
        )
    t.append(f"\n  window: {printable(dr['verdict'])}")
    return t


def _deviation(st: dict[str, Any]) -> Text:
    dev = st.get("deviation")
    if not dev:
        return Text("INS deviations: no two INS units sampled yet (hourly)", style="dim")
    t = Text("INS deviations: ", style="bold")
    t.append(f"{dev['samples']} hourly sample(s) of {', '.join(dev['units'])}; largest m_u:")
    for ch, (name, unit) in _CHANNELS.items():
        rows = [r for r in dev["channels"] if r["channel"] == ch and r["m_u"] is not None]
        if rows:
            worst = max(rows, key=lambda r: r["m_u"])
            digits = 3 if ch == "course" else 0
            t.append(f"  {name} {worst['ins_unit']} {_num(worst['m_u'], digits, unit)}")
    return t


def status_view(st: dict[str, Any]) -> Group:
    """The whole screen for one status document."""
    return Group(_head(st), _findings(st), _sources(st), _dr(st), _deviation(st))


def finding_line(f: dict[str, Any]) -> str:
    """One line for a finding raised or cleared (stderr: journald, a pipe)."""
    name = f"/{f['name']}" if f.get("name") else ""
    when = f["cleared_utc"] or f["raised_utc"]
    return printable(f"{when} {f['check']}{name} {f['event']}: {f['message']}{_consequences(f)}")


class LiveView:
    """The status drawn on the terminal (stdout), redrawn by :meth:`show` (no thread)."""

    def __init__(self) -> None:
        self.live = Live(console=Console(), auto_refresh=False, transient=False)
        self.live.start()

    def show(self, st: dict[str, Any]) -> None:
        self.live.update(status_view(st), refresh=True)

    def stop(self) -> None:
        self.live.stop()
