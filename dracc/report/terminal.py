"""The short summary ``dracc analyze`` prints on the terminal, and ``dracc fleet``'s table.

Sections, in the order a navigator reads them: period and inputs, sources and
rejects, dead-reckoning consistency, the per-unit table, calibration, current, and
what is missing.  The text is laid out by :mod:`dracc.report.textout`: tables at their
natural width on a pipe or in a file (never squeezed, never an ellipsis); a terminal
narrower than a table leaves out its least needed columns (and says which); the long
lines wrap on spaces at the terminal's width (on a pipe at ``$COLUMNS`` or 100), never
inside a number or a source key.  Text from the logs (source keys, file names, and the
notes and messages that quote them) is never read as rich markup, and every control
character is shown as an escape (:func:`dracc.core.safetext.printable`: ESC as
``\\x1b``), so a log can neither style the terminal nor send it a command.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from rich.console import Console

from dracc.core.numbers import counted
from dracc.core.safetext import printable
from dracc.core.vocabulary import CHANNELS, FIX_UPDATED_EP, as_heading, dr_name
from dracc.math.deviation import DeviationResult
from dracc.math.integrity import IntegrityResult
from dracc.math.integrity.causes import failed_with_consequences
from dracc.pipeline.results import (
    Analysis,
    CalibrationSection,
    CurrentSection,
    DRSection,
    Estimate,
    EstimatedPositionSection,
)
from dracc.report import fmt, fmt_duration, fmt_pct, short_utc
from dracc.report.rows import (
    EXCEEDS,
    K_STAR_NOTE,
    calibration_method,
    clock_text,
    has_k_star,
    unit_rows,
)
from dracc.report.textout import Layout, Page, bullet, labelled, layout
from dracc.report.verdict import honesty_text, integrity_count, scored_legs, verdict

if TYPE_CHECKING:
    from dracc.pipeline.fleet import FleetResult
from dracc.report.textout import wrap as wrap_text


class _Page(Page):
    """The summary's lines, with its labelled lines, notes and bullets."""

    def line(self, label: str, text: object) -> None:
        """A line under a 9-character label (``period   ...``), wrapped under its text."""
        self.add(labelled(label, text, self.lay.width))

    def note(self, text: object) -> None:
        self.wrapped(f"note: {printable(text)}", hang=6)

    def bullet(self, text: object) -> None:
        self.add(bullet(text, self.lay.width))


def _est(e: Estimate | None, unit: str, digits: int = 2) -> str:
    if e is None:
        return "-"
    return f"{fmt(e.value, digits)} ± {fmt(e.sigma, digits)} {unit}"


#: the sources table: name, right-aligned, priority (0 always shown; higher: left out
#: sooner on a narrow terminal; first and last are in the period line already)
_SOURCE_COLUMNS = (
    ("source", False, 0),
    ("role", False, 0),
    ("records", True, 1),
    ("sentences", False, 2),
    ("first", False, 3),
    ("last", False, 3),
    ("clock", False, 2),
)


def _sources_table(page: _Page, a: Analysis) -> None:
    rows = []
    for s in a.sources:
        top = sorted(s.sentences.items(), key=lambda kv: (-kv[1], kv[0]))[:4]
        more = len(s.sentences) - len(top)
        sent = " ".join(f"{k}:{v}" for k, v in top) + (f" +{more} more" if more else "")
        rows.append(
            (
                s.key,
                "+".join(s.roles) or "(none)",
                f"{s.records:,}",
                sent,
                short_utc(s.first_ns),
                short_utc(s.last_ns),
                clock_text(s.clock),
            )
        )
    headers, right, prio = zip(*_SOURCE_COLUMNS, strict=True)
    page.table(headers, rows, right=right, priorities=prio)


def _unit_columns(d: DeviationResult) -> tuple[tuple[str, bool, int], ...]:
    """The per-unit table's columns: name, right-aligned, priority (as above)."""
    return (
        ("unit", False, 0),
        ("channel", False, 0),
        ("n", True, 3),
        ("m_u", True, 1),
        ("m_y", True, 0),
        ("excess kurt.", True, 2),
        (f"limit {100 * d.probability:g} %", True, 1),
        ("a priori", True, 1),
        ("verdict", False, 0),
        ("hat σ", True, 2),
        ("ref RMS", True, 3),
        ("k*", True, 3),
    )


def _unit_table(page: _Page, d: DeviationResult) -> None:
    rows: list[tuple[object, ...]] = []
    for name, unit in unit_rows(d):
        if unit is None:
            rows.append((name, "-", "0", *["-"] * 9))
            continue
        for r in unit:
            verdict = f"exceeds→{r.new_apriori}" if r.verdict == EXCEEDS else r.verdict
            if not r.has_hat:
                hat = "-"
            elif r.hat_negative:
                hat = "neg. var."
            else:
                hat = r.hat_sigma
            rows.append(
                (
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
    headers, right, prio = zip(*_unit_columns(d), strict=True)
    page.table(headers, rows, right=right, priorities=prio)


def _section(page: _Page, title: str, body: Any, section: object | None) -> None:
    """A blank line, the heading, then the body, or 'not computed' where there is none."""
    page.blank()
    page.heading(title)
    if section is None:
        page.add("not computed (see Missing)")
    else:
        body(page, section)


def _bullets(page: _Page, title: str, items: Sequence[object]) -> None:
    """A blank line, the heading and one '- item' per item; nothing without items."""
    if not items:
        return
    page.blank()
    page.heading(title)
    for item in items:
        page.bullet(item)


def _notes(page: _Page, notes: Iterable[object]) -> None:
    for note in notes:
        page.note(note)


def _verdict_word(dr: DRSection) -> str:
    """'consistent', 'inconsistent (circle too small)', 'conservative', 'undetermined'."""
    return dr.verdict.partition(":")[0].strip()


def _learned_text(m: Mapping[str, Any]) -> str:
    """The learned current and noise in one line (DRSection.learned); the compass and log
    errors it learned are the calibration's."""
    return (
        f"current set {fmt(m.get('current_set_deg'), 0)} ° drift "
        f"{fmt(m.get('current_drift_kn'), 2)} kn; noise {fmt(m.get('noise_kn'), 2)} kn; "
        "compass and log errors: see Calibration"
    )


def _dr_body(page: _Page, dr: DRSection) -> None:
    page.line(
        "heading",
        f"{dr.heading_source}; speed {dr.speed_source}; restart {dr.reset}; {scored_legs(dr)}",
    )
    # the 2M is of the DR over the ground (water track + what was learned), or, with
    # learn = false, of the water track itself
    r2m = dr.epochs.radius_2m_m
    max2m = fmt(float(np.nanmax(r2m)) if np.isfinite(r2m).any() else None, 0)
    of = f"of the {dr_name(dr.scored_out_of_sample)}, largest {max2m} m"
    if not dr.n_scored:
        why = (
            "no reference: consistency not scored"
            if dr.reference_role is None
            else "no epoch scored against the reference"
        )
        page.line("2M", f"{of}: {why}")
    else:
        page.line(
            "2M",
            f"{of}: reference ({dr.reference_role}) inside 2M at "
            f"{fmt_pct(dr.containment_2m)} (stated: {fmt_pct(dr.expected_inside)})",
        )
        if dr.honesty is not None:
            page.line("honesty", honesty_text(dr.honesty))
        if dr.scored_out_of_sample:
            ep = dr.epochs
            prior = int(np.sum((ep.since_fix_s > 0) & ~np.asarray(ep.scored, dtype=bool)))
            scored = f"{dr.n_scored} epochs out of sample (model learned from earlier fixes only)"
            if prior:
                scored += f"; {prior} prior-only epochs unscored"
        else:
            scored = f"{dr.n_scored} epochs after a fix, error model as configured (learn = false)"
        page.line("scored", scored)
        nees = "-"
        if np.isfinite(dr.nees_statistic):
            nees = (
                f"{fmt(dr.nees_statistic, 1)} over {counted(len(dr.leg_checks), 'scored leg')} "
                f"(chi² {fmt(dr.nees_lower, 1)}-{fmt(dr.nees_upper, 1)}), mean per epoch "
                f"{fmt(dr.mean_nees, 2)} (2 expected)"
            )
        page.line("NEES", f"{nees}; RMS error/M {fmt(dr.error_over_m_rms, 2)} (1 expected)")
    if dr.learned is not None:
        page.line("learned", _learned_text(dr.learned))
    if dr.dominant_source and _verdict_word(dr) != "consistent":
        key = f" ([dead_reckoning] {dr.dominant_key})" if dr.dominant_key else ""
        page.line("dominant", f"{dr.dominant_source}{key}")
    page.line("verdict", dr.verdict)
    _notes(page, dr.notes)


def _deviation_body(page: _Page, d: DeviationResult) -> None:
    fac = ", ".join(f"{ch} {fmt(d.factors[ch], 3)}" for ch in CHANNELS)
    page.add(
        wrap_text(
            f"{len(d.units)} units, every {fmt_duration(d.interval_s)}, "
            f"{len(d.time_ns)} instants; k: {fac}; excess kurtosis (normal 0)",
            page.lay.width,
        )
    )
    _unit_table(page, d)
    if has_k_star(d):
        page.note(K_STAR_NOTE)
    _notes(page, d.messages)


def _calibration_body(page: _Page, c: CalibrationSection) -> None:
    scale = c.log_scale and Estimate(100 * c.log_scale.value, 100 * c.log_scale.sigma)
    nd = c.not_determinable  # each quantity the data cannot determine says so, and why

    def est(key: str, e: Estimate | None, unit: str) -> str:
        return "NOT DETERMINABLE" if key in nd else _est(e, unit)

    page.add(
        wrap_text(
            f"against {c.reference_role} ({calibration_method(c.method, c.n, c.segment_s)}): "
            "compass error "
            f"{est('compass_error_deg', c.compass_error_deg, '°')}; log scale "
            f"{est('log_scale', scale, '%')}; log offset "
            f"{est('log_offset_kn', c.log_offset_kn, 'kn')}",
            page.lay.width,
        )
    )
    _notes(page, (*nd.values(), *c.notes))


def _current_body(page: _Page, cur: CurrentSection) -> None:
    page.add(
        wrap_text(
            f"set {_est(cur.set_deg, '°', 0)} (towards), drift {_est(cur.drift_kn, 'kn')}"
            f" ({cur.n_updates} fix updates)",
            page.lay.width,
        )
    )
    _notes(page, cur.notes)


#: the fix-interval study (seeds/003, Figure 5): name, right-aligned, priority (as above)
_STUDY_COLUMNS: tuple[tuple[str, bool, int], ...] = (
    ("fix interval", True, 0),
    ("updates", True, 2),
    ("mean 2M before", True, 0),
    ("max 2M before", True, 1),
    ("inside 95 %", True, 0),
    ("stated", True, 1),
)


def _metres(x: float | None) -> str:
    """'309 m', or '-' where there is no figure (no update at that interval)."""
    text = fmt(x, 0)
    return text if text == "-" else f"{text} m"


def _aided_ep_body(page: _Page, e: EstimatedPositionSection) -> None:
    """The fix-updated EP (seeds/003) in one line; with --fix-interval, the study's table."""
    r2m = np.asarray(e.radius_2m_m, float)
    ok = np.isfinite(r2m)
    mean2m = fmt(float(r2m[ok].mean()) if ok.any() else None, 0)
    max2m = fmt(float(r2m[ok].max()) if ok.any() else None, 0)
    lops = f", {e.n_lop_updates} from the observation file" if e.n_lop_updates else ""
    page.line(
        "updates",
        f"{e.n_fix_updates} GNSS fixes (one per {fmt_duration(e.fix_interval_s)}){lops}; "
        f"2M mean {mean2m} m, largest {max2m} m over {len(e.time_ns)} epochs",
    )
    if e.interval_study:
        rows = [
            (
                fmt_duration(r.interval_s),
                r.n_updates,
                _metres(r.mean_2m_before_m),
                _metres(r.max_2m_before_m),
                fmt_pct(r.containment),
                fmt_pct(r.expected_containment),
            )
            for r in e.interval_study
        ]
        headers, right, prio = zip(*_STUDY_COLUMNS, strict=True)
        page.table(headers, rows, right=right, priorities=prio)
    _notes(page, e.notes[1:])  # the first note says what the updates line says


def _head(page: _Page, a: Analysis) -> None:
    """The title, the period, the inputs, what was rejected and ignored, the time events."""
    files = len(a.inputs)
    page.heading("dracc analyze")
    page.line(
        "period",
        f"{short_utc(a.start_ns)} → {short_utc(a.end_ns)} ({fmt_duration(a.duration_s)})",
    )
    page.line(
        "inputs",
        f"{files} file{'s' if files != 1 else ''}, {a.lines:,} lines, "
        f"{sum(f.records for f in a.inputs):,} records",
    )
    for f in a.inputs:
        page.line("", f"{f.path} ({f.format}, {f.lines:,} lines)")
    rej = sum(a.rejected.values())
    if rej:
        by = ", ".join(f"{k} {v:,}" for k, v in sorted(a.rejected.items(), key=lambda kv: -kv[1]))
        page.line("rejected", f"{rej:,} lines: {by}")
    else:
        page.line("rejected", "none")
    if a.ignored:
        by = ", ".join(
            f"{k} {v:,}" for k, v in sorted(a.ignored.items(), key=lambda kv: -kv[1])[:8]
        )
        page.line("ignored", f"{sum(a.ignored.values()):,} valid lines dracc does not use: {by}")
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
    page.line("time", ", ".join(events) if events else "no time events")


def _verdict(page: _Page, a: Analysis) -> None:
    """The headline first (:func:`dracc.report.verdict.verdict`, as the HTML report's
    verdict block): each part's level in words, then its one sentence."""
    v = verdict(a)
    page.blank()
    page.heading(f"Verdict: {v.label}")
    page.wrapped(v.headline)
    for f in v.findings:
        page.wrapped(f"{f.label:<11} {f.topic}: {f.headline}", hang=12)


def _integrity_body(page: _Page, ig: IntegrityResult) -> None:
    """The failed checks, one per cause, the checks it caused under it
    (:func:`dracc.math.integrity.causes.failed_with_consequences`)."""
    grouped = failed_with_consequences(ig)
    page.blank()
    n = len(grouped)
    page.heading(f"Integrity: {integrity_count(ig)}; {n} finding{'s' if n != 1 else ''}")
    for c, under in grouped:
        page.bullet(f"[{c.check}] {c.message}")
        for k in under:
            page.add(bullet(f"[{k.check}] {k.message}", page.lay.width, mark=_UNDER))


#: a finding's consequence, under it
_UNDER = "    consequence: "


def _page(a: Analysis, lay: Layout) -> _Page:
    """The whole summary laid out for ``lay``."""
    page = _Page(lay)
    _head(page, a)
    _verdict(page, a)
    page.blank()
    page.heading("Sources")
    _sources_table(page, a)
    _section(page, "Dead reckoning", _dr_body, a.dead_reckoning)
    _section(page, "INS deviations from the mean", _deviation_body, a.deviation)
    _section(page, "Calibration", _calibration_body, a.calibration)
    _section(page, "Current", _current_body, a.current)
    if a.estimated_position is not None:  # seeds/003; the Missing list says why not
        _section(page, as_heading(FIX_UPDATED_EP), _aided_ep_body, a.estimated_position)
    # dracc.math.faults: shown whenever found, excluded or not
    _bullets(page, f"Sensor faults ({len(a.faults)})", [f"{f.kind}: {f.message}" for f in a.faults])
    if a.integrity is not None and a.integrity.failed:
        _integrity_body(page, a.integrity)
    _bullets(page, "Missing", a.missing)
    _bullets(page, "Notes", a.notes)
    return page


def render_text(a: Analysis, width: int = 120, tty: bool = False) -> str:
    """The summary as plain text laid out for ``width`` columns (``tty``: a terminal of
    that width, which leaves out columns that do not fit; else a pipe: every column)."""
    return _page(a, Layout(width, tty)).text()


def print_summary(a: Analysis, console: Console) -> None:
    """Print the summary on ``console`` (stdout in the CLI), laid out for it
    (:func:`dracc.report.textout.layout`), the headings bold on a terminal."""
    _page(a, layout(console)).print(console)


#: ``dracc fleet``'s table: name, right-aligned, priority (as above)
_FLEET_COLUMNS = (
    ("vessel", False, 0),
    ("unit", False, 0),
    ("night", False, 2),
    ("RMS error", True, 0),
    ("m_y", True, 1),
    ("kurt", True, 2),
    ("limit", True, 1),
    ("a priori", True, 1),
    ("verdict", False, 0),
    ("DR 2M", True, 1),
    ("compass", True, 2),
    ("log", True, 2),
)


_RANKING_COLUMNS = (
    ("rank", True, 1),
    ("vessel", False, 0),
    ("unit", False, 0),
    ("quantity", False, 0),
    ("pooled value", True, 0),
    ("peer median", True, 2),
    ("q", True, 0),
    ("since", False, 1),
)


def _ranking_lines(page: Page, ranking) -> None:
    """The discoveries of the ranking (q below the FDR), first on the page."""
    from dracc.report.fleet_html import cell_text, fmt_num_unit

    if ranking is None or ranking.empty:
        return
    found = ranking[ranking["discovery"].fillna(False).astype(bool)]
    tested = int(ranking["p_value"].notna().sum())
    if found.empty:
        untested = len(ranking) - tested
        said = (
            f"no unit stands out among {tested} tested (false discovery rate 5 %)"
            if tested
            else "nothing to test yet"
        )
        page.wrapped(
            f"fleet ranking: {said}; {untested} row(s) without the peers or nights a test "
            "needs; ranking.csv and fleet.html list them all"
        )
        page.blank()
        return
    rows = []
    for _, r in found.iterrows():
        unit = cell_text(r["measure_unit"])
        digits = 3 if unit == "deg" else (2 if unit in ("%", "s") else 0)
        rows.append(
            (
                str(r["rank"]),
                cell_text(r["vessel"]),
                cell_text(r["ins_unit"]),
                cell_text(r["quantity"]),
                fmt_num_unit(r["value"], digits, unit),
                fmt_num_unit(r["peer_median"], digits, unit),
                f"{r['q_value']:.1e}",
                cell_text(r["since"]),
            )
        )
    headers, right, prio = zip(*_RANKING_COLUMNS, strict=True)
    title = f"fleet ranking: {len(found)} of {len(ranking)} stand out (q < 0.05)"
    page.table(headers, _names_escaped(rows), right=right, priorities=prio, title=title)
    page.blank()


def _fleet_page(res: FleetResult, lay: Layout) -> Page:
    import pandas as pd

    from dracc.report.fleet_html import cell_text, fmt_num, fmt_num_unit, latest

    lt = latest(res.table)
    rows = []
    for _, r in lt.iterrows():
        d = 3 if cell_text(r["measure_unit"]) == "deg" else 0
        c = r["dr_containment_2m"]
        unit = "-" if pd.isna(r["ins_unit"]) else f"{r['ins_unit']} {r['channel']}"
        measure = "" if pd.isna(r["measure_unit"]) else r["measure_unit"]
        rows.append(
            (
                cell_text(r["vessel"]),
                unit,
                cell_text(r["day"]),
                fmt_num_unit(r["rms_error"], d, measure),
                fmt_num_unit(r["m_y"], d, measure),
                fmt_num(r["kurtosis_excess"], 1),
                fmt_num(r["limit"], d),
                fmt_num(r["apriori_after"], d),
                cell_text(r["apriori_verdict"]),
                "-" if pd.isna(c) else f"{100 * c:.0f}%",
                fmt_num_unit(r["compass_error_deg"], 2, "°"),
                fmt_num_unit(r["log_scale_pct"], 1, "%"),
            )
        )
    page = Page(lay)
    _ranking_lines(page, res.ranking)
    headers, right, prio = zip(*_FLEET_COLUMNS, strict=True)
    title = (
        "fleet: latest night per vessel, unit and channel (RMS error: the ranking's figure "
        "of that night; m_y, a priori, verdict: the mean of three's rule)"
    )
    page.table(headers, _names_escaped(rows), right=right, priorities=prio, title=title)
    _findings_lines(page, res.findings)
    return page


def _names_escaped(rows: Sequence[Sequence[str]]) -> list[tuple[str, ...]]:
    """The fleet's cells with every control character escaped, a line break too: vessel,
    unit and source names come from ships, and a table cell may hold several lines, so
    a name ``'X\\nall within limits'`` would print a line of its own (issue 33)."""
    return [tuple(map(printable, row)) for row in rows]


#: findings named on the terminal (findings.csv and fleet.html list them all)
_FINDINGS_SHOWN = 12


def _findings_lines(page: Page, findings) -> None:
    """The run's findings in one paragraph under the table: vessel, night, name, source."""
    failed = findings[findings["status"] == "fail"] if len(findings) else findings
    if not len(failed):
        return
    named = [
        printable(f"{r['vessel']} {r['night']} {r['name']} {r['source']}")
        for _, r in failed.head(_FINDINGS_SHOWN).iterrows()
    ]
    more = len(failed) - len(named)
    nights = len(failed.drop_duplicates(["vessel", "night"]))
    page.blank()
    page.wrapped(
        f"findings: {len(failed)} on {nights} night{'s' if nights != 1 else ''}: "
        + "; ".join(named)
        + (f"; {more} more in findings.csv and fleet.html" if more else ""),
        hang=2,
    )


def fleet_text(res: FleetResult, width: int = 100, tty: bool = False) -> str:
    """``dracc fleet``'s table of the latest figures per vessel, unit and channel as text
    laid out for ``width`` columns (``tty``: a terminal of that width)."""
    return _fleet_page(res, Layout(width, tty)).text()


def print_fleet(res: FleetResult, console: Console) -> None:
    """The fleet table (:func:`fleet_text`) laid out for ``console`` and printed there."""
    _fleet_page(res, layout(console)).print(console)
