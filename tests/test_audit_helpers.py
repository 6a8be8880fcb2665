"""Helper for the audit tests: analysis documents (dracc.analysis/1 keys) built by hand."""

from __future__ import annotations

import math

CH = ("lat", "lon", "course")


def make_doc(
    night: str = "2026-11-20",
    m_y: dict | None = None,
    *,
    limit_factor: float = 2.0,
    containment: float | None = 0.95,
    compass_deg: float | None = 0.2,
    log_scale: float | None = 0.005,
    lines: int = 10000,
    rejected: int = 10,
    roles=("ins1", "ins2", "ins3", "gnss", "compass", "log"),
    n: int = 24,
    verdict: str | None = None,
    nees: tuple | None = None,
    dominant: tuple[str, str] | None = None,
) -> dict:
    """``m_y``: {unit: {channel: value}}; m_u = m_y / k, limit = limit_factor * m_y.

    ``verdict``: the DR verdict sentence (``dead_reckoning.verdict``; ``consistent`` follows
    from its first word); ``nees``: (statistic, lower, upper); ``dominant``: (source, key).
    Left out of the document when None (older documents carry neither)."""
    if m_y is None:
        m_y = {u: {"lat": 100.0, "lon": 150.0, "course": 0.1} for u in ("ins1", "ins2", "ins3")}
    k = {"lat": 1.32, "lon": 1.49, "course": 1.49}
    units = {}
    for u, per in m_y.items():
        units[u] = {}
        for ch, v in per.items():
            ok = v is not None and not (isinstance(v, float) and math.isnan(v))
            units[u][ch] = {
                "n": n,
                "m_u": v / k[ch] if ok else None,
                "m_y": v if ok else None,
                "kurtosis": -0.3,
                "limit": limit_factor * v if ok else None,
            }
        units[u]["r_lat_lon"] = 0.1
    dr: dict = {"containment_2m": containment, "n_scored": 120}
    if verdict is not None:
        word = verdict.split(":")[0].split(" ")[0]
        dr["verdict"] = verdict
        dr["consistent"] = {"consistent": True, "conservative": True, "inconsistent": False}.get(
            word
        )
    if nees is not None:
        dr["nees"] = dict(zip(("statistic", "lower", "upper"), nees, strict=True))
    if dominant is not None:
        dr["dominant_source"], dr["dominant_key"] = dominant
    return {
        "schema": "dracc.analysis/1",
        "inputs": [
            {
                "path": f"/logs/{night}.nmea",
                "format": "nmea",
                "lines": lines,
                "records": lines - rejected,
                "rejected": {"checksum": rejected},
            }
        ],
        "sources": {r: {"keys": [r.upper()], "records": 100} for r in roles},
        "period": {"start_utc": f"{night}T00:00:00Z", "end_utc": f"{night}T23:59:59Z"},
        "deviation": {"interval_s": 3600.0, "factors": k, "units": units},
        "dead_reckoning": dr,
        "calibration": {
            "compass_error_deg": None
            if compass_deg is None
            else {"value": compass_deg, "sigma": 0.05},
            "log_scale": None if log_scale is None else {"value": log_scale, "sigma": 0.001},
        },
        "current": None,
    }


def test_helper_document_reads_back():
    # the hand-built document is read by the audit the way the tests assume
    from dracc.pipeline.audit import facts_from_analysis

    f = facts_from_analysis(make_doc(m_y={"ins1": {"lat": 132.0}}))
    (row,) = f.channels
    assert (row.unit, row.channel, row.n) == ("ins1", "lat", 24)
    assert math.isclose(row.m_u, 100.0) and math.isclose(row.limit_error, 264.0)
    assert f.rejected_rate == 10 / 10000 and f.sources["ins2"] == "INS2"


def test_helper_document_carries_the_dr_verdict():
    from dracc.pipeline.audit import facts_from_analysis

    f = facts_from_analysis(
        make_doc(
            verdict="inconsistent (circle too small): x",
            nees=(80.0, 5.1, 34.3),
            dominant=("the current", "current_kn"),
        )
    )
    assert (f.dr_verdict, f.dr_consistent, f.dr_nees, f.dr_nees_upper) == (
        "inconsistent",
        False,
        80.0,
        34.3,
    )
    assert (f.dr_dominant_source, f.dr_dominant_key) == ("the current", "current_kn")
    old = facts_from_analysis(make_doc())  # a document without verdict or NEES
    assert (old.dr_verdict, old.dr_consistent, old.dr_nees, old.dr_dominant_source) == (None,) * 4
