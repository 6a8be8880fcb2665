"""Helper for the audit tests: analysis documents (dracc.analysis/1 keys) built by hand."""

from __future__ import annotations

import math

CH = ("lat", "lon", "course")


def make_doc(night: str = "2026-11-20", m_y: dict | None = None, *, limit_factor: float = 2.0,
             containment: float | None = 0.95, compass_deg: float | None = 0.2,
             log_scale: float | None = 0.005, lines: int = 10000, rejected: int = 10,
             roles=("ins1", "ins2", "ins3", "gnss", "compass", "log"), n: int = 24) -> dict:
    """``m_y``: {unit: {channel: value}}; m_u = m_y / k, limit = limit_factor * m_y."""
    if m_y is None:
        m_y = {u: {"lat": 100.0, "lon": 150.0, "course": 0.1} for u in ("ins1", "ins2", "ins3")}
    k = {"lat": 1.32, "lon": 1.49, "course": 1.49}
    units = {}
    for u, per in m_y.items():
        units[u] = {}
        for ch, v in per.items():
            ok = v is not None and not (isinstance(v, float) and math.isnan(v))
            units[u][ch] = {"n": n, "m_u": v / k[ch] if ok else None, "m_y": v if ok else None,
                            "kurtosis": -0.3, "limit": limit_factor * v if ok else None}
        units[u]["r_lat_lon"] = 0.1
    return {
        "schema": "dracc.analysis/1",
        "inputs": [{"path": f"/logs/{night}.nmea", "format": "nmea", "lines": lines,
                    "records": lines - rejected, "rejected": {"checksum": rejected}}],
        "sources": {r: {"keys": [r.upper()], "records": 100} for r in roles},
        "period": {"start_utc": f"{night}T00:00:00Z", "end_utc": f"{night}T23:59:59Z"},
        "deviation": {"interval_s": 3600.0, "factors": k, "units": units},
        "dead_reckoning": {"containment_2m": containment, "n_scored": 120},
        "calibration": {"compass_error_deg": None if compass_deg is None else
                        {"value": compass_deg, "sigma": 0.05},
                        "log_scale": None if log_scale is None else {"value": log_scale, "sigma": 0.001}},
        "current": None,
    }


def test_helper_document_reads_back():
    # the hand-built document is read by the audit the way the tests assume
    from dracc.audit import facts_from_analysis

    f = facts_from_analysis(make_doc(m_y={"ins1": {"lat": 132.0}}))
    (row,) = f.channels
    assert (row.unit, row.channel, row.n) == ("ins1", "lat", 24)
    assert math.isclose(row.m_u, 100.0) and math.isclose(row.limit_error, 264.0)
    assert f.rejected_rate == 10 / 10000 and f.sources["ins2"] == "INS2"
