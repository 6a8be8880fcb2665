"""The short rich summary ``dracc analyze`` prints on the terminal.

Sections, in the order a navigator reads them: period and inputs, sources and
rejects, dead-reckoning consistency, the per-unit table, calibration, current, and
what is missing.  Text from the logs (source keys, file names, and the notes and
messages that quote them) is printed with rich markup disabled, so a log cannot style
the terminal, and with every control character shown as an escape
(:func:`dracc.core.safetext.printable`: ESC as ``\\x1b``), so a log cannot send the
terminal a command.  Every text of the summary goes through :func:`_text`.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import IO, Any, cast

import numpy as np
from rich.console import Console, Group, JustifyMethod, RenderableType
from rich.table import Table
from rich.text import Text

from dracc.core.safetext import printable
from dracc.core.vocabulary import CHANNELS
from dracc.math.deviation import DeviationResult
from dracc.pipeline.results import (
    Analysis,
    CalibrationSection,
    CurrentSection,
    DRSection,
    Estimate,
)
from dracc.report import fmt, fmt_duration, fmt_pct, fmt_signed, short_utc
from dracc.report.rows import EXCEEDS, unit_rows


def _text(text: object = "", style: str = "") -> Text:
    """A rich Text of ``text`` with control characters escaped (never markup)."""
    return Text(printable(text), style=style)


def _est(e: Estimate | None, unit: str, digits: int = 2) -> str:
    if e is None:
        return "-"
    return f"{fmt(e.value, digits)} ± {fmt(e.sigma, digits)} {unit}"


def _heading(text: str) -> Text:
    return _text(text, style="bold")


def _sources_table(a: Analysis) -> Table:
    t = Table(box=None, pad_edge=False, show_edge=False, header_style="bold")
    columns: tuple[tuple[str, JustifyMethod], ...] = (
        ("source", "left"),
        ("role", "left"),
        ("records", "right"),
        ("sentences", "left"),
        ("first", "left"),
        ("last", "left"),
    )
    for col, just in columns:
        # figures never wrap; a very long source key (it comes from the log) folds
        t.add_column(
            col,
            justify=just,
            no_wrap=col != "source",
            overflow="fold",
        )
    for s in a.sources:
        top = sorted(s.sentences.items(), key=lambda kv: (-kv[1], kv[0]))[:4]
        sent = " ".join(f"{k}:{v}" for k, v in top) + (" …" if len(s.sentences) > 4 else "")
        t.add_row(
            _text(s.key),
            _text("+".join(s.roles) or "(none)"),
            f"{s.records:,}",
            _text(sent),
            short_utc(s.first_ns),
            short_utc(s.last_ns),
        )
    return t


def _unit_table(d: DeviationResult) -> Table:
    p = f"{100 * d.probability:g} %"
    t = Table(box=None, pad_edge=False, show_edge=False, header_style="bold")
    for col in (
        "unit",
        "channel",
        "n",
        "m_u",
        "m_y",
        "excess kurt.",
        f"limit {p}",
        "a priori",
        "verdict",
        "hat σ",
        "ref RMS",
        "k*",
    ):
        t.add_column(
            col, justify="left" if col in ("unit", "channel", "verdict") else "right", no_wrap=True
        )
    for name, rows in unit_rows(d):
        if rows is None:
            t.add_row(name, "-", "0", *["-"] * 9)
            continue
        for r in rows:
            if r.verdict == EXCEEDS:
                verdict = f"exceeds→{r.new_apriori}"
            else:
                verdict = r.verdict
            if not r.has_hat:
                hat = "-"
            elif r.hat_negative:
                hat = "neg. var."
            else:
                hat = r.hat_sigma
            # Text, not str: rich would read 'lat [m]' as markup and print 'lat'
            t.add_row(
                *(
                    _text(str(c))
                    for c in (
                        name,
                        r.channel_text,
                        r.n,
                        r.m_u,
                        r.m_y,
                        r.kurtosis,
                        r.limit,
                        r.apriori,
                        verdict,
                        hat,
                        r.ref_rms,
                        r.k_star,
                    )
                )
            )
    return t


def _section(title: str, body: list[RenderableType] | None) -> list[RenderableType]:
    """A blank line, the heading, then the body, or 'not computed' where there is none."""
    return [
        _text(""),
        _heading(title),
        *(body if body is not None else [_text("not computed (see Missing)")]),
    ]


def _bullets(title: str, items: Sequence[object]) -> list[RenderableType]:
    """A blank line, the heading and one '- item' line per item; nothing without items."""
    if not items:
        return []
    return [_text(""), _heading(title), *(_text(f"- {item}") for item in items)]


def _notes(notes: Iterable[object]) -> list[RenderableType]:
    return [_text(f"note: {note}") for note in notes]


def _verdict_word(dr: DRSection) -> str:
    """'consistent', 'inconsistent (circle too small)', 'conservative', 'undetermined'."""
    return dr.verdict.partition(":")[0].strip()


def _learned_line(m: Mapping[str, Any]) -> Text:
    """The learned current and corrections in one line (DRSection.learned)."""
    scale, scale_sigma = m.get("log_scale_correction"), m.get("log_scale_correction_sigma")
    return _text(
        f"learned  current set {fmt(m.get('current_set_deg'), 0)} ° drift "
        f"{fmt(m.get('current_drift_kn'), 2)} kn; corrections: heading "
        f"{fmt_signed(m.get('heading_correction_deg'), 2)} ± "
        f"{fmt(m.get('heading_correction_sigma_deg'), 2)} °, log scale "
        f"{fmt_signed(None if scale is None else 100.0 * scale, 2)} ± "
        f"{fmt(None if scale_sigma is None else 100.0 * scale_sigma, 2)} %"
    )


def _dr_body(dr: DRSection) -> list[RenderableType]:
    body: list[RenderableType] = [
        _text(
            f"heading  {dr.heading_source}; speed {dr.speed_source}; "
            f"restart {dr.reset}; {len(dr.legs)} leg{'s' if len(dr.legs) != 1 else ''}"
        )
    ]
    # the 2M is of the estimated position (water track + what was learned), or, with
    # learn = false, of the water track itself
    r2m = dr.epochs.radius_2m_m
    max2m = fmt(float(np.nanmax(r2m)) if np.isfinite(r2m).any() else None, 0)
    of = (
        f"2M       of the {'estimated position' if dr.scored_out_of_sample else 'DR water track'}, "
        f"largest {max2m} m"
    )
    if not dr.n_scored:
        body.append(
            _text(
                f"{of}: "
                + (
                    "no reference: consistency not scored"
                    if dr.reference_role is None
                    else "no epoch scored against the reference"
                )
            )
        )
    else:
        body.append(
            _text(
                f"{of}: reference ({dr.reference_role}) inside 2M at "
                f"{fmt_pct(dr.containment_2m)} (model: {fmt_pct(dr.expected_inside)})"
            )
        )
        if dr.scored_out_of_sample:
            ep = dr.epochs
            prior = int(np.sum((ep.since_fix_s > 0) & ~np.asarray(ep.scored, dtype=bool)))
            scored = f"scored   {dr.n_scored} epochs out of sample (model learned from earlier fixes only)"
            if prior:
                scored += f"; {prior} prior-only epochs unscored"
        else:
            scored = f"scored   {dr.n_scored} epochs after a fix, error model as configured (learn = false)"
        body.append(_text(scored))
        nees = "-"
        if np.isfinite(dr.nees_statistic):
            n_legs = len(dr.leg_checks)
            nees = (
                f"{fmt(dr.nees_statistic, 1)} over {n_legs} leg{'s' if n_legs != 1 else ''} "
                f"(chi² {fmt(dr.nees_lower, 1)}-{fmt(dr.nees_upper, 1)}), mean per epoch "
                f"{fmt(dr.mean_nees, 2)} (2 expected)"
            )
        body.append(
            _text(f"NEES     {nees}; RMS error/M {fmt(dr.error_over_m_rms, 2)} (1 expected)")
        )
    if dr.learned is not None:
        body.append(_learned_line(dr.learned))
    if dr.dominant_source and _verdict_word(dr) != "consistent":
        key = f" ([dead_reckoning] {dr.dominant_key})" if dr.dominant_key else ""
        body.append(_text(f"dominant {dr.dominant_source}{key}"))
    body.append(_text(f"verdict  {dr.verdict}"))
    return body + _notes(dr.notes)


def _deviation_body(d: DeviationResult) -> list[RenderableType]:
    fac = ", ".join(f"{ch} {fmt(d.factors[ch], 3)}" for ch in CHANNELS)
    body: list[RenderableType] = [
        _text(
            f"{len(d.units)} units, every {fmt_duration(d.interval_s)}, "
            f"{len(d.time_ns)} instants; k: {fac}; excess kurtosis (normal 0)"
        ),
        _unit_table(d),
    ]
    return body + _notes(d.messages)


def _calibration_body(c: CalibrationSection) -> list[RenderableType]:
    scale = c.log_scale and Estimate(100 * c.log_scale.value, 100 * c.log_scale.sigma)
    return [
        _text(
            f"against {c.reference_role} ({c.n} segments of {c.segment_s:g} s): compass error "
            f"{_est(c.compass_error_deg, '°')}; log scale {_est(scale, '%')}; "
            f"log offset {_est(c.log_offset_kn, 'kn')}"
        )
    ] + _notes(c.notes)


def _current_body(cur: CurrentSection) -> list[RenderableType]:
    return [
        _text(
            f"set {_est(cur.set_deg, '°', 0)} (towards), drift {_est(cur.drift_kn, 'kn')}"
            f" ({cur.n_updates} fix updates)"
        )
    ] + _notes(cur.notes)


def summary(a: Analysis) -> Group:
    """The summary as a rich renderable."""
    parts: list[RenderableType] = []
    files = len(a.inputs)
    parts.append(_heading("dracc analyze"))
    parts.append(
        _text(
            f"period   {short_utc(a.start_ns)} → {short_utc(a.end_ns)} "
            f"({fmt_duration(a.duration_s)})"
        )
    )
    parts.append(
        _text(
            f"inputs   {files} file{'s' if files != 1 else ''}, {a.lines:,} lines, "
            f"{sum(f.records for f in a.inputs):,} records"
        )
    )
    for f in a.inputs:
        parts.append(_text(f"         {f.path} ({f.format}, {f.lines:,} lines)"))
    rej = sum(a.rejected.values())
    if rej:
        by = ", ".join(f"{k} {v:,}" for k, v in sorted(a.rejected.items(), key=lambda kv: -kv[1]))
        parts.append(_text(f"rejected {rej:,} lines: {by}"))
    else:
        parts.append(_text("rejected none"))
    if a.ignored:
        by = ", ".join(
            f"{k} {v:,}" for k, v in sorted(a.ignored.items(), key=lambda kv: -kv[1])[:8]
        )
        parts.append(
            _text(f"ignored  {sum(a.ignored.values()):,} valid lines dracc does not use: {by}")
        )
    te = a.time
    events = [
        f"{n} {what}"
        for n, what in (
            (te.duplicates, "duplicates"),
            (te.backsteps, "back-steps"),
            (te.gaps, "gaps"),
            (te.rollovers, "midnight rollovers"),
            (te.implausible_dates, "implausible dates"),
        )
        if n
    ]
    parts.append(_text("time     " + (", ".join(events) if events else "no time events")))
    parts.append(_text(""))
    parts.append(_heading("Sources"))
    parts.append(_sources_table(a))

    parts += _section(
        "Dead reckoning", None if a.dead_reckoning is None else _dr_body(a.dead_reckoning)
    )
    parts += _section(
        "INS deviations from the mean",
        None if a.deviation is None else _deviation_body(a.deviation),
    )
    parts += _section(
        "Calibration", None if a.calibration is None else _calibration_body(a.calibration)
    )
    parts += _section("Current", None if a.current is None else _current_body(a.current))
    # dracc.math.faults: shown whenever found, excluded or not
    parts += _bullets(
        f"Sensor faults ({len(a.faults)})", [f"{f.kind}: {f.message}" for f in a.faults]
    )
    if a.integrity is not None:
        failed = a.integrity.failed
        parts += _bullets(
            f"Integrity: {len(failed)} of {len(a.integrity.checks)} checks failed",
            [f"[{c.check}] {c.message}" for c in failed],
        )
    parts += _bullets("Missing", a.missing)
    parts += _bullets("Notes", a.notes)
    return Group(*parts)


def render_text(a: Analysis, width: int = 120) -> str:
    """The summary as plain text (no colour), for golden files and pipes."""
    console = Console(
        width=width,
        record=True,
        color_system=None,
        force_terminal=False,
        file=cast(IO[str], _NullFile()),  # rich only calls write() and flush()
        soft_wrap=False,
    )
    console.print(summary(a))
    return console.export_text()


#: the summary's tables are laid out for at least this many columns; a narrower terminal
#: wraps the long lines rather than the tables hiding figures behind ellipses
MIN_WIDTH = 110
#: a file or a pipe has no width: lay the tables out as wide as their content needs, up to this
FILE_WIDTH = 200


def print_summary(a: Analysis, console: Console) -> None:
    """Print the summary on ``console`` (stdout in the CLI)."""
    width = console.width
    target = max(width, MIN_WIDTH) if console.is_terminal else FILE_WIDTH
    console.width = target  # rich never prints wider than the console's own width
    try:
        console.print(summary(a))
    finally:
        console.width = width


class _NullFile:
    def write(self, _s: str) -> int:
        return 0

    def flush(self) -> None:
        pass
