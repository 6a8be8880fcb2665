"""dracc.report.rows: the one row model behind the terminal and HTML per-unit tables."""

from __future__ import annotations

import dataclasses
import html as html_lib
import math

from test_report import make_analysis

from dracc.report import html, rows, terminal


def test_channel_digits_and_sigma_bound():
    assert rows.channel_digits("lat") == 1 and rows.channel_digits("lon") == 1
    assert rows.channel_digits("course") == 3
    assert rows.sigma_bound(6.25, 1) == "2.5"
    assert rows.sigma_bound(0.0004, 3) == "0.020"
    assert rows.sigma_bound(-1e-9, 1) == "<0"
    assert rows.sigma_bound(None, 1) == "-" and rows.sigma_bound(math.nan, 1) == "-"


def test_rows_carry_the_statistics_figures():
    d = make_analysis("full").deviation
    table = rows.unit_rows(d)
    assert [name for name, _ in table] == list(d.units)
    verdicts = set()
    for name, urows in table:
        u = d.whole.units[name]
        assert [r.channel for r in urows] == [
            ch for ch in ("lat", "lon", "course") if ch in u.channels
        ]
        for r in urows:
            c = u.channels[r.channel]
            digits = 3 if r.channel == "course" else 1
            assert r.channel_text == f"{r.channel} [{'deg' if r.channel == 'course' else 'm'}]"
            assert (r.n, r.m_u, r.m_y, r.limit) == (
                str(c.n),
                f"{c.m_u:,.{digits}f}",
                f"{c.m_y:,.{digits}f}",
                f"{c.limit:,.{digits}f}",
            )
            assert r.kurtosis == f"{c.kurtosis:.2f}"
            want = {None: rows.NO_APRIORI, True: rows.EXCEEDS, False: rows.WITHIN}[
                c.exceeds_apriori
            ]
            assert r.verdict == want
            if want == rows.EXCEEDS:
                assert r.new_apriori == f"{c.new_apriori:,.{digits}f}"
            h = u.hat.get(r.channel)
            assert r.has_hat == (h is not None)
            if h is not None:
                assert r.hat_negative == h.negative
                if not h.negative:
                    assert r.hat_sigma == f"{h.sigma:,.{digits}f}"
            ref = u.reference.get(r.channel)
            word = {"+": "k ok", "-": "k low"}.get(ref.mark) if ref is not None else None
            assert r.k_star == ("-" if ref is None else f"{ref.k_star:.2f} {word}")
            verdicts.add(r.verdict)
    # the hand-built analysis exercises every verdict and a negative hat variance
    assert verdicts == {rows.NO_APRIORI, rows.EXCEEDS, rows.WITHIN}
    assert any(r.hat_negative for _, urows in table for r in urows)


def test_terminal_and_html_show_the_same_figures():
    a = make_analysis("full")
    text = terminal.render_text(a, width=200)
    page = html._units(a)
    for _, urows in rows.unit_rows(a.deviation):
        for r in urows:
            cells = [r.n, r.m_u, r.m_y, r.kurtosis, r.limit, r.apriori, r.ref_rms, r.k_star]
            # (the terminal shows 'lat', not 'lat [m]': rich takes '[m]' for markup; golden)
            line = next(ln for ln in text.splitlines() if ln.split()[:2] == [r.unit, r.channel])
            assert f">{r.channel_text}</td>" in page
            for cell in cells:
                assert cell in line
                assert f"<td>{html_lib.escape(cell)}</td>" in page


def test_unit_without_statistics():
    a = make_analysis("full")
    d = a.deviation
    units = {k: v for k, v in d.whole.units.items() if k != "ins2"}
    d2 = dataclasses.replace(d, whole=dataclasses.replace(d.whole, units=units))
    table = dict(rows.unit_rows(d2))
    assert table["ins2"] is None and table["ins1"]
    line = next(
        ln
        for ln in terminal.render_text(dataclasses.replace(a, deviation=d2)).splitlines()
        if ln.startswith("ins2")
    )
    assert line.split() == ["ins2", "-", "0"] + ["-"] * 9
