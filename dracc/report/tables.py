"""Tables for spreadsheets and databases: CSV and Parquet, written atomically.

``--out DIR`` writes, each as ``.csv`` and ``.parquet``:

``dr_track``         the full-rate DR track (time_utc, lat_deg, lon_deg, since_fix_s,
                     radius_2m_m, semi_major_m, semi_minor_m, orientation_deg, ref_error_m, leg,
                     water_lat_deg, water_lon_deg, scored): lat/lon and the 2M are those of the
                     estimated position, water_* the water track (heading and log only), scored
                     whether the row is scored out of sample
``dr_epochs``        the same columns at the reporting epochs
``deviation_samples`` one row per instant: time_utc and ``<ins_unit>_lat_m``,
                     ``<ins_unit>_lon_m``, ``<ins_unit>_course_deg``
``unit_stats``       one row per window, INS unit and channel: window, window_start_utc,
                     ins_unit, channel, measure_unit (m or deg), n, m_u, m_y,
                     kurtosis_excess, limit, a priori, hat and reference figures

Every column is named and typed as :data:`dracc.core.vocabulary.TABLE_COLUMNS` says:
times (``*_utc``) are ``timestamp[ns, tz=UTC]`` in Parquet and ISO 8601 with ``Z`` in
CSV (:func:`csv_ready`, shared with the fleet tables), dates ``date32`` and
``YYYY-MM-DD``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pa_csv

from dracc.core import atomic
from dracc.core.arrays import ArrayLike
from dracc.core.safetext import csv_cell
from dracc.core.timefmt import iso_utc
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNEL_UNITS, CHANNELS
from dracc.math.deviation import WindowStats
from dracc.pipeline.results import Analysis, DRTrackResult


def _times(time_ns: ArrayLike) -> pd.DatetimeIndex:
    return pd.to_datetime(np.asarray(time_ns, dtype="int64"), unit="ns", utc=True)


def dr_frame(t: DRTrackResult) -> pd.DataFrame:
    """A DR track as a table."""
    return pd.DataFrame(
        {
            "time_utc": _times(t.time_ns),
            "lat_deg": np.degrees(t.lat_rad),
            "lon_deg": np.degrees(t.lon_rad),
            "since_fix_s": t.since_fix_s,
            "radius_2m_m": t.radius_2m_m,
            "semi_major_m": t.semi_major_m,
            "semi_minor_m": t.semi_minor_m,
            "orientation_deg": np.degrees(t.orientation_rad),
            "ref_error_m": t.ref_error_m,
            "leg": np.asarray(t.leg, dtype="int64"),
            "water_lat_deg": np.degrees(t.water_lat_rad),
            "water_lon_deg": np.degrees(t.water_lon_rad),
            "scored": np.asarray(t.scored, dtype=bool),
        }
    )


def samples_frame(a: Analysis) -> pd.DataFrame | None:
    """Deviation samples, one row per instant."""
    d = a.deviation
    if d is None:
        return None
    cols: dict[str, object] = {"time_utc": _times(d.time_ns)}
    for unit in d.units:
        for ch in CHANNELS:
            if ch in d.samples[unit]:
                cols[f"{unit}_{CHANNEL_KEYS[ch]}"] = np.asarray(d.samples[unit][ch], dtype=float)
    return pd.DataFrame(cols)


def _window_rows(w: WindowStats) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for name, u in w.units.items():
        for ch in CHANNELS:
            c = u.channels.get(ch)
            if c is None:
                continue
            h = u.hat.get(ch)
            r = u.reference.get(ch)
            rows.append(
                {
                    "window": w.label,
                    "window_start_utc": pd.Timestamp(w.start_ns, unit="ns", tz="UTC"),
                    "ins_unit": name,
                    "channel": ch,
                    "measure_unit": CHANNEL_UNITS[ch],
                    "n": c.n,
                    "m_u": c.m_u,
                    "k": c.k,
                    "m_y": c.m_y,
                    "kurtosis_excess": c.kurtosis,
                    "k_pie": c.k_pie,
                    "k_hm": c.k_hm,
                    "limit": c.limit,
                    "apriori": np.nan if c.apriori is None else c.apriori,
                    "exceeds_apriori": c.exceeds_apriori,
                    "new_apriori": c.new_apriori,
                    "r_lat_lon": u.r_lat_lon,
                    "hat_variance": np.nan if h is None else h.variance,
                    "hat_sigma": np.nan if h is None else h.sigma,
                    "hat_negative": None if h is None else h.negative,
                    "ref_rmse": np.nan if r is None else r.rmse,
                    "ref_m_x": np.nan if r is None else r.m_x,
                    "k_star": np.nan if r is None else r.k_star,
                    "mark": None if r is None else r.mark,
                }
            )
    return rows


def stats_frame(a: Analysis) -> pd.DataFrame | None:
    """Per-unit statistics: the whole log first (window 'all'), then each window."""
    d = a.deviation
    if d is None:
        return None
    rows = _window_rows(d.whole)
    for w in d.windows:
        rows.extend(_window_rows(w))
    df = pd.DataFrame(rows)
    for c in ("exceeds_apriori", "hat_negative"):
        if c in df:
            df[c] = df[c].astype("boolean")
    return df


def frames(a: Analysis) -> dict[str, pd.DataFrame]:
    """Every table this analysis has, by name."""
    out: dict[str, pd.DataFrame] = {}
    if a.dead_reckoning is not None:
        out["dr_track"] = dr_frame(a.dead_reckoning.track)
        out["dr_epochs"] = dr_frame(a.dead_reckoning.epochs)
    s = samples_frame(a)
    if s is not None:
        out["deviation_samples"] = s
    st = stats_frame(a)
    if st is not None:
        out["unit_stats"] = st
    return out


def _iso_column(col: pd.Series) -> pd.Series:
    """A timestamp column as ISO 8601 UTC text with ``Z``, with the fewest fractional
    digits of a second (0, 3, 6 or 9) that write every time of the column exactly;
    missing times (NaT) an empty cell."""
    utc = col.dt.tz_convert("UTC") if col.dt.tz is not None else col.dt.tz_localize("UTC")
    ns = utc.dt.tz_localize(None).to_numpy("datetime64[ns]").view("int64")
    have = ~utc.isna().to_numpy()
    text = np.full(len(col), "", dtype=object)
    if have.any():
        t = ns[have]
        unit = next(
            (u for u, step in (("s", 10**9), ("ms", 10**6), ("us", 10**3)) if not (t % step).any()),
            "ns",
        )
        text[have] = iso_utc(t, unit)
    return pd.Series(text, index=col.index, dtype=object)


def csv_ready(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` as its CSV shows it: timestamps as ISO 8601 UTC text with ``Z``
    (:func:`_iso_column`), dates as ``YYYY-MM-DD``, and a text cell starting with ``=``,
    ``+``, ``-``, ``@``, a tab or a CR with a leading single quote, so that no cell is read
    as a formula (:func:`dracc.core.safetext.csv_cell`).  Numbers are left alone."""
    out = df.copy()
    for col in out.columns:
        c = out[col]
        if isinstance(c.dtype, pd.DatetimeTZDtype) or pd.api.types.is_datetime64_dtype(c):
            out[col] = _iso_column(c)
        elif isinstance(c.dtype, pd.ArrowDtype) and pa.types.is_date(c.dtype.pyarrow_dtype):
            out[col] = c.astype("string")
        elif pd.api.types.is_string_dtype(c) or c.dtype == object:
            out[col] = c.map(csv_cell, na_action="ignore")
    return out


def write_tables(a: Analysis, out_dir: str | Path) -> list[Path]:
    """Write every table as CSV and Parquet into ``out_dir``; return the paths written."""
    out_dir = Path(out_dir)
    written = []
    for name, df in frames(a).items():
        csv_path = out_dir / f"{name}.csv"
        with atomic.atomic_path(csv_path) as tmp:
            pa_csv.write_csv(pa.Table.from_pandas(csv_ready(df), preserve_index=False), tmp)
        written.append(csv_path)
        pq_path = out_dir / f"{name}.parquet"
        with atomic.atomic_path(pq_path) as tmp:
            df.to_parquet(tmp, index=False, engine="pyarrow")
        written.append(pq_path)
    return written
