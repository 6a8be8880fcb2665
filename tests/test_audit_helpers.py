"""Helper for the audit tests: typed analyses (:class:`dracc.pipeline.results.Analysis`)
built by hand, holding just what the audit and the fleet read."""

from __future__ import annotations

import math

import numpy as np

from dracc.core.timefmt import parse_utc
from dracc.math.deviation import DeviationResult
from dracc.math.deviation.analysis import ChannelStats, UnitStats, WindowStats
from dracc.pipeline.results import (
    Analysis,
    CalibrationSection,
    DRSection,
    DRTrackResult,
    Estimate,
    InputFile,
    SourceRow,
    TimeSummary,
)

CH = ("lat", "lon", "course")


nan = math.nan


def _ns(utc: str | None) -> int | None:
    return None if utc is None else int(parse_utc(utc).timestamp()) * 1_000_000_000


def _channel(n: int, m_u: float, m_y: float, limit: float) -> ChannelStats:
    nan = math.nan
    return ChannelStats(
        n,
        m_u,
        m_y / m_u if m_u else nan,
        m_y,
        -0.3,
        -0.3,
        nan,
        nan,
        nan,
        limit,
        None,
        None,
        nan,
        "no a priori",
    )


def _deviation(units: dict[str, dict[str, ChannelStats]], start: int, end: int) -> DeviationResult:
    whole = WindowStats(
        "all", start, end, {u: UnitStats(ch, nan, 0.1, {}, {}) for u, ch in units.items()}
    )
    empty = np.array([], dtype=np.int64)
    return DeviationResult(
        3600.0, 0.0, 0.95, 0.95, tuple(units), {}, empty, {}, {}, empty, whole, (), {}, {}, {}
    )


def _dr_section(containment, verdict, consistent, nees, dominant) -> DRSection:
    arr = np.array([])
    track = DRTrackResult(*([arr] * 16))
    stat, lower, upper = nees if nees is not None else (nan, nan, nan)
    source, key = dominant if dominant is not None else (None, None)
    return DRSection(
        "compass",
        "log",
        "1h",
        60.0,
        track,
        track,
        (),
        "gnss",
        nan if containment is None else containment,
        120,
        0.96,
        1.0,
        consistent,
        verdict or "",
        0,
        0,
        nees_statistic=stat,
        nees_lower=lower,
        nees_upper=upper,
        dominant_source=source,
        dominant_key=key,
    )


def make_analysis(
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
    period: tuple[str | None, str | None] | None = None,
) -> Analysis:
    """``m_y``: {unit: {channel: value}}; m_u = m_y / k, limit = limit_factor * m_y.

    ``verdict``: the DR verdict sentence (``consistent`` follows from its first word; none:
    an empty sentence, read as no verdict); ``nees``: (statistic, lower, upper);
    ``dominant``: (source, key); ``period``: (start, end) UTC, default the whole night."""
    if m_y is None:
        m_y = {u: {"lat": 100.0, "lon": 150.0, "course": 0.1} for u in ("ins1", "ins2", "ins3")}
    k = {"lat": 1.32, "lon": 1.49, "course": 1.49}
    units: dict[str, dict[str, ChannelStats]] = {}
    for u, per in m_y.items():
        units[u] = {}
        for ch, v in per.items():
            ok = v is not None and not (isinstance(v, float) and math.isnan(v))
            units[u][ch] = (
                _channel(n, v / k[ch], v, limit_factor * v) if ok else _channel(n, nan, nan, nan)
            )
    start_utc, end_utc = period or (f"{night}T00:00:00Z", f"{night}T23:59:59Z")
    start, end = _ns(start_utc), _ns(end_utc)
    consistent = None
    if verdict is not None:
        word = verdict.split(":")[0].split(" ")[0]
        consistent = {"consistent": True, "conservative": True, "inconsistent": False}.get(word)
    calibration = CalibrationSection(
        "gnss",
        None if compass_deg is None else Estimate(compass_deg, 0.05),
        None if log_scale is None else Estimate(log_scale, 0.001),
        None,
        10,
        600.0,
        0.1,
    )
    return Analysis(
        schema="dracc.analysis/1",
        dracc_version="test",
        inputs=(
            InputFile(
                f"/logs/{night}.nmea", "nmea", lines, lines - rejected, {"checksum": rejected}
            ),
        ),
        sources=tuple(SourceRow(r.upper(), (r,), 100, {}, start, end) for r in roles),
        rejected={"checksum": rejected},
        reject_examples={},
        time=TimeSummary(0, 0, 0, 0, 0, ()),
        start_ns=start,
        end_ns=end,
        lines=lines,
        tracks=(),
        deviation=_deviation(units, start or 0, end or 0),
        dead_reckoning=_dr_section(containment, verdict, consistent, nees, dominant),
        calibration=calibration,
        current=None,
    )


def test_helper_document_reads_back():
    # the hand-built analysis is read by the audit the way the tests assume
    from dracc.pipeline.audit import facts_from_analysis

    f = facts_from_analysis(make_analysis(m_y={"ins1": {"lat": 132.0}}))
    (row,) = f.channels
    assert (row.unit, row.channel, row.n) == ("ins1", "lat", 24)
    assert math.isclose(row.m_u, 100.0) and math.isclose(row.limit_error, 264.0)
    assert f.rejected_rate == 10 / 10000 and f.sources["ins2"] == "INS2"


def test_helper_document_carries_the_dr_verdict():
    from dracc.pipeline.audit import facts_from_analysis

    f = facts_from_analysis(
        make_analysis(
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
    old = facts_from_analysis(make_analysis())  # an analysis without verdict or NEES
    assert (old.dr_verdict, old.dr_consistent, old.dr_nees, old.dr_dominant_source) == (None,) * 4
