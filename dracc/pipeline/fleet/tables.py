"""The fleet's tables and their publication: one row per log, unit and channel; trends.

The fleet table has one row per log, unit and channel (a log without INS statistics has
one row with empty unit and channel).  The a priori verdict applies the monitoring rule
(:func:`dracc.pipeline.audit.rule.apriori_chain`) per vessel, unit and channel in time
order, seeded with ``[deviation.apriori]``.  The per-day trend pools the RMS of the
day's logs::

    m_y,day = sqrt( sum_i n_i m_y,i^2 / sum_i n_i )        (pooled RMS, weights n_i)

The outputs (tables, trends, per-vessel CSV, ``fleet.json`` and extra pages such as
``fleet.html``) are written to a staging folder and published together by one rename
(:func:`dracc.core.atomic.file_set`); CSV cells that a spreadsheet would read as a
formula get a leading single quote.

Column names and kinds are those of :data:`dracc.core.vocabulary.TABLE_COLUMNS`:
``period_start_utc`` and ``period_end_utc`` are UTC timestamps, ``day`` a date (pyarrow
``date32``), ``ins_unit`` the INS unit and ``measure_unit`` the unit of the channel's
figures (m or deg).  ``rms_error`` is the unit's RMS error of the log's night as the
ranking reads it (:func:`night_figures`; how it was found in ``rms_error_method``:
``reference``, ``hat`` or ``factor``), the figure the pages show; ``m_y`` is the mean of
three's K5b figure, which the a priori rule applies to (one bad unit raises the other
two's m_y: it blames all three).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
import pyarrow as pa

from dracc.core.vocabulary import CHANNEL_UNITS
from dracc.pipeline.audit.measures import channel_quantity
from dracc.pipeline.audit.rule import apriori_chain
from dracc.pipeline.fleet.tasks import LogTask

#: columns of the fleet table, in order (units in the names or in ``measure_unit``)
TABLE_COLUMNS = (
    "vessel",
    "log",
    "sha256",
    "status",
    "error",
    "period_start_utc",
    "period_end_utc",
    "day",
    "ins_unit",
    "channel",
    "measure_unit",
    "n",
    "m_u",
    "m_y",
    "rms_error",
    "rms_error_method",
    "kurtosis_excess",
    "limit",
    "apriori_before",
    "apriori_after",
    "apriori_verdict",
    "dr_containment_2m",
    "dr_n_scored",
    "dr_consistent",
    "dr_verdict",
    "dr_nees",
    "compass_error_deg",
    "compass_error_sigma_deg",
    "log_scale_pct",
    "log_scale_sigma_pct",
    "rejected_rate_pct",
    "lines",
)
TREND_COLUMNS = (
    "vessel",
    "day",
    "ins_unit",
    "channel",
    "measure_unit",
    "logs",
    "n",
    "m_y",
    "apriori_after",
    "dr_containment_2m",
)


@dataclass(frozen=True)
class FleetResult:
    """The fleet table, the per-day trends, and what happened to each log."""

    table: pd.DataFrame
    trends: pd.DataFrame
    failures: tuple[dict, ...]  #: {"vessel", "log", "path", "error"}
    analysed: int  #: logs analysed in this run, successfully (a failed one is in failures)
    cached: int  #: logs taken from the cache
    #: the ranked list (:data:`dracc.pipeline.fleet.ranking.RANKING_COLUMNS`), best first
    ranking: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: files that are no log (a README, a photo): {"vessel", "log", "path", "why"}; not
    #: analysed, not in the tables, not counted among the logs
    skipped: tuple[dict, ...] = ()
    documents: int = 0  #: nights read from audit documents and databases (not analysed)
    #: inputs left out as a night already in the tables (:func:`drop_duplicate_nights`):
    #: {"vessel", "log", "path", "why"}; not in the tables, not counted among the logs
    duplicates: tuple[dict, ...] = ()
    #: each night's findings and checks not made
    #: (:data:`dracc.pipeline.fleet.findings.FINDING_COLUMNS`)
    findings: pd.DataFrame = field(default_factory=pd.DataFrame)
    #: each night's integrity checks made, passed, failed, not checked
    #: (:data:`dracc.pipeline.fleet.findings.INTEGRITY_COLUMNS`)
    integrity: pd.DataFrame = field(default_factory=pd.DataFrame)

    @property
    def logs(self) -> int:
        """The logs of the run: analysed + cached + documents + failed (skipped files apart)."""
        return self.analysed + self.cached + self.documents + len(self.failures)


#: the dtype of a UTC date column (``day``): pyarrow ``date32`` (Parquet DATE)
DATE_DTYPE = pd.ArrowDtype(pa.date32())


def _day(start: str | None, end: str | None):
    """The UTC date of the middle of the period ``start``..``end`` (ISO 8601 texts)."""
    if not start or not end:
        return None
    t0 = pd.Timestamp(start).tz_convert("UTC")
    t1 = pd.Timestamp(end).tz_convert("UTC")
    return (t0 + (t1 - t0) / 2).date()


def _night(text: object):
    """The date of an audit night 'YYYY-MM-DD'; None for anything else."""
    if not isinstance(text, str):
        return None
    try:
        return dt.date.fromisoformat(text)
    except ValueError:
        return None


def night_of_summary(s: Mapping) -> str | None:
    """The night (UTC date, ISO text) a summary belongs to, as its fleet row says."""
    per = s.get("period") or {}
    d = _night(s.get("night")) or _day(per.get("start_utc"), per.get("end_utc"))
    return None if d is None else d.isoformat()


def night_figures(s: Mapping) -> dict[tuple[str, str], tuple[float, str]]:
    """(INS unit, channel) -> (RMS error, method) of one summary: the night's figure the
    ranking reads (:func:`dracc.pipeline.audit.measures.night_measures`: against the
    reference, else the three-cornered hat, else m_y), so that the fleet table and the
    ranking show one number for one unit and night."""
    by_quantity = {channel_quantity(ch): ch for ch in CHANNEL_UNITS}
    out = {}
    for r in (s.get("measures") or {}).get("rows", ()):
        ch = by_quantity.get(r.get("quantity"))
        if ch is not None and r.get("value") is not None:
            out[(str(r.get("unit")), ch)] = (float(r["value"]), str(r.get("method") or ""))
    return out


#: which of two inputs of one vessel and night is kept: a log's own analysis, then an
#: audit document (it carries the night's integrity counts), then a database's night
_SOURCE_RANK = {"dracc.audit/1": 1, "dracc.audit.state": 2}


def drop_duplicate_nights(
    tasks: Sequence[LogTask], summaries: Mapping[str, dict], documents: frozenset[str]
) -> tuple[list[LogTask], tuple[dict, ...]]:
    """``tasks`` without the inputs that repeat a vessel's night (issue 33: a night came
    2-3 times into fleet.csv), and what was left out, with why.  A night is shown by the
    logs of that night, each once (a second file with the same bytes is left out), or,
    without a log, by one document's night (an audit document before a database's, then
    the first given): a document of a night whose log is analysed too, or a second copy of
    a document, is left out.  ``documents``: the task paths of document nights.  Failed
    and unread inputs are kept (they have no night)."""

    def rank(i: int) -> int:
        path = tasks[i].path
        return _SOURCE_RANK.get(str(summaries[path].get("schema")), 3) if path in documents else 0

    groups: dict[tuple[str, str], list[int]] = {}
    for i, t in enumerate(tasks):
        night = night_of_summary(summaries[t.path]) if t.path in summaries else None
        if night is not None:
            groups.setdefault((t.vessel, night), []).append(i)
    dropped: dict[int, str] = {}
    for (_, night), members in groups.items():
        members.sort(key=lambda i: (rank(i), i))
        first = tasks[members[0]]
        logs_seen: dict[str | None, LogTask] = {}
        for i in members[1:] if rank(members[0]) else members:
            t = tasks[i]
            if rank(i) == 0 and t.sha256 not in logs_seen:
                logs_seen[t.sha256] = t
            elif rank(i) == 0:
                same = logs_seen[t.sha256]
                dropped[i] = f"the same bytes as {same.vessel}/{same.log} (night {night})"
            elif rank(members[0]) == 0:
                dropped[i] = f"night {night} is analysed from its log {first.vessel}/{first.log}"
            else:
                dropped[i] = f"night {night} is read from {first.vessel}/{first.log} already"
    kept = [t for i, t in enumerate(tasks) if i not in dropped]
    left = tuple(
        {"vessel": tasks[i].vessel, "log": tasks[i].log, "path": tasks[i].path, "why": why}
        for i, why in sorted(dropped.items())
    )
    return kept, left


def _pct(x):
    return None if x is None else 100.0 * x


def fleet_table(
    tasks: Sequence[LogTask],
    summaries: Mapping[str, dict],
    failures: Mapping[str, str],
    seeds: Mapping[tuple[str, str], float],
) -> pd.DataFrame:
    """One row per log, unit and channel, sorted by vessel, time, log, unit, channel."""
    rows: list[dict] = []
    for t in tasks:
        base = {"vessel": t.vessel, "log": t.log, "sha256": t.sha256}
        if t.path in failures:
            rows.append({**base, "status": "failed", "error": failures[t.path]})
            continue
        s = summaries.get(t.path)
        if s is None:
            continue
        per = s["period"]
        cal = s["calibration"]
        # a night stored without its rejected count (NULL) has no rate
        rate = (
            s["rejected"] / s["lines"] if s.get("lines") and s.get("rejected") is not None else None
        )
        common = {
            **base,
            "status": "ok",
            "error": None,
            "period_start_utc": per["start_utc"],
            "period_end_utc": per["end_utc"],
            # an audit document's own night, else the middle of the period
            "day": _night(s.get("night")) or _day(per["start_utc"], per["end_utc"]),
            "dr_containment_2m": s["dr"]["containment_2m"],
            "dr_n_scored": s["dr"]["n_scored"],
            "dr_consistent": s["dr"]["consistent"],
            "dr_verdict": s["dr"].get("verdict"),
            "dr_nees": s["dr"].get("nees"),
            "compass_error_deg": cal["compass_error_deg"],
            "compass_error_sigma_deg": cal["compass_error_sigma_deg"],
            "log_scale_pct": _pct(cal["log_scale"]),
            "log_scale_sigma_pct": _pct(cal["log_scale_sigma"]),
            "rejected_rate_pct": _pct(rate),
            "lines": s.get("lines"),
        }
        if not s["channels"]:
            rows.append(common)
        figures = night_figures(s)
        for c in s["channels"]:
            rms, method = figures.get((c["unit"], c["channel"]), (None, None))
            rows.append(
                {
                    **common,
                    "ins_unit": c["unit"],
                    "channel": c["channel"],
                    "measure_unit": CHANNEL_UNITS.get(c["channel"]),
                    "n": c["n"],
                    "m_u": c["m_u"],
                    "m_y": c["m_y"],
                    "rms_error": rms,
                    "rms_error_method": method,
                    "kurtosis_excess": c["kurtosis"],
                    "limit": c["limit_error"],
                }
            )
    df = pd.DataFrame(rows, columns=list(TABLE_COLUMNS))
    df = _typed(df)
    df = df.sort_values(
        ["vessel", "period_start_utc", "log", "ins_unit", "channel"],
        na_position="last",
        kind="mergesort",
    ).reset_index(drop=True)
    _apply_rule(df, seeds)
    return df


def _typed(df: pd.DataFrame) -> pd.DataFrame:
    floats = [
        "m_u",
        "m_y",
        "rms_error",
        "kurtosis_excess",
        "limit",
        "apriori_before",
        "apriori_after",
        "dr_containment_2m",
        "dr_nees",
        "compass_error_deg",
        "compass_error_sigma_deg",
        "log_scale_pct",
        "log_scale_sigma_pct",
        "rejected_rate_pct",
    ]
    ints = ["n", "dr_n_scored", "lines"]
    times = ["period_start_utc", "period_end_utc"]
    typed = floats + ints + times + ["day", "dr_consistent"]
    strings = [c for c in TABLE_COLUMNS if c not in typed]
    for c in times:
        df[c] = pd.to_datetime(df[c], utc=True, format="ISO8601").astype("datetime64[ns, UTC]")
    # through pyarrow: a column without any date (every log failed) is float NaN, which
    # pandas cannot cast to date32
    day = df["day"].astype(object).where(df["day"].notna(), None)
    df["day"] = pd.Series(
        pa.array(day.tolist(), type=pa.date32()), dtype=DATE_DTYPE, index=df.index
    )
    for c in floats:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
    for c in ints:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("Int64")
    for c in strings:
        df[c] = df[c].astype("string")
    df["dr_consistent"] = df["dr_consistent"].astype("boolean")
    return df


def _apply_rule(df: pd.DataFrame, seeds: Mapping[tuple[str, str], float]) -> None:
    """The monitoring rule per vessel, unit and channel, log after log in time order
    (:func:`dracc.pipeline.audit.apriori_chain` on each series; one assignment per column)."""
    ok_pos = np.flatnonzero(((df["status"] == "ok") & df["ins_unit"].notna()).to_numpy(dtype=bool))
    before = np.full(len(df), np.nan)
    after = np.full(len(df), np.nan)
    verdict = np.full(len(df), None, dtype=object)
    logs = df["log"].to_numpy(dtype=object)
    m_y = df["m_y"].to_numpy(dtype="float64")
    keys = df.iloc[ok_pos][["vessel", "ins_unit", "channel"]]
    for (_vessel, unit, channel), pos in keys.groupby(
        ["vessel", "ins_unit", "channel"], sort=False
    ).indices.items():
        rows = ok_pos[pos]  # in table order: time order within the vessel
        steps = apriori_chain(
            seeds.get((unit, channel)),
            [(str(logs[r]), None if np.isnan(m_y[r]) else float(m_y[r])) for r in rows],
        )
        before[rows] = [np.nan if st.before is None else st.before for st in steps]
        after[rows] = [np.nan if st.after is None else st.after for st in steps]
        verdict[rows] = [st.verdict for st in steps]
    df["apriori_before"] = before
    df["apriori_after"] = after
    df["apriori_verdict"] = pd.array(verdict, dtype="string")


def fleet_trends(table: pd.DataFrame) -> pd.DataFrame:
    """Per vessel, day, unit and channel: pooled RMS m_y (weights n), the a priori at the
    day's end, and the DR containment of the vessel's logs that day pooled over their
    scored epochs (weights ``dr_n_scored``)."""
    ok = table[(table["status"] == "ok") & table["ins_unit"].notna() & table["day"].notna()]
    key = ["vessel", "day", "ins_unit", "channel"]
    n = ok["n"].astype("float64")
    m_y = ok["m_y"].astype("float64")
    good = m_y.notna() & (n > 0)
    parts = ok[key + ["measure_unit", "log", "apriori_after"]].assign(
        _n=n.where(good, 0.0), _nm2=(n * m_y**2).where(good, 0.0)
    )
    agg = (
        parts.groupby(key, sort=True)
        .agg(
            measure_unit=("measure_unit", "first"),
            logs=("log", "nunique"),
            n=("_n", "sum"),
            nm2=("_nm2", "sum"),
            apriori_after=("apriori_after", "last"),
        )
        .reset_index()
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        agg["m_y"] = np.where(agg["n"] > 0, np.sqrt(agg["nm2"] / agg["n"]), np.nan)  # pooled RMS
    per_log = ok.drop_duplicates(["vessel", "log", "sha256"])
    w = per_log["dr_n_scored"].astype("float64")
    c = per_log["dr_containment_2m"].astype("float64")
    okc = c.notna() & w.notna() & (w > 0)
    dr = per_log[["vessel", "day"]].assign(_w=w.where(okc, 0.0), _wc=(w * c).where(okc, 0.0))
    dr = (
        dr.groupby(["vessel", "day"], sort=True)
        .agg(w=("_w", "sum"), wc=("_wc", "sum"))
        .reset_index()
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        dr["dr_containment_2m"] = np.where(dr["w"] > 0, dr["wc"] / dr["w"], np.nan)
    df = agg.merge(dr[["vessel", "day", "dr_containment_2m"]], on=["vessel", "day"], how="left")
    df = df[list(TREND_COLUMNS)].copy()
    for col in ("vessel", "ins_unit", "channel", "measure_unit"):
        df[col] = df[col].astype("string")  # ``day`` keeps the table's dtype (a date)
    for col in ("logs", "n"):
        df[col] = df[col].round().astype("Int64")
    for col in ("m_y", "apriori_after", "dr_containment_2m"):
        df[col] = df[col].astype("float64")
    return df.reset_index(drop=True)


def count_logs(table: pd.DataFrame) -> int:
    """The number of logs in a fleet table (a log has one row per unit and channel)."""
    return len(table.drop_duplicates(["vessel", "log", "sha256"]))
