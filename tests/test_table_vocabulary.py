"""One column vocabulary across every table dracc writes (issue 18).

Every table (``analyze --out``, the fleet and trend tables, ``dracc records``) is written
from one real analysis of the 3 h sample log, then read back with pandas and with DuckDB:
each column is in :data:`dracc.core.vocabulary.TABLE_COLUMNS` (or a per-unit
``<ins_unit>_lat_m``), of the kind it names there (a ``*_utc`` time is ``timestamp[ns,
tz=UTC]`` in Parquet, ``TIMESTAMP WITH TIME ZONE`` in DuckDB and ISO 8601 with ``Z`` in
CSV), no column is called plain ``unit``, and the same thing has the same name in every
table.  The times are checked against the log's own text (its first and last RMC).  The
audit history and fleet pages name their columns in the same words, and their plots fit
the date axis to the nights (one night is about a day wide, not 2025-2029).
"""

from __future__ import annotations

import datetime as dt
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from dracc.core.config import Config
from dracc.core.vocabulary import (
    CHANNEL_KEYS,
    COLUMN_KINDS,
    TABLE_COLUMN_SUFFIXES,
    TABLE_COLUMNS,
    column_kind,
)

duckdb = pytest.importorskip("duckdb")

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "sample_logs" / "voyage_tag.nmea"
ISO_Z = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d{3}|\.\d{6}|\.\d{9})?Z$")

#: DuckDB's type names for each kind of column
DUCK_TYPES = {
    # DuckDB 2 reads Parquet timestamp[ns, tz=UTC] as its nanosecond TIMESTAMPTZ_NS
    "timestamp": {"TIMESTAMP WITH TIME ZONE", "TIMESTAMPTZ_NS"},
    "date": {"DATE"},
    "text": {"VARCHAR"},
    "int": {"TINYINT", "SMALLINT", "INTEGER", "BIGINT"},
    "float": {"DOUBLE"},
    "bool": {"BOOLEAN"},
}


def _arrow_kind(t: pa.DataType) -> str:
    if pa.types.is_timestamp(t):
        assert t.unit == "ns" and t.tz == "UTC", t
        return "timestamp"
    if pa.types.is_date32(t):
        return "date"
    if pa.types.is_string(t) or pa.types.is_large_string(t):
        return "text"
    if pa.types.is_dictionary(t) and pa.types.is_string(t.value_type):
        return "text"
    if pa.types.is_integer(t):
        return "int"
    if pa.types.is_floating(t):
        return "float"
    if pa.types.is_boolean(t):
        return "bool"
    raise AssertionError(f"unexpected Parquet type {t}")


def _pandas_kind(s: pd.Series) -> str:
    d = s.dtype
    if isinstance(d, pd.DatetimeTZDtype):
        assert str(d.tz) == "UTC", d
        return "timestamp"
    if isinstance(d, pd.ArrowDtype) and pa.types.is_date32(d.pyarrow_dtype):
        return "date"
    if (
        pd.api.types.is_object_dtype(d)
        and s.dropna().map(type).eq(dt.date).all()
        and s.notna().any()
    ):
        return "date"  # pandas reads a Parquet DATE as datetime.date objects
    if pd.api.types.is_bool_dtype(d):
        return "bool"
    if pd.api.types.is_integer_dtype(d):
        return "int"
    if pd.api.types.is_float_dtype(d):
        return "float"
    if (
        pd.api.types.is_string_dtype(d)
        or isinstance(d, pd.CategoricalDtype)
        or pd.api.types.is_object_dtype(d)
    ):
        return "text"
    raise AssertionError(f"{s.name}: unexpected dtype {d}")


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """One analysis of the sample log; every table of it written as Parquet and CSV."""
    from dracc.ingest import read_logs
    from dracc.pipeline.analysis import analyse_voyage
    from dracc.pipeline.fleet import FleetResult, fleet_table, fleet_trends, summarise
    from dracc.pipeline.fleet.tasks import LogTask
    from dracc.pipeline.records import records_table
    from dracc.report import fleet_tables, records_out, tables

    out = tmp_path_factory.mktemp("vocabulary")
    cfg = Config()
    voyage = read_logs([LOG], cfg.ingest)
    a = analyse_voyage(voyage, cfg)
    tables.write_tables(a, out / "analyze")
    summary = summarise(a)
    tasks = [
        LogTask("Aurora", str(LOG), "voyage_tag.nmea", "a" * 64),
        LogTask("Aurora", "/x/broken.nmea", "broken.nmea", "b" * 64),
    ]
    table = fleet_table(tasks, {str(LOG): summary}, {"/x/broken.nmea": "not a log"}, {})
    res = FleetResult(table, fleet_trends(table), (), 1, 0)
    fleet_tables.write_tables(res, out / "fleet")
    rec = records_table(voyage)
    records_out.write_records(rec, str(out / "records.parquet"))
    records_out.write_records(rec, str(out / "records.csv"))
    paths = {f"analyze/{p.stem}": p for p in sorted((out / "analyze").glob("*.parquet"))}
    paths |= {"fleet/fleet": out / "fleet" / "fleet.parquet"}
    paths |= {"fleet/trends": out / "fleet" / "trends.parquet"}
    paths |= {"records": out / "records.parquet"}
    return {"analysis": a, "summary": summary, "res": res, "paths": paths}


def test_the_vocabulary_itself():
    assert "unit" not in TABLE_COLUMNS and {"ins_unit", "measure_unit"} <= set(TABLE_COLUMNS)
    for name, (kind, meaning) in TABLE_COLUMNS.items():
        assert kind in COLUMN_KINDS and meaning, name
        assert (kind == "timestamp") == name.endswith("_utc"), name  # times are *_utc
    assert set(TABLE_COLUMN_SUFFIXES) == {"_lat_m", "_lon_m", "_course_deg"}
    assert column_kind("ins2_course_deg") == "float" and column_kind("_lat_m") is None
    assert column_kind("unit") is None and column_kind("measure") is None


def test_declared_columns_are_in_the_vocabulary():
    """The column lists the writers declare, with the kinds they store."""
    from dracc.pipeline.fleet.tables import TABLE_COLUMNS as FLEET
    from dracc.pipeline.fleet.tables import TREND_COLUMNS
    from dracc.pipeline.records import COLUMNS as RECORDS
    from dracc.report.records_out import SCHEMA

    for name in (*FLEET, *TREND_COLUMNS, *RECORDS):
        assert column_kind(name) is not None, name
    for field in SCHEMA:
        assert _arrow_kind(field.type) == column_kind(field.name), field


def test_every_expected_table_is_there(written):
    assert set(written["paths"]) == {
        "analyze/dr_track",
        "analyze/dr_epochs",
        "analyze/deviation_samples",
        "analyze/unit_stats",
        "fleet/fleet",
        "fleet/trends",
        "records",
    }


@pytest.mark.parametrize(
    "table",
    [
        "analyze/dr_track",
        "analyze/dr_epochs",
        "analyze/deviation_samples",
        "analyze/unit_stats",
        "fleet/fleet",
        "fleet/trends",
        "records",
    ],
)
def test_table_names_and_types(written, table):
    path = written["paths"][table]
    schema = pq.read_schema(path)
    # nullable dtypes: an integer column with gaps stays integer (records' fix_quality)
    df = pd.read_parquet(path, dtype_backend="numpy_nullable")
    duck = duckdb.sql(f"describe select * from read_parquet('{path}')").fetchall()
    duck_types = {r[0]: r[1] for r in duck}
    assert list(df.columns) == schema.names == list(duck_types)
    assert "unit" not in df.columns and len(df)
    for name in df.columns:
        kind = column_kind(name)
        assert kind is not None, f"{table}: column {name!r} is not in the vocabulary"
        assert _arrow_kind(schema.field(name).type) == kind, (table, name)
        assert _pandas_kind(df[name]) == kind, (table, name, df[name].dtype)
        assert duck_types[name] in DUCK_TYPES[kind], (table, name, duck_types[name])
    # the CSV beside it: the same columns; times ISO 8601 with Z, equal to the Parquet's
    csv_path = path.with_suffix(".csv")
    csv = pd.read_csv(csv_path, dtype=str, keep_default_na=False)
    assert list(csv.columns) == list(df.columns)
    duck_csv = dict(
        duckdb.sql(f"describe select * from read_csv_auto('{csv_path}')").fetchall()[i][:2]
        for i in range(len(df.columns))
    )
    for name in df.columns:
        if column_kind(name) == "timestamp":
            cells = csv[name][csv[name] != ""]
            assert len(cells) and cells.str.match(ISO_Z).all(), (table, name, cells.iloc[0])
            back = pd.to_datetime(cells, utc=True, format="ISO8601").astype("datetime64[ns, UTC]")
            expect = df.loc[df[name].notna(), name].reset_index(drop=True)
            pd.testing.assert_series_equal(back.reset_index(drop=True), expect, check_names=False)
            assert duck_csv[name] in DUCK_TYPES["timestamp"], (table, name, duck_csv[name])
        elif column_kind(name) == "date":
            cells = csv[name][csv[name] != ""]
            assert cells.str.match(r"^\d{4}-\d\d-\d\d$").all() and duck_csv[name] == "DATE"


def _rmc_times(path: Path) -> list[dt.datetime]:
    """The log's RMC times, read from the text by hand (hhmmss.ss, ddmmyy)."""
    out = []
    for line in path.read_text(encoding="ascii", errors="replace").splitlines():
        m = re.search(r"\$..RMC,(\d{6}(?:\.\d+)?),A?,[^*]*?,(\d{6}),", line)
        if m:
            hms, dmy = m.group(1), m.group(2)
            out.append(
                dt.datetime(
                    2000 + int(dmy[4:]),
                    int(dmy[2:4]),
                    int(dmy[:2]),
                    int(hms[:2]),
                    int(hms[2:4]),
                    int(hms[4:6]),
                    tzinfo=dt.UTC,
                )
            )
    return out


def test_fleet_period_is_the_logs_period(written):
    """period_*_utc are timestamps equal to the log's own first and last times, and the
    day is the UTC date of its middle (independent: the RMC text, by hand)."""
    t = pd.read_parquet(written["paths"]["fleet/fleet"])
    ok = t[t["status"] == "ok"]
    rmc = _rmc_times(LOG)
    assert len(rmc) > 100
    start, end = ok["period_start_utc"].iloc[0], ok["period_end_utc"].iloc[0]
    # the period spans every record, so it holds the RMCs (other sentences may lead by < 1 s)
    assert start <= pd.Timestamp(min(rmc)) < start + pd.Timedelta(seconds=2)
    assert end - pd.Timedelta(seconds=2) < pd.Timestamp(max(rmc)) <= end
    assert (ok["day"] == (start + (end - start) / 2).date()).all()
    failed = t[t["status"] == "failed"]
    assert failed["period_start_utc"].isna().all() and failed["ins_unit"].isna().all()


def test_the_same_names_for_the_same_things(written):
    """ins_unit, channel, measure_unit, n, m_u, m_y, kurtosis_excess and limit hold the
    same values in analyze's unit_stats (whole log) and in the fleet table."""
    stats = pd.read_parquet(written["paths"]["analyze/unit_stats"])
    fleet = pd.read_parquet(written["paths"]["fleet/fleet"])
    trends = pd.read_parquet(written["paths"]["fleet/trends"])
    shared = ["ins_unit", "channel", "measure_unit", "n", "m_u", "m_y", "kurtosis_excess", "limit"]
    assert set(shared) <= set(stats.columns) & set(fleet.columns)
    key = ["ins_unit", "channel"]
    a = stats[stats["window"] == "all"][shared].sort_values(key).reset_index(drop=True)
    b = fleet[fleet["status"] == "ok"][shared].sort_values(key).reset_index(drop=True)
    assert len(a) == 9 and set(a["ins_unit"]) == {"ins1", "ins2", "ins3"}
    for c in shared:
        if c in ("ins_unit", "channel", "measure_unit", "n"):
            assert a[c].astype(str).tolist() == b[c].astype(str).tolist(), c
        else:
            np.testing.assert_allclose(a[c].to_numpy(float), b[c].to_numpy(float), rtol=1e-12)
    # measure_unit: metres for lat/lon, degrees for course, as the channel keys say
    for _, r in a.iterrows():
        assert CHANNEL_KEYS[r["channel"]].endswith("_" + r["measure_unit"])
    # one log a day: the day's pooled m_y is the log's m_y
    m = trends.merge(b, on=key, suffixes=("_day", ""))
    np.testing.assert_allclose(m["m_y_day"], m["m_y"], rtol=1e-12)
    # the per-unit sample columns are named by the same INS units
    samples = pd.read_parquet(written["paths"]["analyze/deviation_samples"])
    prefixes = {c.rsplit("_", 2)[0] for c in samples.columns if c != "time_utc"}
    assert prefixes == set(a["ins_unit"])


class _Headers(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.columns: list[str | None] = []
        self.texts: list[str] = []
        self._in = False

    def handle_starttag(self, tag, attrs):
        if tag == "th":
            self.columns.append(dict(attrs).get("data-column"))
            self.texts.append("")
            self._in = True

    def handle_endtag(self, tag):
        if tag == "th":
            self._in = False

    def handle_data(self, data):
        if self._in:
            self.texts[-1] += data


def _history_doc(nights: list[str]) -> dict:
    return {
        "schema": "dracc.audit.history/1",
        "series": [
            {
                "vessel": "Aurora",
                "unit": u,
                "channel": "lat",
                "measure": "m",
                "nights": [
                    {
                        "night": n,
                        "n": 9,
                        "m_u": 300.0 + i,
                        "m_y": 400.0 + 10 * i,
                        "kurtosis": -0.5,
                        "limit_error": 900.0,
                        "apriori_before": None,
                        "apriori_after": 400.0 + 10 * i,
                        "verdict": "established" if i == 0 else "raised",
                    }
                    for i, n in enumerate(nights)
                ],
            }
            for u in ("ins1", "ins2")
        ],
        "nights": [
            {
                "vessel": "Aurora",
                "night": n,
                "audited_utc": n + "T00:20:00Z",
                "content_sha256": "0" * 64,
                "dr_containment_2m": 0.97,
                "dr_verdict": "consistent",
                "dr_consistent": True,
                "dr_nees": 10.0,
                "compass_error_deg": 0.3,
                "log_scale": 0.02,
                "rejected_rate": 0.0,
                "findings": [],
            }
            for n in nights
        ],
        "apriori_events": [],
    }


def test_pages_name_their_columns_in_the_vocabulary(written):
    from dracc.report.audit_html import history_html
    from dracc.report.fleet_html import fleet_html

    for page in (
        history_html(_history_doc(["2026-11-18", "2026-11-19"])),
        fleet_html(written["res"]),
    ):
        p = _Headers()
        p.feed(page)
        assert p.columns and all(c in TABLE_COLUMNS for c in p.columns), p.columns
        assert "ins_unit" in p.columns and "unit" not in [t.strip() for t in p.texts]


def _axis_days(nights: list[str]) -> tuple[float, list[str]]:
    """The x span in days of the history figure of ``nights``, and its tick labels."""
    from matplotlib import pyplot as plt

    from dracc.report.audit_html import history_lines, m_y_history_figure

    fig = m_y_history_figure(history_lines(_history_doc(nights), "Aurora"), "t", 2.0)
    try:
        fig.canvas.draw()
        ax = fig.axes[-1]
        lo, hi = ax.get_xlim()
        labels = [t.get_text() for t in ax.get_xticklabels() if t.get_text()]
        visible = [lab for lab, x in zip(labels, ax.get_xticks(), strict=False) if lo <= x <= hi]
        return hi - lo, visible
    finally:
        plt.close(fig)


def test_history_plot_of_one_night_is_a_day_wide():
    span, labels = _axis_days(["2026-11-18"])
    assert span == pytest.approx(1.0)  # half a day each side, not 2025-2029
    assert labels == ["2026-11-18"]


def test_history_plot_of_a_few_nights():
    span, labels = _axis_days(["2026-11-18", "2026-11-19", "2026-11-21"])
    assert span == pytest.approx(3.0 + 1.0)  # three days of data, half a day each side
    assert labels == ["2026-11-18", "2026-11-19", "2026-11-20", "2026-11-21"]
    span, labels = _axis_days([f"2026-11-{d:02d}" for d in range(1, 31)])
    assert span == pytest.approx(29 * 1.1)  # a pad of 5 % of the span each side
    assert 4 <= len(labels) <= 10
    assert all(re.fullmatch(r"\d{4}-\d\d-\d\d", s) for s in labels)
