"""The HTML report in a real headless browser (Debian's chromium).

The report is loaded in an iframe of a probe page whose script lists, after the load
event, every image (decoded size), every heading and any script element; Chromium's
``--dump-dom`` prints the probe page with that list.  A NetLog of the run shows
every URL the browser requested: the report must request none (the hostile variant
carries an ``<img src="http://example.com/...">`` in its source names, escaped).
When ``CI=true`` the test must not skip: a missing browser is a failure there.
"""

from __future__ import annotations

import html as html_lib
import json
import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import pytest
from test_report import HOSTILE, _not_learned, make_analysis

from dracc.core.geodesy import offset_ne_m
from dracc.report import plots
from dracc.report.html import CSP, render_html, write_html

pytestmark = pytest.mark.slow

PROBE = """<!DOCTYPE html><html><body><pre id="result">pending</pre>
<iframe id="f" src="REPORT" style="width:1200px;height:900px"></iframe>
<script>
window.addEventListener('load', function () {
  var d = document.getElementById('f').contentDocument;
  var imgs = Array.prototype.map.call(d.querySelectorAll('img'), function (i) {
    return {alt: i.alt, complete: i.complete, w: i.naturalWidth, h: i.naturalHeight,
            scheme: i.getAttribute('src').split(':')[0]}; });
  var heads = Array.prototype.map.call(d.querySelectorAll('h1,h2,h3'),
                                       function (h) { return h.textContent; });
  var w = d.defaultView;
  var sections = Array.prototype.map.call(d.querySelectorAll('body > section'),
                                          function (s) { return s.id; });
  var ths = Array.prototype.map.call(d.querySelectorAll('th'), function (t) {
    var a = t.querySelector('a'); return a ? a.getAttribute('href') : null; });
  var terms = Array.prototype.map.call(d.querySelectorAll('#glossary dt'),
                                       function (t) { return t.id; });
  var fp = d.querySelector('#faults > p'), fs = fp ? w.getComputedStyle(fp) : null;
  var vb = d.getElementById('verdict-block');
  var out = {imgs: imgs, heads: heads, scripts: d.querySelectorAll('script').length,
             links: d.querySelectorAll('link[href],iframe,object,embed').length,
             body: d.body.innerText, sections: sections, ths: ths, terms: terms,
             verdict: vb ? vb.innerText : null,
             faults: fp ? {cls: fp.className, text: fp.innerText, color: fs.color,
                           border: fs.borderLeftStyle + ' ' + fs.borderLeftColor,
                           font: fs.fontStyle} : null};
  document.getElementById('result').textContent = JSON.stringify(out);
});
</script></body></html>
"""

#: hosts Chromium itself contacts (updates, time, accounts), not the page
_BROWSER_HOSTS = ("google.com", "googleapis.com", "gvt1.com", "gstatic.com")


def _chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail("CI=true but no chromium on PATH: the browser test must run in CI")
    pytest.skip("chromium not installed (apt-get install chromium)")


def _run(tmp_path: Path, report: Path, *extra: str) -> subprocess.CompletedProcess:
    cmd = [
        _chromium(),
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={tmp_path / 'profile'}",
        *extra,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)


def probe_result(tmp_path: Path, page: Path, probe_html: str, *extra: str) -> Any:
    """Open ``probe_html`` (written beside ``page``, which it loads) in the real browser and
    return the JSON its ``<pre id="result">`` holds."""
    import html as _html

    probe = page.parent / "probe.html"
    probe.write_text(probe_html, encoding="utf-8")
    res = _run(
        tmp_path, page, "--allow-file-access-from-files", *extra, "--dump-dom", probe.as_uri()
    )
    m = re.search(r'<pre id="result">(.*?)</pre>', res.stdout, re.S)
    assert m, f"no probe result; chromium said: {res.stderr[-2000:]}"
    return json.loads(_html.unescape(m.group(1)))


def _probe(tmp_path: Path, report: Path) -> tuple[dict, list[str]]:
    netlog = tmp_path / "net.json"
    data = probe_result(
        tmp_path, report, PROBE.replace("REPORT", report.name), f"--log-net-log={netlog}"
    )
    urls = re.findall(r'"url":"([^"]*)"', netlog.read_text(encoding="utf-8", errors="replace"))
    return data, urls


def test_html_in_real_browser(tmp_path):
    """The hostile variant has every section of the full one, plus markup in its log strings."""
    report = tmp_path / "report.html"
    write_html(make_analysis("hostile"), report)
    data, urls = _probe(tmp_path, report)
    imgs = data["imgs"]
    alts = [i["alt"] for i in imgs]
    legs = [x for x in alts if x.startswith("track plot, leg ")]
    assert [x for x in alts if x not in legs] == [
        "track plot",
        "deviation plot",
        "2M growth plot",
        "current plot",
    ]
    assert len(legs) >= 1  # the overview, then a panel per leg (the worst 8 at most)
    for i in imgs:
        assert i["complete"] and i["w"] > 300 and i["h"] > 200, i
        assert i["scheme"] == "data"
    heads = data["heads"]
    for h in (
        "Summary",
        "Sources",
        "Missing",
        "Dead reckoning",
        "INS accuracy per unit",
        "Calibration and current",
        "Plots",
    ):
        assert h in heads
    assert data["scripts"] == 0 and data["links"] == 0
    page_urls = [
        u
        for u in urls
        if not u.startswith(("file:", "data:"))
        and not any(host in u.split("/")[2] for host in _BROWSER_HOSTS)
    ]
    assert not page_urls, page_urls
    assert not any("example.com" in u for u in urls)
    # the hostile text shows as text, it did not become markup
    assert HOSTILE in data["body"]
    # the estimated position: the learned model with its config block, NEES, the water track
    assert "Learned model" in heads
    body = data["body"]
    assert "NEES\t36.0 over 24 scored legs" in body
    assert "[dead_reckoning]\nlearn = false\n" in body
    assert "water track (heading and log only), thin dashed" in body


def test_html_dead_reckoning_shows_nees_and_the_learned_model():
    a = make_analysis("full")
    text = render_html(a)
    dr_part = text.split('<section id="dead-reckoning">', 1)[1].split("</section>", 1)[0]
    assert (
        '<td><a class="g" href="#g-nees">NEES</a></td><td>36.0 over 24 scored legs (χ² bounds '
        "26.5–77.0); mean per epoch 1.65" in dr_part
    )
    assert (
        "out of sample" in dr_part and "5 epochs of earlier legs (prior only) not scored" in dr_part
    )
    assert (
        "<td>largest part of the 2M</td><td>the change of the current (prior: [dead_reckoning] "
        "current_kn)</td>" in dr_part
    )
    # the compass and log errors once, in the calibration section (issue 31)
    assert "heading correction" not in dr_part and "log scale correction" not in dr_part
    assert '<td>compass and log errors</td><td><a href="#calibration">Calibration</a>' in dr_part
    cal_part = text.split('<section id="calibration">', 1)[1].split("</section>", 1)[0]
    assert (
        "<td>against</td><td>gnss (learned with the DR over the ground from 288 "
        "fixes)</td>" in cal_part
    )
    assert "set 45° (towards), drift 0.49 kn" in dr_part
    # the config block verbatim (escaped) in a <pre>
    block = html_lib.escape(a.dead_reckoning.learned["config_block"], quote=True)
    assert f'<pre class="config">{block}</pre>' in dr_part
    # per leg: NEES where scored, '-' for leg 0 (prior only)
    assert (
        '<th><a class="g" href="#g-mean-nees">mean NEES</a></th><th><a class="g" '
        'href="#g-last-nees">last NEES</a></th><th><a class="g" href="#g-nees-bound">NEES '
        "bound</a></th>" in dr_part
    )
    assert "<td>0</td><td>-</td><td>-</td><td>-</td><td>-</td></tr>" in dr_part
    assert "<td>45</td><td>1.70</td><td>2.00</td><td>9.21</td></tr>" in dr_part


def test_html_without_a_learned_model_says_so():
    text = render_html(_not_learned(make_analysis("full")))
    assert "Learned model" not in text and "<pre" not in text
    assert "nothing learned" in text and "the dead-reckoning track (the water track" in text


def _overview(a):
    from dracc.report.track_plots import draw_track_panels

    panels = list(draw_track_panels(a))
    for p in panels[1:]:
        plt.close(p.fig)
    assert panels[0].leg is None  # the overview comes first
    return panels[0]


def test_track_overview_draws_the_water_track_and_the_estimated_position():
    a = make_analysis("full")
    over = _overview(a)
    try:
        lines = {ln.get_label(): ln for ln in over.ax.get_lines()}
        water, ep = lines[plots.WATER_LABEL], lines[plots.EP_LABEL]
        assert water.get_linestyle() == "--" and water.get_linewidth() < ep.get_linewidth()
        assert ep.get_linestyle() == "-"
        tr = a.dead_reckoning.track
        lat0, lon0 = float(tr.lat_rad[0]), float(tr.lon_rad[0])
        for line, (lat, lon) in (
            (water, (tr.water_lat_rad, tr.water_lon_rad)),
            (ep, (tr.lat_rad, tr.lon_rad)),
        ):
            n, e = offset_ne_m(lat, lon, lat0, lon0)
            x, y = (np.asarray(v, float) for v in line.get_data())
            ok = np.isfinite(x)  # NaN breaks at the restarts
            assert ok.sum() == len(n) and np.isnan(x).sum() == 24
            np.testing.assert_allclose(x[ok], e / 1e3)
            np.testing.assert_allclose(y[ok], n / 1e3)
        # the two tracks differ (by the learned current: 0.25 m/s for up to an hour)
        wx, ex = np.asarray(water.get_xdata(), float), np.asarray(ep.get_xdata(), float)
        assert np.nanmax(np.abs(ex - wx)) > 0.5
    finally:
        plt.close(over.fig)
    # learn = false: the DR is the water track, drawn once
    over = _overview(_not_learned(a))
    try:
        labels = [ln.get_label() for ln in over.ax.get_lines()]
        assert (
            plots.DR_LABEL in labels
            and plots.WATER_LABEL not in labels
            and plots.EP_LABEL not in labels
        )
    finally:
        plt.close(over.fig)


def test_html_bare_shows_missing_and_only_the_track():
    text = render_html(make_analysis("bare"))
    assert text.count("<img ") == 1 and 'alt="track plot"' in text
    assert "no INS triple" in text and "no heading" in text
    assert text.count("nothing to plot (see Missing)") == 4


def test_html_screenshot_is_not_blank(tmp_path):
    report = tmp_path / "report.html"
    write_html(make_analysis("full"), report)
    shot = tmp_path / "shot.png"
    _run(
        tmp_path,
        report,
        "--window-size=1200,2400",
        "--hide-scrollbars",
        f"--screenshot={shot}",
        report.as_uri(),
    )
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[0] == 2400 and img.shape[1] == 1200
    assert img[..., :3].std() > 0.05  # text, tables and plots, not an empty page


def test_html_is_self_contained_text():
    text = render_html(make_analysis("hostile"))
    assert CSP in text and "default-src 'none'" in text
    assert "<script" not in text.replace("&lt;script", "")
    assert 'src="http' not in text
    # the only links are to the page's own glossary (fragments), never out of the page
    hrefs = re.findall(r'href="([^"]*)"', text)
    assert hrefs and all(h.startswith("#") for h in hrefs)
    ids = set(re.findall(r'id="([^"]*)"', text))
    assert {h[1:] for h in hrefs} <= ids


@pytest.fixture(scope="module")
def sample_reports(tmp_path_factory):
    """The sample voyage's report ("none found") and its speed log alone ("not checked")."""
    from dataclasses import replace

    from dracc.core.config import IngestConfig
    from dracc.frames import empty_frame
    from dracc.ingest import read_logs
    from dracc.pipeline.analysis import analyse_voyage

    tag = Path(__file__).resolve().parents[1] / "sample_logs" / "voyage_tag.nmea"
    v = read_logs([tag], IngestConfig())
    only_log = replace(
        v,
        frames={k: (f if k == "water" else empty_frame(k)) for k, f in v.frames.items()},
        sources={k: s for k, s in v.sources.items() if k == "LOG"},
    )
    out = tmp_path_factory.mktemp("sample_reports")
    paths = (out / "sample.html", out / "log_only.html")
    write_html(analyse_voyage(v), paths[0])
    write_html(analyse_voyage(only_log), paths[1])
    return paths


def test_verdict_block_and_glossary_in_a_real_browser(tmp_path, sample_reports):
    """The verdict is the page's first section and names the truly worst unit (INS2 in
    sample_logs/params.json); every column header links to a glossary entry; "none found"
    and "not checked" look different (class, label, border and colour)."""
    truth = json.loads(
        (Path(__file__).resolve().parents[1] / "sample_logs" / "params.json").read_text()
    )["unit_rms"]
    worst = max(truth, key=lambda u: truth[u]["lat_m"] ** 2 + truth[u]["lon_m"] ** 2).lower()
    data, _ = _probe(tmp_path, sample_reports[0])
    assert data["sections"][0] == "verdict-block" and data["heads"][1] == "Verdict"
    assert f"INS unit with the largest m_y against the others: {worst}" in data["verdict"]
    for label in ("OK", "NOT CHECKED"):  # levels in words, not colour only
        assert label in data["verdict"]
    assert data["ths"] and all(h and h[1:] in data["terms"] for h in data["ths"]), data["ths"]
    assert data["sections"][-1] == "glossary" and len(data["terms"]) == len(set(data["terms"]))
    found = data["faults"]
    data2, _ = _probe(tmp_path / "2", sample_reports[1])
    unchecked = data2["faults"]
    assert found["cls"] == "none-found" and found["text"].startswith("OK none found")
    assert unchecked["cls"] == "not-checked"
    assert unchecked["text"].startswith("NOT CHECKED sensor faults not checked")
    assert found["border"] != unchecked["border"] and found["font"] != unchecked["font"]
    assert "NOT CHECKED" in data2["verdict"] and "INS unit with" not in data2["verdict"]
