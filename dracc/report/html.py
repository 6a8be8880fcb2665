"""One self-contained HTML report that opens offline (a bridge PC has no network).

Everything is inline: CSS in a ``<style>`` element, plots as base64 PNG ``data:``
URIs.  A Content-Security-Policy forbids fetching anything and running scripts, so
even a hostile string in a log cannot make the page load a URL; every text taken
from the logs goes through :func:`html.escape` as well.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from dracc.core import atomic
from dracc.core.numbers import counted
from dracc.core.timefmt import iso_utc
from dracc.core.vocabulary import CHANNELS, DR_OVER_GROUND, FIX_UPDATED_EP, WATER_TRACK, as_heading
from dracc.math.integrity import IntegrityResult
from dracc.math.integrity.causes import failed_with_consequences
from dracc.pipeline.results import Analysis, DRLeg, DRSection, Estimate
from dracc.report import fmt, fmt_duration, fmt_pct, short_utc
from dracc.report.glossary import GLOSSARY, anchor
from dracc.report.page import (  # one policy and one data URI for every page
    CSP,
    consequences_html,
    data_uri,
)
from dracc.report.rows import (
    EXCEEDS,
    K_STAR_NOTE,
    WITHIN,
    calibration_method,
    channel_rows,
    clock_text,
    has_k_star,
    unit_rows,
)
from dracc.report.verdict import (
    FAULTS_FOUND,
    Finding,
    Verdict,
    containment_text,
    honesty_text,
    integrity_count,
    scored_legs,
    verdict,
    with_ins,
)

#: a column header: the glossary term (shown as it is), or (term, header html)
Header = str | tuple[str, str]

_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 1.5em auto;
       max-width: 1100px; color: #1b1b1b; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; margin-top: 1.6em; }
table { border-collapse: collapse; font-size: 0.9em; margin: 0.5em 0; }
th, td { padding: 0.2em 0.6em; border-bottom: 1px solid #e4e4e4; text-align: right; white-space: nowrap; }
th { background: #f3f3f3; }
td.l, th.l { text-align: left; }
.bad { color: #b00020; font-weight: 600; }
.ok { color: #1b6e20; font-weight: 600; }
.missing { background: #fff4e5; border-left: 4px solid #ff9800; padding: 0.5em 1em; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #555; }
.kv td:first-child { text-align: left; color: #555; }
.kv td { text-align: left; white-space: normal; }
pre.config { background: #f6f6f6; border: 1px solid #ddd; padding: 0.5em 1em; font-size: 0.85em;
             overflow-x: auto; }
th a.g, .kv a.g { color: inherit; text-decoration: underline dotted; }
.artefact { color: #455a64; background: #eceff1; border-radius: 3px; padding: 0 0.3em;
            font-style: italic; }
#verdict-block { border: 1px solid #ccc; padding: 0.3em 1em 0.8em; }
#verdict-block > p.overall { font-size: 1.15em; }
.verdict-list { list-style: none; padding: 0; margin: 0; }
.verdict-list > li { margin: 0.5em 0; padding: 0.3em 0.6em; border-left: 6px solid #999; }
.verdict-list ul { margin: 0.2em 0 0 1em; padding-left: 1em; font-size: 0.9em; color: #333; }
.lvl { display: inline-block; min-width: 8.5em; font-weight: 700; font-size: 0.85em;
       letter-spacing: 0.03em; }
li.lvl-ok { border-left-color: #1b6e20; background: #f1f8f1; }
li.lvl-attention { border-left-color: #e08a00; background: #fff8e6; }
li.lvl-fail { border-left-color: #b00020; background: #fdecee; }
li.lvl-not-checked { border-left: 6px dashed #78909c; background: #f5f5f5; }
.lvl-ok .lvl, span.lvl-ok { color: #1b6e20; }
.lvl-attention .lvl, span.lvl-attention { color: #9a5b00; }
.lvl-fail .lvl, span.lvl-fail { color: #b00020; }
.lvl-not-checked .lvl, span.lvl-not-checked { color: #546e7a; font-style: italic; }
p.none-found { border-left: 4px solid #1b6e20; padding: 0.3em 0.8em; }
p.not-checked { border-left: 4px dashed #78909c; padding: 0.3em 0.8em; color: #455a64;
                font-style: italic; }
dl.glossary dt { font-weight: 600; margin-top: 0.5em; }
dl.glossary dd { margin-left: 1.5em; }
dl.glossary .label { color: #555; font-size: 0.9em; }
"""


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _th(h: Header) -> str:
    """A header cell's content: the header linked to its glossary entry."""
    term, text = (h, _e(h)) if isinstance(h, str) else h
    if term not in GLOSSARY:
        return text
    return f'<a class="g" href="#{anchor(term)}">{text}</a>'


def _table(headers: list[Header], rows: list[list[str]], left: int = 1) -> str:
    """An HTML table; cells are already escaped; the first ``left`` columns align left.
    Each header is a glossary term (or (term, html)) and links to the term's entry."""
    head = "".join(
        f'<th class="l">{_th(h)}</th>' if i < left else f"<th>{_th(h)}</th>"
        for i, h in enumerate(headers)
    )
    body = "".join(
        "<tr>"
        + "".join(
            f'<td class="l">{c}</td>' if i < left else f"<td>{c}</td>" for i, c in enumerate(r)
        )
        + "</tr>"
        for r in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _figure(png: bytes | None, alt: str, caption: str, fig_id: str) -> str:
    if png is None:
        return f'<p class="missing">{_e(caption)}: nothing to plot (see Missing).</p>'
    return (
        f'<figure id="{fig_id}"><img alt="{_e(alt)}" src="{data_uri(png)}">'
        f"<figcaption>{_e(caption)}</figcaption></figure>"
    )


def _est(e: Estimate | None, unit: str, digits: int = 2, scale: float = 1.0) -> str:
    if e is None:
        return "-"
    return f"{fmt(scale * e.value, digits)} ± {fmt(scale * e.sigma, digits)} {unit}"


def _summary(a: Analysis) -> str:
    rows = [
        (
            "period",
            f"{short_utc(a.start_ns)} → {short_utc(a.end_ns)} ({fmt_duration(a.duration_s)})",
        ),
        (
            "inputs",
            "<br>".join(
                f"{_e(f.path)} ({_e(f.format)}, {f.lines:,} lines, {f.records:,} records)"
                for f in a.inputs
            ),
        ),
        (
            "rejected lines",
            ", ".join(f"{_e(k)}: {v:,}" for k, v in sorted(a.rejected.items())) or "none",
        ),
        (
            "ignored (valid, unused)",
            ", ".join(f"{_e(k)}: {v:,}" for k, v in sorted(a.ignored.items())) or "none",
        ),
    ]
    if a.integrity is not None:
        failed = a.integrity.failed
        count = _e(integrity_count(a.integrity))
        text = (
            f'<span class="bad">{count}</span>: ' + _causes_html(a.integrity)
            if failed
            else f'<span class="ok">{count}</span>'
        )
        rows.append(("integrity", text))
    te = a.time
    rows.append(
        (
            "time events",
            f"{te.duplicates} duplicates, {te.backsteps} back-steps, "
            f"{te.gaps} gaps, {te.rollovers} midnight rollovers, "
            f"{te.implausible_dates} implausible dates",
        )
    )
    dr = a.dead_reckoning
    if dr is not None:
        cls = "ok" if dr.consistent else ("bad" if dr.consistent is False else "")
        rows.append(("dead reckoning", f'<span class="{cls}">{_e(dr.verdict)}</span>'))
    kv = "".join(f"<tr><td>{k}</td><td>{v}</td></tr>" for k, v in rows)
    src = _table(
        ["source", "roles", "records", "sentences", "first", "last", "clock"],
        [
            [
                _e(s.key),
                _e("+".join(s.roles) or "(none)"),
                f"{s.records:,}",
                _e(" ".join(f"{k}:{v}" for k, v in sorted(s.sentences.items()))),
                short_utc(s.first_ns),
                short_utc(s.last_ns),
                _e(clock_text(s.clock)),
            ]
            for s in a.sources
        ],
        left=2,
    )
    return f'<table class="kv">{kv}</table><h3>Sources</h3>{src}'


def _causes_html(ig: IntegrityResult) -> str:
    """The failed checks, one finding per cause with the checks it caused under it
    (:func:`dracc.math.integrity.causes.failed_with_consequences`)."""
    grouped = failed_with_consequences(ig)
    items = "".join(
        f"<li>{_e(f'[{c.check}] {c.message}')}"
        + consequences_html((k.check, k.message) for k in under)
        + "</li>"
        for c, under in grouped
    )
    n = len(grouped)
    return f"{n} finding{'s' if n != 1 else ''}<ul class='findings'>{items}</ul>"


def _units(a: Analysis) -> str:
    d = a.deviation
    if d is None:
        return '<p class="missing">INS deviation statistics not computed (see Missing).</p>'
    p = f"{100 * d.probability:g} %"
    rows = []
    for _, urows in unit_rows(d):
        for r in urows or ():
            if r.verdict == EXCEEDS:
                verdict = f'<span class="bad">exceeds; new {r.new_apriori}</span>'
            elif r.verdict == WITHIN:
                verdict = '<span class="ok">within</span>'
            else:
                verdict = r.verdict
            hat = (
                "-"
                if not r.has_hat
                else (
                    f'<a class="artefact" href="#{anchor("negative variance")}">'
                    "negative variance (artefact)</a>"
                    if r.hat_negative
                    else f"{r.hat_sigma} [{_e(r.hat_lower)}, {_e(r.hat_upper)}]"
                )
            )
            rows.append(
                [
                    _e(r.unit),
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
                    _e(r.k_star),
                ]
            )
    fac = ", ".join(f"{ch} {fmt(d.factors[ch], 3)}" for ch in CHANNELS)
    intro = (
        f"<p>{len(d.units)} units sampled every {fmt_duration(d.interval_s)} at "
        f"{len(d.time_ns)} instants; m<sub>y</sub> = k·m<sub>u</sub> with k: {fac}; kurtosis is "
        f"<em>excess</em> kurtosis (0 for a normal distribution); limits at P = {p}.</p>"
    )
    notes = "".join(f"<p>{_e(n)}</p>" for n in d.messages)
    notes += f"<p>{_e(K_STAR_NOTE)}.</p>" if has_k_star(d) else ""
    table = _table(
        [
            "unit",
            "channel",
            "n",
            "m_u",
            "m_y",
            "excess kurtosis",
            ("limit", f"limit {p}"),
            "a priori",
            "a priori verdict",
            ("hat σ", "hat σ [bounds]"),
            "ref RMS",
            "k*",
        ],
        rows,
        left=2,
    )
    windows = ""
    if d.windows:
        wrows = []
        for w in d.windows:
            for name, u in w.units.items():
                for r in channel_rows(name, u):
                    wrows.append(
                        [
                            _e(w.label),
                            _e(r.unit),
                            r.channel,
                            r.n,
                            r.m_u,
                            r.m_y,
                            r.kurtosis,
                            _e(r.k_star),
                        ]
                    )
        windows = "<h3>Per window</h3>" + _table(
            ["window", "unit", "channel", "n", "m_u", "m_y", "excess kurtosis", "k*"], wrows, left=3
        )
    return intro + table + notes + windows


def _nees(dr: DRSection) -> str:
    if dr.nees_statistic is None or not math.isfinite(dr.nees_statistic):
        return "-"
    return (
        f"{fmt(dr.nees_statistic, 1)} over {counted(len(dr.leg_checks), 'scored leg')} (χ² bounds "
        f"{fmt(dr.nees_lower, 1)}–{fmt(dr.nees_upper, 1)}); mean per epoch "
        f"{fmt(dr.mean_nees, 2)} (2 expected)"
    )


def _learned(m: Mapping[str, Any] | None) -> str:
    """The model learned from the fixes, and its [dead_reckoning] block in a <pre>."""
    if m is None:
        return ""

    def g(key: str, digits: int, scale: float = 1.0) -> str:
        v = m.get(key)
        return fmt(None if v is None else scale * v, digits)

    rows = [
        (
            "current (persistent)",
            f"set {g('current_set_deg', 0)}° (towards), drift {g('current_drift_kn', 2)} kn",
        ),
        (
            "current variation",
            f"σ {g('current_variation_kn', 2)} kn per axis, τ "
            f"{fmt_duration(m.get('current_tau_s') or math.nan)}",
        ),
        (
            "compass and log errors",
            '<a href="#calibration">Calibration</a> (learned here, given once there)',
        ),
        (
            "short-term noise",
            f"σ {g('noise_kn', 2)} kn per axis, τ {fmt_duration(m.get('noise_tau_s') or math.nan)}",
        ),
        ("fix noise", f"{g('fix_sigma_m', 1)} m per axis"),
        (
            "model",
            f"the best of {_e(m.get('n_models', '-'))} grid models, weight "
            f"{g('model_weight', 3)}; filter step {g('filter_step_s', 0)} s; "
            f"{_e(m.get('n_fixes_used', '-'))} fixes used, {_e(m.get('n_outliers', '-'))} "
            "outliers left out",
        ),
    ]
    kv = "".join(f"<tr><td>{k}</td><td>{v}</td></tr>" for k, v in rows)
    block = m.get("config_block")
    pre = (
        ""
        if not block
        else "<p>To reuse this model where there is no reference, put this block in the "
        f'configuration (<code>--config</code>):</p><pre class="config">{_e(block)}</pre>'
    )
    return f'<h3>Learned model</h3><table class="kv" id="dr-learned">{kv}</table>{pre}'


def _dr(a: Analysis) -> str:
    dr = a.dead_reckoning
    if dr is None:
        return '<p class="missing">Dead reckoning not computed (see Missing).</p>'
    position = (
        f"{DR_OVER_GROUND}: the {WATER_TRACK} plus the current and the compass and log "
        "corrections learned from earlier fixes"
        if dr.scored_out_of_sample
        else f"the {WATER_TRACK} (heading and log; error model as configured, nothing learned)"
    )
    scored = f"{dr.n_scored} epochs after a fix"
    if dr.scored_out_of_sample:
        prior = int(sum((dr.epochs.since_fix_s > 0) & ~dr.epochs.scored.astype(bool)))
        scored += ", out of sample (each leg's model learned only from fixes before it)" + (
            f"; {prior} epochs of earlier legs (prior only) not scored" if prior else ""
        )
    rows = [
        ("heading", _e(dr.heading_source)),
        ("speed", _e(dr.speed_source)),
        ("restart", _e(dr.reset)),
        ("legs", scored_legs(dr)),
        ("reference", _e(dr.reference_role or "none")),
        ("position and 2M", _e(position)),
        ("scored", _e(scored)),
        (
            "2M containment",
            containment_text(dr),
        ),
        ("stated against achieved", _e(honesty_text(dr.honesty)) if dr.honesty else "-"),
        ("RMS error / M", fmt(dr.error_over_m_rms, 2)),
        ("NEES", _nees(dr)),
        (
            "reference σ",
            f"{fmt(dr.reference_sigma_m, 1)} m per axis (in the stated probability and the tests; "
            "the circle judged is the one drawn)",
        ),
    ]
    if dr.dominant_source:
        key = f" (prior: [dead_reckoning] {_e(dr.dominant_key)})" if dr.dominant_key else ""
        rows.append(("largest part of the 2M", f"{_e(dr.dominant_source)}{key}"))
    rows.append(("verdict", _e(dr.verdict)))
    kv = "".join(f"<tr><td>{_th(k)}</td><td>{v}</td></tr>" for k, v in rows)
    checks = {int(lc.leg): lc for lc in dr.leg_checks}

    def nees(leg: DRLeg, field: str, digits: int) -> str:
        lc = checks.get(int(leg.index))
        return "-" if lc is None else fmt(getattr(lc, field), digits)

    legs = _table(
        [
            "leg",
            "start",
            "end",
            "fix",
            "inside 2M",
            "scored",
            ("max error", "max error [m]"),
            "mean NEES",
            "last NEES",
            "NEES bound",
        ],
        [
            [
                str(leg.index),
                _e(iso_utc(leg.start_ns)),
                _e(iso_utc(leg.end_ns)),
                _e(leg.fix_source),
                fmt_pct(leg.containment_2m),
                str(leg.n_scored),
                fmt(leg.max_error_m, 0),
                nees(leg, "mean_nees", 2),
                nees(leg, "last_nees", 2),
                nees(leg, "nees_upper", 2),
            ]
            for leg in dr.legs
        ],
        left=4,
    )
    notes = "".join(f"<p>{_e(n)}</p>" for n in dr.notes)
    return (
        f'<table class="kv">{kv}</table>{notes}{_learned(dr.learned)}'
        f"<details><summary>Legs</summary>{legs}</details>"
    )


def _calibration_current(a: Analysis) -> str:
    out = []
    c = a.calibration
    if c is None:
        out.append('<p class="missing">Calibration not computed (see Missing).</p>')
    else:
        nd = c.not_determinable  # said in words, and why (issue 29)
        rows = [
            (
                "against",
                f"{_e(c.reference_role)} ({_e(calibration_method(c.method, c.n, c.segment_s))})",
            ),
            ("compass error", _est(c.compass_error_deg, "°")),
            ("log scale error", _est(c.log_scale, "%", scale=100.0)),
            ("log offset", _est(c.log_offset_kn, "kn")),
        ]
        for i, key in enumerate(("compass_error_deg", "log_scale", "log_offset_kn"), 1):
            if key in nd:
                rows[i] = (rows[i][0], f"NOT DETERMINABLE: {_e(nd[key])}")
        out.append(
            '<table class="kv">'
            + "".join(f"<tr><td>{k}</td><td>{v}</td></tr>" for k, v in rows)
            + "</table>"
        )
        out.extend(f"<p>{_e(n)}</p>" for n in c.notes)
    cur = a.current
    if cur is None:
        out.append('<p class="missing">Current not estimated (see Missing).</p>')
    else:
        out.append(
            f"<p>Current: set {_est(cur.set_deg, '°', 0)} (towards), drift "
            f"{_est(cur.drift_kn, 'kn')}, from {cur.n_updates} fix updates.</p>"
        )
        out.extend(f"<p>{_e(n)}</p>" for n in cur.notes)
    out.append(_aided_ep(a))
    return "".join(out)


def _aided_ep(a: Analysis) -> str:
    """The fix-updated EP (seeds/003's aided DR): its updates and the fix-interval table."""
    e = a.estimated_position
    if e is None:
        return ""
    r2m = [float(x) for x in e.radius_2m_m if math.isfinite(x)]
    out = [
        f'<h3 id="fix-updated-ep">{as_heading(FIX_UPDATED_EP)}</h3>'
        f"<p>{e.n_fix_updates} GNSS updates, {e.n_lop_updates} "
        f"from the observation file; 2M up to {max(r2m, default=math.nan):.0f} m "
        f"over {len(e.time_ns)} epochs.</p>"
    ]
    out.extend(f"<p>{_e(n)}</p>" for n in e.notes)
    if e.interval_study:
        rows = [
            [
                f"{r.interval_s:g} s",
                str(r.n_updates),
                f"{r.mean_2m_before_m:.0f} m",
                f"{r.max_2m_before_m:.0f} m",
                f"{100 * r.containment:.1f} %",
                f"{100 * r.expected_containment:.1f} %",
            ]
            for r in e.interval_study
        ]
        head: list[Header] = [
            "fix interval",
            "updates",
            "mean 2M before",
            "max 2M before",
            "inside 95 %",
            "stated",
        ]
        out.append(_table(head, rows))
    return "".join(out)


def _finding(f: Finding) -> str:
    reasons = "".join(f"<li>{_e(r)}</li>" for r in f.reasons)
    return (
        f'<li class="lvl-{f.level}" data-topic="{_e(f.topic)}">'
        f'<span class="lvl">{_e(f.label)}</span> <strong>{_e(f.topic)}</strong>: '
        f"{_e(f.headline)}" + (f"<ul>{reasons}</ul>" if reasons else "") + "</li>"
    )


def _verdict(v: Verdict) -> str:
    """The verdict block: the overall level and headline, then each part with its reasons.
    Every level is written out (OK, ATTENTION, FAIL, NOT CHECKED), not shown by colour only."""
    worst = (
        ""
        if v.worst is None
        else f'<p class="worst">{_e(v.worst.label)}: <strong>{_e(v.worst.unit)}</strong> '
        f"{_e(v.worst.channel)}: {_e(v.worst.detail)}.</p>"
    )
    return (
        '<section id="verdict-block"><h2>Verdict</h2>'
        f'<p class="overall lvl-{v.level}"><span class="lvl lvl-{v.level}">{_e(v.label)}</span> '
        f"{_e(v.headline)}</p>{worst}"
        '<ul class="verdict-list">' + "".join(_finding(f) for f in v.findings) + "</ul>"
        '<p>Every column and figure is explained in the <a href="#glossary">glossary</a>.</p>'
        "</section>"
    )


def _glossary() -> str:
    """Every term once, with its meaning and its equation label (METHODS.md)."""
    items = "".join(
        f'<dt id="{anchor(term)}">{_e(term)}'
        + (f' <span class="label">{_e(label)}</span>' if label else "")
        + f"</dt><dd>{_e(meaning)}</dd>"
        for term, (meaning, label) in GLOSSARY.items()
    )
    return (
        '<section id="glossary"><h2>Glossary</h2><p>Each column header links here; the '
        "labels are the equations of the methods (METHODS.md).</p>"
        f'<dl class="glossary">{items}</dl></section>'
    )


def _faults(a: Analysis, v: Verdict) -> str:
    """The sensor-fault section: the faults found, or "none found" (what was searched)
    distinct from "not checked" (and why not)."""
    fd = v.faults
    head = f'<span class="lvl lvl-{fd.level}">{_e(fd.label)}</span> {_e(fd.headline)}'
    if v.faults_state != FAULTS_FOUND:
        cls = "none-found" if fd.level == "ok" else "not-checked"
        reasons = "".join(f"<li>{_e(r)}</li>" for r in fd.reasons)
        return (
            f'<section id="faults"><h2>Sensor faults</h2><p class="{cls}">{head}</p>'
            + (f"<ul>{reasons}</ul>" if reasons else "")
            + "</section>"
        )
    return (
        f'<section id="faults"><h2>Sensor faults</h2><p class="found">{head}</p>'
        + _table(
            [
                "kind",
                "source",
                "role",
                ("start", "start (UTC)"),
                ("end", "end (UTC)"),
                "records",
                "what was seen",
            ],
            [
                [
                    _e(f.kind),
                    _e(f.source),
                    _e(f.role or "-"),
                    _e(short_utc(f.start_ns)),
                    _e(short_utc(f.end_ns)),
                    _e(f.n_records),
                    _e(f.message),
                ]
                for f in a.faults
            ],
            left=3,
        )
        + "</section>"
    )


def render_html(a: Analysis, ins: Finding | None = None) -> str:
    """The whole report as one HTML document (a string).  ``ins``: the INS accuracy
    part of the verdict judged elsewhere (the audit page's own judgement), else the
    analysis' own."""
    title = "dracc voyage analysis"
    if a.start_ns is not None:
        title += f" {short_utc(a.start_ns)}"
    missing = ""
    if a.missing:
        missing = (
            '<section id="missing"><h2>Missing</h2><div class="missing"><ul>'
            + "".join(f"<li>{_e(m)}</li>" for m in a.missing)
            + "</ul></div></section>"
        )
    v = verdict(a) if ins is None else with_ins(verdict(a), ins)
    faults = _faults(a, v)
    notes = ""
    if a.notes:
        notes = (
            '<section id="notes"><h2>Notes</h2><ul>'
            + "".join(f"<li>{_e(n)}</li>" for n in a.notes)
            + "</ul></section>"
        )
    from dracc.report import plots, track_plots  # matplotlib loads only when a page is drawn

    figures = "".join(
        [
            track_plots.figures_html(a),  # the overview and the leg panels
            track_plots.aided_ep_html(a),  # the fix-updated EP (seeds/003) over the DR
            _figure(
                plots.deviation_plot(a),
                "deviation plot",
                "Hourly deviations from the mean per unit and channel (the paper's Figure 1)",
                "fig-deviations",
            ),
            _figure(
                plots.growth_plot(a),
                "2M growth plot",
                "2M since the last fix against the actual DR error",
                "fig-growth",
            ),
            _figure(
                plots.honesty_plot(a),
                "stated against achieved",
                "Stated against achieved: a Stanford diagram of the scored epochs (the error "
                "against the 2M drawn; red crosses beyond it) and the PIT histogram (flat "
                "when the probability stated beside 2M is the one achieved)",
                "fig-honesty",
            ),
            _figure(
                plots.current_plot(a),
                "current plot",
                "Estimated current (set and drift)",
                "fig-current",
            ),
        ]
    )
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta http-equiv="Content-Security-Policy" content="{CSP}">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="dracc {_e(a.dracc_version)}">
<title>{_e(title)}</title>
<style>{_CSS}</style>
</head>
<body>
<h1>{_e(title)}</h1>
<p>Report schema {_e(a.schema)}, dracc {_e(a.dracc_version)}.</p>
{_verdict(v)}
<section id="summary"><h2>Summary</h2>{_summary(a)}</section>
{missing}
{faults}
<section id="dead-reckoning"><h2>Dead reckoning</h2>{_dr(a)}</section>
<section id="units"><h2>INS accuracy per unit</h2>{_units(a)}</section>
<section id="calibration"><h2>Calibration and current</h2>{_calibration_current(a)}</section>
<section id="plots"><h2>Plots</h2>{figures}</section>
{notes}
{_glossary()}
</body>
</html>
"""


def render_sections(a: Analysis, ins: Finding | None = None) -> tuple[str, str]:
    """(body, css) of the report without its page: for the audit page to embed, with
    the audit's INS accuracy judgement as ``ins`` (:func:`render_html`)."""
    page = render_html(a, ins)
    body = page.split("<body>", 1)[1].rsplit("</body>", 1)[0]
    body = body.split("</h1>", 1)[1] if "</h1>" in body else body
    return body, _CSS


def write_html(a: Analysis, path: str | Path) -> None:
    """Write the report atomically to ``path``."""
    atomic.write_text(path, render_html(a))
