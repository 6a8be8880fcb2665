"""Issue 32, counts: every count in one report agrees with the others and no figure
misleads (a named regression test for each)."""

from __future__ import annotations

import dataclasses
import re
from html import escape as html_escape

import pytest
from test_report import make_analysis

from dracc.core.numbers import counted
from dracc.math.integrity import Check, IntegrityResult
from dracc.report import html, terminal
from dracc.report.verdict import integrity_count, verdict


def _check(status: str, source: str = "GNSS", name: str = "jump") -> Check:
    return Check(
        "plausibility",
        name,
        source,
        "gnss",
        status,
        {"name": "x", "value": 1.0, "unit": "m"},
        {"value": 2.0, "unit": "m", "rule": "r"},
        {},
        0.001,
        f"{source}: {name} {status}",
        why_not="no clock" if status == "not_checked" else None,
    )


def _integrity(passed: int, skipped: int, failed: int = 0) -> IntegrityResult:
    checks = (
        [_check("pass") for _ in range(passed)]
        + [_check("not_checked", "MAG", "latency") for _ in range(skipped)]
        + [_check("fail") for _ in range(failed)]
    )
    return IntegrityResult(tuple(checks), (), 0, 1, 0.001)


def test_counted_says_one_and_many():
    assert counted(1, "segment") == "1 segment"
    assert counted(0, "segment") == "0 segments"
    assert counted(3, "fix", "fixes") == "3 fixes"
    assert counted(12_000, "line") == "12,000 lines"


def test_integrity_count_never_counts_the_checks_not_made_as_passed():
    # issue 32: "all 38 integrity checks made passed" above "all 42 checks passed"
    assert (
        integrity_count(_integrity(38, 4)) == "all 38 integrity checks made passed; 4 not checked"
    )
    assert integrity_count(_integrity(42, 0)) == "all 42 integrity checks passed"
    assert (
        integrity_count(_integrity(36, 4, 2))
        == "2 of 38 integrity checks made failed; 4 not checked"
    )
    assert integrity_count(_integrity(0, 3)) == "no integrity check could be made; 3 not checked"


def test_terminal_verdict_and_html_summary_state_one_integrity_count():
    a = dataclasses.replace(make_analysis("full"), integrity=_integrity(38, 4))
    count = "all 38 integrity checks made passed; 4 not checked"
    assert verdict(a).integrity.headline == count
    text = terminal.render_text(a, width=200)
    page = html.render_html(a)
    assert count in text and count in page
    # no other count of the integrity checks anywhere
    for doc in (text, page):
        assert not re.search(r"all 42\b|\b42 (integrity )?checks", doc), doc
    failed = dataclasses.replace(a, integrity=_integrity(36, 4, 2))
    text = terminal.render_text(failed, width=200)
    page = html.render_html(failed)
    count = "2 of 38 integrity checks made failed; 4 not checked"
    assert count in text and count in page and "of 42" not in text + page


def _audited(tmp_path, integrity: IntegrityResult | None = None):
    from test_audit_helpers import make_analysis as audit_analysis

    from dracc.pipeline.audit import AuditConfig, audit_night, facts_from_analysis
    from dracc.pipeline.state import StateStore

    a = audit_analysis("2026-11-19", m_y={"ins1": {"lat": 100.0, "course": 0.1}})
    if integrity is not None:
        a = dataclasses.replace(a, integrity=integrity)
    with StateStore(tmp_path / "s.sqlite") as store:
        return audit_night(
            facts_from_analysis(a),
            store=store,
            acfg=AuditConfig(required_sources=("ins1",)),
            seeds={},
            vessel="Aurora",
            night=None,
            content_hash="h",
            settings_hash="s",
        )


def test_audit_head_says_all_checks_passed_only_when_every_check_was_made(tmp_path):
    from dracc.report.audit_html import verdict_head
    from dracc.report.audit_text import format_summary

    assert verdict_head("ok", 0, 0) == "all checks passed"
    assert verdict_head("ok", 0, 1) == "all checks made passed; 1 not checked (listed below)"
    assert verdict_head("findings", 1, 3) == "1 finding; 3 not checked (listed below)"
    o = _audited(tmp_path)  # the first night: the accuracy window is not full
    head = format_summary(o).splitlines()[0]
    assert head.endswith(": all checks made passed; 1 not checked (listed below)")
    assert sum(ln.startswith("not checked: ") for ln in format_summary(o).splitlines()) == 1


def test_audit_finding_names_its_source_once(tmp_path):
    # issue 32: "[consistency] INS2 (ins2): ins2 (INS2): starts drifting ..."
    from dracc.report.audit_text import format_summary

    drift = dataclasses.replace(
        _check("fail", "INS2", "velocity"),
        check="consistency",
        role="ins2",
        message="ins2 (INS2): starts drifting from the mean of the other INS units",
    )
    o = _audited(tmp_path, IntegrityResult((drift,), (), 0, 1, 0.001))
    (line,) = [ln for ln in format_summary(o).splitlines() if "starts drifting" in ln]
    assert (
        line
        == "  - [consistency] INS2 (ins2): starts drifting from the mean of the other INS units"
    )


def test_audit_names_why_the_calibration_did_not_run(tmp_path):
    # issue 32: "Compass error not estimated (no heading or no reference)" on a night with
    # both: the fit itself failed, and its reason is in the analysis' Missing list
    from test_audit_helpers import make_analysis as audit_analysis

    from dracc.pipeline.audit import AuditConfig, evaluate, facts_from_analysis

    why = (
        "calibration not computed: log calibration: only 1 segment of 600 s have both log "
        "data and reference positions at their ends (need at least 4)"
    )
    a = audit_analysis("2026-11-19")
    a = dataclasses.replace(a, calibration=None, missing=(why,))
    _, skipped = evaluate(facts_from_analysis(a), AuditConfig())
    by_name = {s["name"]: s["why"] for s in skipped}
    assert by_name["compass_error"] == why and by_name["log_scale"] == why
    # no calibration because no dead reckoning ran: said as such, never 'no heading'
    a = dataclasses.replace(a, dead_reckoning=None, missing=("no speed log: ...",))
    _, skipped = evaluate(facts_from_analysis(a), AuditConfig())
    by_name = {s["name"]: s["why"] for s in skipped}
    assert "no dead reckoning to calibrate" in by_name["compass_error"]
    assert "no heading or no reference" not in by_name["compass_error"]


def _nmea(body: str) -> str:
    x = 0
    for b in body.encode():
        x ^= b
    return f"${body}*{x:02X}"


def test_a_speed_source_without_the_log_role_reads_once_after_speed(tmp_path):
    # issue 32: "speed speed source VW (...)" in the DR section
    from dracc.core.config import IngestConfig
    from dracc.ingest import read_logs
    from dracc.pipeline.selection import speed_series

    p = tmp_path / "vhw.log"
    p.write_text(
        "".join(
            f"2026-03-01T00:00:{k:02d}.000Z {_nmea('VWVHW,,T,,M,12.0,N,22.2,K')}\n"
            for k in range(10)
        )
    )
    v = read_logs([p], IngestConfig())
    for s in v.sources.values():
        s.roles = []
    got = speed_series(v, [])
    assert got is not None
    desc = got[3]
    assert desc.startswith("VW (VHW, through the water; chosen by evidence"), desc
    assert "speed source" not in desc


def test_one_calibration_segment_is_said_in_the_singular():
    # issue 32: "only 1 segments"
    import numpy as np
    import pytest

    from dracc.core.errors import InsufficientDataError
    from dracc.math.calibration import calibrate_from_track

    t = np.arange(0, 700, 1.0)
    rt = np.arange(0, 700, 10.0)
    lat = np.radians(54) + 6 * rt / 6378137.0
    with pytest.raises(InsufficientDataError, match="only 1 segment of 600 s has both"):
        calibrate_from_track(
            t, np.zeros_like(t), np.full_like(t, 6.0), rt, lat, np.full_like(rt, 0.3),
            max_ref_gap_s=60,
        )  # fmt: skip


def test_inspect_rate_is_the_epoch_rate_not_sentences_a_second(tmp_path):
    # issue 32: "3.01 Hz" for a 1 Hz INS that sends GGA, HDT and VTG each second
    from dracc.core.config import IngestConfig
    from dracc.ingest.inspect import inspect_logs
    from dracc.report.inspect_report import render_inspection_text

    lines = []
    for k in range(120):
        ts = f"2026-03-01T00:{k // 60:02d}:{k % 60:02d}.000Z"
        hms = f"00{k // 60:02d}{k % 60:02d}.00"
        lines += [
            f"{ts} {_nmea(f'INGGA,{hms},5436.0,N,01847.0,E,1,12,0.8,10.0,M,30.0,M,,')}",
            f"{ts} {_nmea('INHDT,60.0,T')}",
            f"{ts} {_nmea('INVTG,60.0,T,,M,12.0,N,22.2,K,A')}",
        ]
    p = tmp_path / "ins.nmea"
    p.write_text("\n".join(lines) + "\n")
    rep = inspect_logs([p], IngestConfig())
    (s,) = rep["sources"].values()
    assert sum(s["sentences"].values()) == 360
    assert abs(s["rate_hz"] - 1.0) < 1e-9 and s["rate_sentence"] in ("GGA", "HDT", "VTG")
    text = render_inspection_text(rep, width=200)
    assert " 1.00 " in text and "3.0" not in text
    assert "most frequent sentence type" in text  # the table says what its rate is


def test_watch_counts_lines_a_second_never_calls_them_hz():
    # issue 32: watch showed "rate Hz 3.01" for a 1 Hz INS sending three sentence types
    from rich.console import Console

    from dracc.pipeline.watch import SourceState, Watch
    from dracc.report.watch_view import status_view

    now = [1_772_323_200 * 10**9]
    w = Watch([], clock=lambda: now[0])
    st = w.state["INS1"] = SourceState()
    for k in range(60):
        for _ in range(3):  # GGA, HDT, VTG in one second
            st.add(now[0] + k * 10**9, None)
    now[0] += 60 * 10**9
    s = w.status()["sources"]["INS1"]
    assert "rate_hz" not in s and abs(s["lines_per_s"] - 3.0) < 0.1
    console = Console(width=160, record=True)
    console.print(status_view(w.status()))
    text = console.export_text()
    assert "lines/s" in text and "Hz" not in text


def test_k_star_direction_is_a_word_and_dash_only_no_value():
    # issue 32: "1.61 -" (k underestimates) beside "-" (no reference) in the k* column
    from dracc.report.glossary import GLOSSARY
    from dracc.report.rows import K_STAR_NOTE, k_star_text, unit_rows

    assert k_star_text(0.53, "+") == "0.53 k ok"
    assert k_star_text(1.61, "-") == "1.61 k low"
    assert k_star_text(float("nan"), "") == "-"
    a = make_analysis("full")
    cells = [r.k_star for _, rs in unit_rows(a.deviation) for r in rs or ()]
    assert "-" in cells  # a channel without a reference
    assert all(c == "-" or re.fullmatch(r"[0-9.]+ k (ok|low)", c) for c in cells), cells
    assert any(c.endswith("k low") for c in cells) and any(c.endswith("k ok") for c in cells)
    text = terminal.render_text(a, width=200)
    assert not re.search(r"\d \+$|\d -$", text, re.MULTILINE)
    page = html.render_html(a)
    assert K_STAR_NOTE in " ".join(text.split())  # the note under the table
    assert html_escape(K_STAR_NOTE) in page
    assert GLOSSARY["k*"][0].startswith(K_STAR_NOTE)


def _nights(tmp_path, ends: list[str], acfg):
    """Audit one night per end time (each from its midnight), ins1 lat m_y 100, 120, ..."""
    from test_audit_helpers import make_analysis as audit_analysis

    from dracc.pipeline.audit import audit_night, facts_from_analysis
    from dracc.pipeline.state import StateStore

    outs = []
    with StateStore(tmp_path / "w.sqlite") as store:
        for i, end in enumerate(ends):
            night = f"2026-11-{17 + i}"
            a = audit_analysis(
                night, m_y={"ins1": {"lat": 100.0 + 20 * i}}, period=(f"{night}T00:00:00Z", end)
            )
            outs.append(
                audit_night(
                    facts_from_analysis(a),
                    store=store,
                    acfg=acfg,
                    seeds={},
                    vessel="Aurora",
                    night=None,
                    content_hash=night,
                    settings_hash="s",
                )
            )
    return outs


def test_accuracy_window_is_never_longer_than_configured(tmp_path):
    # issue 32: "accuracy window: 96.0 h of 72 h": three logs of 00:00:00-23:59:59 fell
    # 3 s short of 72 h and took a whole fourth night
    from dracc.pipeline.audit import AuditConfig
    from dracc.report.audit_text import format_summary

    ends = [f"2026-11-{17 + i}T23:59:59Z" for i in range(4)]
    last = _nights(tmp_path, ends, AuditConfig())[-1]
    acc = last.accuracy
    assert acc["complete"] and len(acc["nights"]) == 3 and acc["partial"] is None
    assert acc["hours"] == pytest.approx(72.0, abs=0.01)
    line = next(ln for ln in format_summary(last).splitlines() if ln.startswith("accuracy window"))
    assert line == "accuracy window: 72.0 h of 72 h over 3 nights"


def test_accuracy_window_takes_the_part_of_the_oldest_night_it_needs(tmp_path):
    # 26 h logs: 26 + 26 h and 20 h of the oldest night, its statistics weighted 20/26
    import math

    from dracc.core.config import DeviationConfig
    from dracc.math.deviation import stats
    from dracc.pipeline.audit import AuditConfig
    from dracc.report.audit_text import format_summary

    ends = [f"2026-11-{18 + i}T02:00:00Z" for i in range(3)]
    last = _nights(tmp_path, ends, AuditConfig())[-1]
    acc = last.accuracy
    assert acc["complete"] and acc["hours"] == pytest.approx(72.0)
    assert acc["partial"] == {"night": "2026-11-17", "hours": pytest.approx(20.0), "of_hours": 26.0}
    line = next(ln for ln in format_summary(last).splitlines() if ln.startswith("accuracy window"))
    assert line == (
        "accuracy window: 72.0 h of 72 h over 3 nights (2026-11-17 in part: 20.0 h of its 26.0 h)"
    )
    (row,) = [c for c in acc["channels"] if (c["unit"], c["channel"]) == ("ins1", "lat")]
    w, n, k, d = (20 / 26, 1, 1), 24, 1.32, DeviationConfig()
    m_y = (100.0, 120.0, 140.0)
    m_u = math.sqrt(sum(wi * n * (v / k) ** 2 for wi, v in zip(w, m_y, strict=True)) / (n * sum(w)))
    n_eff = sum(w) * float(stats.effective_samples(n, d.interval_s, d.correlation_time_s))
    want = float(stats.limiting_error(k * m_u, d.probability, -0.3, d.confidence, n_eff)[0])
    assert row["limit_error"] == pytest.approx(want, rel=1e-9)


def _with_apriori(a, apriori: dict[tuple[str, str], float]):
    """``a`` with the a priori RMS of the given (unit, channel)s (the others: none)."""
    d = a.deviation
    units = {}
    for name, u in d.whole.units.items():
        chans = {}
        for ch, c in u.channels.items():
            ap = apriori.get((name, ch))
            chans[ch] = dataclasses.replace(
                c, apriori=ap, exceeds_apriori=None if ap is None else c.m_y > ap
            )
        units[name] = dataclasses.replace(u, channels=chans)
    whole = dataclasses.replace(d.whole, units=units)
    return dataclasses.replace(a, deviation=dataclasses.replace(d, whole=whole))


def test_the_unit_that_stands_out_says_by_which_rule_in_every_report():
    # issue 32: "Worst INS unit" was the largest m_y against the median without an a
    # priori and the largest ratio to its own a priori with one: it named a good unit
    import jsonschema

    from dracc.report import json_report

    base = make_analysis("full")
    m = {
        (n, ch): c.m_y
        for n, u in base.deviation.whole.units.items()
        for ch, c in u.channels.items()
    }
    # every unit within its a priori: the one closest to it is named as such, not "worst"
    a = _with_apriori(
        base, {k: 2 * v for k, v in m.items()} | {("ins1", "lat"): m["ins1", "lat"] / 0.9}
    )
    v = verdict(a)
    assert v.worst.label == "INS unit closest to its a priori RMS"
    assert (v.worst.unit, v.worst.channel) == ("ins1", "lat") and not v.worst.out_of_limits
    assert v.headline.endswith("; INS unit closest to its a priori RMS: ins1 (lat)")
    assert "worst" not in v.headline.lower() and "worst" not in v.ins.headline.lower()
    page = html.render_html(a)
    assert "INS unit closest to its a priori RMS: <strong>ins1</strong>" in page
    doc = json_report.to_dict(a)
    jsonschema.validate(doc, json_report.load_schema())
    assert doc["worst_ins_unit"]["rule"] == v.worst.label
    assert (doc["worst_ins_unit"]["ins_unit"], doc["worst_ins_unit"]["channel"]) == ("ins1", "lat")
    # one above its a priori: the furthest over it
    a = _with_apriori(
        base, {k: 2 * v for k, v in m.items()} | {("ins3", "lon"): m["ins3", "lon"] / 1.5}
    )
    v = verdict(a)
    assert v.worst.label == "INS unit furthest over its a priori RMS"
    assert (v.worst.unit, v.worst.channel) == ("ins3", "lon")
    assert json_report.to_dict(a)["worst_ins_unit"]["rule"] == v.worst.label
    # nothing configured: the largest m_y against the others, in the terminal too
    a = _with_apriori(base, {})
    v = verdict(a)
    assert v.worst.label == "INS unit with the largest m_y against the others"
    assert f"{v.worst.label}: {v.worst.unit} ({v.worst.channel})" in terminal.render_text(a, 200)
    assert json_report.to_dict(a)["worst_ins_unit"]["basis"] == "other units"


def test_the_audit_page_and_document_name_the_same_unit_by_the_same_rule(tmp_path):
    # the audit judges against its own a priori (raised on the first night): within every
    # one, where the configured a priori are all exceeded; page and JSON say the same
    from test_audit_page import _second_night

    from dracc.report import audit_json
    from dracc.report.audit_html import audit_page

    o = _second_night(tmp_path)
    doc = audit_json.to_dict(o)
    w = doc["analysis"]["worst_ins_unit"]
    assert w["rule"] == "INS unit closest to its a priori RMS" and not w["out_of_limits"]
    page = audit_page(o, doc)
    assert f"{w['rule']}: <strong>{w['ins_unit']}</strong> {w['channel']}" in page
    assert "furthest over" not in page
