"""The audit page of one night (``dracc audit --html``) can be read (issue 32).

Its embedded analysis judges INS accuracy by the audit's own judgement (the a priori
rule's values and the audit's accuracy findings), not against the configured a priori
the audit has already raised; its windows show UTC times or "no data", never "None";
and at a 1280x800 window the page does not scroll sideways (a real browser measures it).
"""

from __future__ import annotations

import html
import re
from dataclasses import replace

import pytest
from test_audit_helpers import make_analysis

from dracc.math.deviation.results import ChannelMode
from dracc.pipeline.audit import AuditConfig, audit_night, facts_from_analysis
from dracc.pipeline.state import StateStore
from dracc.report import audit_json
from dracc.report.audit_html import audit_page, night_html, window_text

NIGHTS = ("2026-11-19", "2026-11-20")
UNITS = ("ins1", "ins2", "ins3")
M_Y = {u: {"lat": 100.0, "lon": 150.0, "course": 0.1} for u in UNITS}
#: the configured a priori: far below m_y, so the first night raises every channel
CONFIGURED = {(u, ch): {"lat": 3.0, "lon": 3.0, "course": 0.01}[ch] for u in UNITS for ch in M_Y[u]}


def _configured(a):
    """``a`` as the analysis judges it against the configured a priori (CONFIGURED)."""
    d = a.deviation
    units = {}
    for name, u in d.whole.units.items():
        chans = {}
        for ch, c in u.channels.items():
            ap = CONFIGURED[(name, ch)]
            chans[ch] = replace(
                c, apriori=ap, exceeds_apriori=c.m_y > ap, new_apriori=max(ap, c.m_y),
                verdict="exceeds" if c.m_y > ap else "within",
            )  # fmt: skip
        units[name] = replace(u, channels=chans)
    modes = {  # the helper leaves the channels' modes out; the report prints their k
        ch: ChannelMode(UNITS, "three", k, None)
        for ch, k in {"lat": 1.32, "lon": 1.49, "course": 1.49}.items()
    }
    return replace(a, deviation=replace(d, whole=replace(d.whole, units=units), channels=modes))


def _second_night(tmp_path, acfg=None):
    """Two nights with the same m_y: the first raises every a priori, the second is
    'within' every one of them, while the configured a priori are all exceeded."""
    with StateStore(tmp_path / "s.sqlite") as store:
        for night in NIGHTS:
            a = _configured(make_analysis(night, m_y=M_Y))
            o = audit_night(
                facts_from_analysis(a),
                store=store,
                acfg=acfg or AuditConfig(),
                seeds=CONFIGURED,
                vessel="Aurora",
                night=night,
                content_hash=night,
                settings_hash="s",
            )
    return replace(o, analysis=a)


def _text(fragment: str) -> str:
    return re.sub(r"\s+", " ", html.unescape(re.sub(r"<[^>]+>", " ", fragment)))


def _ins_part(page: str) -> str:
    block = re.search(r'<section id="verdict-block">.*?</section>', page, re.S).group(0)
    part = block.split('data-topic="INS accuracy">', 1)[1].split('<li class="lvl-', 1)[0]
    return _text(part).strip()


def _units_verdicts(page: str) -> list[tuple[str, str, str, str]]:
    """(unit, channel, a priori, verdict) of the embedded 'INS accuracy per unit' table."""
    sec = re.search(r'<section id="units">.*?</section>', page, re.S).group(0)
    rows = re.findall(r"<tr>(<td.*?)</tr>", sec, re.S)
    cells = [[_text(c).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", r, re.S)] for r in rows]
    return [(c[0], c[1].split(" ")[0], c[7], c[8]) for c in cells]


def test_the_page_and_its_analysis_agree_on_the_a_priori_verdicts(tmp_path):
    o = _second_night(tmp_path)
    doc = audit_json.to_dict(o)
    assert {c["verdict"] for c in doc["ins"]} == {"within"}  # the audit: within every one
    page = audit_page(o, doc)
    # the embedded table shows the a priori the audit judged against, and its verdicts
    rows = _units_verdicts(page)
    assert len(rows) == len(doc["ins"]) == 9
    audit = {(c["unit"], c["channel"]): c for c in doc["ins"]}
    for unit, ch, apriori, word in rows:
        c = audit[(unit, ch)]
        assert word == "within", (unit, ch, word)
        assert float(apriori.replace(",", "")) == pytest.approx(c["apriori_before"], rel=1e-3)
    # the verdict block: no FAIL against the configured a priori the audit has raised
    part = _ins_part(page)
    assert "FAIL" not in part and "x its a priori RMS 3.0" not in page
    assert "a priori rule max(a priori, m_y): within for 9 unit channels" in part
    # the 24 h nights leave the 72 h accuracy window short: said as the audit says it
    assert part.startswith("NOT CHECKED INS accuracy : limits not checked: limit:")
    nc = [n for n in doc["not_checked"] if n["check"] == "accuracy"]
    assert nc and html.unescape(nc[0]["why"]) in part
    # and the page says which rule each judgement uses
    assert "How INS accuracy is judged on this page" in _text(page)


def _tight_limits() -> AuditConfig:
    """Limits every unit channel exceeds, judged over a 6 h accuracy window."""
    return replace(
        AuditConfig(),
        accuracy_window_h=6.0,
        limits={"all": {"lat_m": 1.0, "lon_m": 1.0, "course_deg": 0.0001}},
    )


def test_accuracy_findings_are_the_embedded_ins_verdict(tmp_path):
    acfg = _tight_limits()
    o = _second_night(tmp_path, acfg)
    doc = audit_json.to_dict(o)
    found = [f for f in doc["findings"] if f["check"] == "accuracy"]
    assert len(found) == 9
    part = _ins_part(audit_page(o, doc))
    assert part.startswith("FAIL INS accuracy : 9 audit findings on accuracy")
    for f in found:
        assert f["message"] in part


def test_window_text_is_utc_or_no_data_never_none():
    assert window_text({"start_utc": None, "end_utc": None}) == "no data"
    assert window_text(None) == "no data" and window_text({}) == "no data"
    assert (
        window_text({"start_utc": "2026-11-20T00:00:00Z", "end_utc": "2026-11-20T08:00:00Z"})
        == "2026-11-20T00:00:00Z to 2026-11-20T08:00:00Z"
    )
    assert window_text({"start_utc": "2026-11-20T00:00:00Z", "end_utc": None}) == (
        "from 2026-11-20T00:00:00Z"
    )
    assert window_text({"nights": ["2026-11-19", "2026-11-20"], "hours": 48.0}) == (
        "2026-11-19, 2026-11-20; 48.0 h"
    )


def test_the_window_line_shows_utc_times_or_no_data(tmp_path):
    o = _second_night(tmp_path)
    doc = audit_json.to_dict(o)
    f = {
        "check": "integrity", "source": None, "role": "gnss", "clause": "5.3",
        "statistic": {"name": "gap", "value": 1.0, "unit": "s"},
        "threshold": {"value": 0.5, "unit": "s", "rule": "r"},
        "evidence": [], "message": "a gap",
    }  # fmt: skip
    doc["findings"] = [
        {**f, "window": {"start_utc": "2026-11-20T01:00:00Z", "end_utc": "2026-11-20T02:00:00Z"}},
        {**f, "window": {"start_utc": None, "end_utc": None}},
    ]
    doc["logs"]["period"] = {"start_utc": None, "end_utc": None}
    text = _text(night_html(doc))
    assert "None" not in text
    assert "2026-11-20T01:00:00Z to 2026-11-20T02:00:00Z" in text
    assert re.search(r"window .*no data", text) and "Period no data." in text
    # the audit's own document: the period in UTC
    assert "Period 2026-11-20T00:00:00Z to 2026-11-20T23:59:59Z." in _text(audit_page(o, None))


PROBE = """<!DOCTYPE html><html><body style="margin:0"><pre id="result">pending</pre>
<iframe id="f" src="PAGE" style="width:1280px;height:800px;border:0"></iframe>
<script>
window.addEventListener('load', function () {
  var d = document.getElementById('f').contentDocument, w = d.defaultView;
  var cells = Array.prototype.map.call(d.querySelectorAll('#findings td.message'),
    function (c) { var r = c.getBoundingClientRect(); return [r.left, r.right]; });
  document.getElementById('result').textContent = JSON.stringify({
    scroll: d.documentElement.scrollWidth, inner: w.innerWidth, cells: cells});
});
</script></body></html>
"""


@pytest.mark.slow
def test_the_page_fits_a_1280_px_window_in_a_real_browser(tmp_path):
    """Long finding messages (and a long unbroken token) wrap: the page is no wider than
    the 1280x800 window and every finding's message cell lies inside it."""
    from test_report_html import probe_result

    acfg = _tight_limits()
    o = _second_night(tmp_path, acfg)
    doc = audit_json.to_dict(o)
    long = " ".join(["the limiting error of this unit channel is above its limit"] * 8)
    for i, f in enumerate(doc["findings"]):
        f["message"] = f"{i}: {long} /var/log/nav/" + "x" * 200
    assert len(doc["findings"]) == 9
    page = tmp_path / "page.html"
    page.write_text(audit_page(o, doc), encoding="utf-8")
    data = probe_result(tmp_path, page, PROBE.replace("PAGE", page.name))
    assert data["inner"] == 1280
    assert data["scroll"] <= 1280, data
    assert len(data["cells"]) == 9
    for left, right in data["cells"]:
        assert 0 <= left < right <= 1280, data["cells"]
