"""Write canonical frames as a CSV voyage log (long or wide form), read back by
:func:`dracc.ingest.csv.read_csv`.

Values are written in the units a navigator reads, with the unit in the name
(``lat_deg``, ``heading_deg``, ``stw_kn``, ``total_water_nmi``, ``rot_degpmin``; see
:func:`dracc.ingest.csv_quantities.frame_quantities`), each with 17 significant digits so
that reading back reproduces the value to the last bit in those units.  Times are ISO
8601 UTC with nanoseconds (``2024-05-01T12:00:00.000000000Z``).

One time per record, ``time_ns``: the time of fix of a record that has one, the receive
time of the others; so a CSV shows the sources' latencies on records without a time of
fix, a leap (GNSS time) and a clock step, and with ``date_shifts`` (a week rollover) the
GNSS's early dates; not the receive times of fixes, and rows in time order show a loop as
records repeated, not as a step back.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd

from dracc.core.atomic import atomic_path
from dracc.core.timefmt import iso_utc
from dracc.frames import KINDS
from dracc.ingest.csv_quantities import frame_quantities
from dracc.sim.nmea_out import DateShifts, date_shift_days


def _fmt(v: np.ndarray) -> np.ndarray:
    """Floats as shortest round-trip text ('' for NaN); integers without '.0'."""
    s = pd.Series(v, dtype=np.float64)
    out = np.array([repr(float(x)) for x in s.to_numpy()], dtype=object)
    out[s.isna().to_numpy()] = ""
    whole = (
        s.notna().to_numpy()
        & (s.to_numpy() == np.round(s.to_numpy()))
        & (np.abs(s.to_numpy()) < 1e15)
    )
    out[whole] = np.array([str(int(x)) for x in s.to_numpy()[whole]], dtype=object)
    return out


def _tables(
    frames: dict[str, pd.DataFrame],
) -> Iterator[tuple[str, pd.DataFrame, dict[str, np.ndarray]]]:
    for kind in KINDS:
        df = frames.get(kind)
        if df is None or len(df) == 0:
            continue
        yield kind, df, frame_quantities(kind, df)


def _early(df: pd.DataFrame, shifts: DateShifts) -> pd.DataFrame:
    """``df`` with its times ``date_shift_days`` early where ``shifts`` say."""
    t = df["time_ns"].to_numpy(np.int64)
    days = date_shift_days(df["source"].astype(str).to_numpy(object), t, shifts)
    return df.assign(time_ns=t - days * 86_400 * 1_000_000_000) if days.any() else df


def write_csv(
    frames: dict[str, pd.DataFrame],
    path: str | Path,
    form: str = "long",
    date_shifts: DateShifts = (),
) -> Path:
    """Write ``frames`` (kind -> canonical frame) to ``path`` atomically; return the path.

    ``form='long'``: ``time_utc,source,quantity,value``, one present value per row, rows in
    time order.  ``form='wide'``: ``time_utc,source,<quantities...>``, one row per time and
    source (records of several kinds at the same time and source share a row).
    ``date_shifts``: a source's times that many days early in a window (a rollover).
    """
    if form not in ("long", "wide"):
        raise ValueError(f"form must be 'long' or 'wide', got {form!r}")
    if date_shifts:
        frames = {k: _early(df, date_shifts) if len(df) else df for k, df in frames.items()}
    path = Path(path)
    parts = []
    if form == "long":
        for _kind, df, qs in _tables(frames):
            t = df["time_ns"].to_numpy(dtype=np.int64)
            src = df["source"].astype(str).to_numpy(dtype=object)
            for q, v in qs.items():
                if q == "reference":
                    mask = pd.notna(v) & (v != "")
                    txt = np.asarray(v, dtype=object)
                else:
                    mask = ~np.isnan(v)
                    txt = _fmt(v)
                if not mask.any():
                    continue
                parts.append(
                    pd.DataFrame(
                        {"time_ns": t[mask], "source": src[mask], "quantity": q, "value": txt[mask]}
                    )
                )
        if parts:
            out = pd.concat(parts, ignore_index=True).sort_values("time_ns", kind="stable")
        else:
            out = pd.DataFrame(
                {"time_ns": np.zeros(0, np.int64), "source": [], "quantity": [], "value": []}
            )
        out.insert(0, "time_utc", iso_utc(unit="ns", time_ns=out["time_ns"].to_numpy()))
        out = out.drop(columns="time_ns")
    else:
        merged = None
        for _kind, df, qs in _tables(frames):
            t = pd.DataFrame(
                {
                    "time_ns": df["time_ns"].to_numpy(dtype=np.int64),
                    "source": df["source"].astype(str).to_numpy(dtype=object),
                }
            )
            t["occ"] = t.groupby(["time_ns", "source"]).cumcount().to_numpy()
            for q, v in qs.items():
                t[q] = v if q == "reference" else _fmt(v)
            merged = (
                t
                if merged is None
                else merged.merge(t, on=["time_ns", "source", "occ"], how="outer")
            )
        if merged is None:
            out = pd.DataFrame({"time_utc": [], "source": []})
        else:
            merged = merged.sort_values(["time_ns", "source", "occ"], kind="stable")
            merged.insert(0, "time_utc", iso_utc(unit="ns", time_ns=merged["time_ns"].to_numpy()))
            out = merged.drop(columns=["time_ns", "occ"]).fillna("")
    with atomic_path(path) as tmp:
        out.to_csv(tmp, index=False, lineterminator="\n")
    return path
