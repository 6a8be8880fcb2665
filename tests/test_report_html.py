"""The HTML report in a real headless browser (Debian's chromium).

The report is loaded in an iframe of a probe page whose script lists, after the load
event, every image (decoded size), every heading and any script element; Chromium's
``--dump-dom`` prints the probe page with that list.  A NetLog of the run shows
every URL the browser requested: the report must request none (the hostile variant
carries an ``<img src="http://example.com/...">`` in its source names, escaped).
When ``CI=true`` the test must not skip: a missing browser is a failure there.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from test_report import HOSTILE, make_analysis

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
  var out = {imgs: imgs, heads: heads, scripts: d.querySelectorAll('script').length,
             links: d.querySelectorAll('link[href],iframe,object,embed').length,
             body: d.body.innerText};
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
    cmd = [_chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
           "--no-first-run", "--disable-background-networking", "--disable-component-update",
           "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}", *extra]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120, check=False)


def _probe(tmp_path: Path, report: Path) -> tuple[dict, list[str]]:
    probe = report.parent / "probe.html"
    probe.write_text(PROBE.replace("REPORT", report.name), encoding="utf-8")
    netlog = tmp_path / "net.json"
    res = _run(tmp_path, report, "--allow-file-access-from-files", f"--log-net-log={netlog}",
               "--dump-dom", probe.as_uri())
    m = re.search(r'<pre id="result">(.*?)</pre>', res.stdout, re.S)
    assert m, f"no probe result; chromium said: {res.stderr[-2000:]}"
    import html as _html

    data = json.loads(_html.unescape(m.group(1)))
    urls = re.findall(r'"url":"([^"]*)"', netlog.read_text(encoding="utf-8", errors="replace"))
    return data, urls


def test_html_in_real_browser(tmp_path):
    """The hostile variant has every section of the full one, plus markup in its log strings."""
    report = tmp_path / "report.html"
    write_html(make_analysis("hostile"), report)
    data, urls = _probe(tmp_path, report)
    imgs = data["imgs"]
    assert [i["alt"] for i in imgs] == ["track plot", "deviation plot", "2M growth plot", "current plot"]
    for i in imgs:
        assert i["complete"] and i["w"] > 300 and i["h"] > 200, i
        assert i["scheme"] == "data"
    heads = data["heads"]
    for h in ("Summary", "Sources", "Missing", "Dead reckoning", "INS accuracy per unit",
              "Calibration and current", "Plots"):
        assert h in heads
    assert data["scripts"] == 0 and data["links"] == 0
    page_urls = [u for u in urls if not u.startswith(("file:", "data:"))
                 and not any(host in u.split("/")[2] for host in _BROWSER_HOSTS)]
    assert not page_urls, page_urls
    assert not any("example.com" in u for u in urls)
    # the hostile text shows as text, it did not become markup
    assert HOSTILE in data["body"]


def test_html_bare_shows_missing_and_only_the_track():
    text = render_html(make_analysis("bare"))
    assert text.count("<img ") == 1 and 'alt="track plot"' in text
    assert "no INS triple" in text and "no heading" in text
    assert text.count("nothing to plot (see Missing)") == 3


def test_html_screenshot_is_not_blank(tmp_path):
    report = tmp_path / "report.html"
    write_html(make_analysis("full"), report)
    shot = tmp_path / "shot.png"
    _run(tmp_path, report, "--window-size=1200,2400", "--hide-scrollbars", f"--screenshot={shot}",
         report.as_uri())
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[0] == 2400 and img.shape[1] == 1200
    assert img[..., :3].std() > 0.05  # text, tables and plots, not an empty page


def test_html_is_self_contained_text():
    text = render_html(make_analysis("hostile"))
    assert CSP in text and "default-src 'none'" in text
    assert "<script" not in text.replace("&lt;script", "")
    assert 'src="http' not in text and "href=" not in text
