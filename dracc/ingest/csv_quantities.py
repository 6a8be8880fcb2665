"""Named quantities with their unit in the name: the vocabulary of CSV and MCAP/JSON logs.

A quantity name is a base name and a unit suffix, e.g. ``lat_deg``, ``stw_kn``,
``sog_mps``, ``total_water_nmi``.  The suffix says how to reach the canonical unit
(radians, metres per second, metres, radians per second), so a column in knots is never
read as metres per second: ``stw_kn`` is multiplied by 1852/3600 (exact, units.py) and
``stw_mps`` is taken as is.  Names without a unit suffix are read only where they are
dimensionless (``quality``, ``hdop``, ``reference``).

This table is used by the CSV long and wide forms, by plain JSON objects in MCAP and by
ROS 2 / protobuf messages whose field names are quantity names (the dracc message types).

=================  ========  ======================  ==============================
base name          kind      canonical column        unit suffixes accepted
=================  ========  ======================  ==============================
lat, lon           position  lat_rad, lon_rad        deg, rad
alt                position  alt_m                   m
quality, hdop      position  quality, hdop           (none)
heading            heading   heading_rad             deg, rad
deviation          heading   deviation_rad           deg, rad
variation          heading   variation_rad           deg, rad (east positive)
reference          heading   reference               (none; 'T'/'M', 'true'/'magnetic' ...)
is_true ...        heading   reference               (none; boolean, see vocabulary.py)
cog                ground    cog_rad                 deg, rad
sog                ground    sog_mps                 kn, mps, kmh
stw                water     stw_mps                 kn, mps, kmh
stw_transverse     water     stw_transverse_mps      kn, mps, kmh
sog_long           water     sog_long_mps            kn, mps, kmh
sog_transverse     water     sog_transverse_mps      kn, mps, kmh
total_water        distance  total_water_m           m, nmi
trip_water         distance  trip_water_m            m, nmi
rot                rot       rot_radps               radps, degps, degpmin
=================  ========  ======================  ==============================

Plausibility (a value outside is rejected, counted, never clamped): latitude within
[-90 deg, 90 deg], longitude within [-180 deg, 180 deg], headings and courses within
[0, 360 deg] (360 is read as 0), deviation and variation within [-180 deg, 180 deg],
speeds finite and below 100 m/s (194 kn), distances finite and non-negative, quality
an integer in [0, 9], hdop non-negative.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.quantities import (
    BOOLEAN_FIELDS,
    QUANTITIES,
    Quantity,
)
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M
from dracc.frames import KIND_COLUMNS, Rejects, make_frame
from dracc.ingest.references import (
    REJECT_REASON,
    normalize_boolean,
    normalize_reference,
)

#: names that look like a physical quantity but carry no unit: a hint for the user
UNITLESS_HINTS = {
    "lat",
    "lon",
    "latitude",
    "longitude",
    "heading",
    "hdg",
    "course",
    "cog",
    "speed",
    "sog",
    "stw",
    "rot",
    "alt",
    "altitude",
    "distance",
}

_SPEED_MAX_MPS = 100.0


def lookup(name: str, declared: dict[str, str] | None = None) -> Quantity | None:
    """The quantity a column/field ``name`` holds, or None if it names none.

    ``declared`` (``[ingest] quantities`` in the config) maps a column or field name that
    does not carry its unit to a quantity name, e.g. ``{"Speed (kn)": "stw_kn"}``; it
    wins over the name itself.
    """
    if declared and name in declared:
        return QUANTITIES.get(declared[name])
    return QUANTITIES.get(name)


def check_declared(declared: dict[str, str], where: str) -> None:
    """Raise ConfigError when a declared quantity name is unknown."""
    from dracc.core.errors import ConfigError

    for col, q in declared.items():
        if q not in QUANTITIES:
            raise ConfigError(
                f"[ingest.quantities] {col!r} = {q!r}: not a quantity name "
                f"({where}); known: {', '.join(sorted(QUANTITIES))}"
            )


def _valid_mask(column: str, v: np.ndarray) -> np.ndarray:
    """True where a canonical value is plausible (NaN counts as valid: it means absent)."""
    nan = np.isnan(v)
    with np.errstate(invalid="ignore"):
        if column == "lat_rad":
            ok = np.abs(v) <= math.pi / 2
        elif column == "lon_rad":
            ok = np.abs(v) <= math.pi
        elif column in ("heading_rad", "cog_rad"):
            ok = (v >= 0.0) & (v <= 2 * math.pi)
        elif column in ("deviation_rad", "variation_rad"):
            ok = np.abs(v) <= math.pi
        elif column.endswith("_mps"):
            ok = np.abs(v) < _SPEED_MAX_MPS
        elif column.endswith("_m") and column != "alt_m":
            ok = np.isfinite(v) & (v >= 0.0)
        elif column == "quality":
            ok = (v >= 0) & (v <= 9) & (v == np.round(v))
        elif column == "hdop":
            ok = v >= 0.0
        else:
            ok = np.isfinite(v)
    valid: np.ndarray = ok | nan
    return valid


def add_rejects(
    rejects: Rejects, reason: str, file: str, lines: np.ndarray, texts: list[str]
) -> None:
    """Count ``len(lines)`` rejects of one reason, keeping the first few as examples."""
    n = len(lines)
    if n == 0:
        return
    k = min(n, rejects.max_examples)
    for i in range(k):
        rejects.add(reason, file, int(lines[i]), texts[i] if i < len(texts) else "")
    if n > k:
        rejects.counts[reason] += n - k


def _labels(x: object, n: int) -> pd.Categorical | np.ndarray:
    """A string column as given (a Categorical stays one), a scalar as a 1-byte Categorical."""
    if isinstance(x, pd.Categorical):
        return x
    if np.isscalar(x):
        return pd.Categorical.from_codes(np.zeros(n, dtype=np.int8), categories=[x])
    return np.asarray(x, dtype=object)


def build_frames(
    time_ns: np.ndarray,
    source: object,
    line: np.ndarray,
    sentence: object,
    values: dict[str, np.ndarray],
    file: str,
    rejects: Rejects,
    talker: object = None,
    recv_ns: np.ndarray | None = None,
) -> dict[str, pd.DataFrame]:
    """Canonical frames from records given as quantity columns.

    ``values`` maps quantity names (``lat_deg``, ``stw_kn``, ...) to float arrays (or, for
    ``reference``, string arrays) aligned with ``time_ns``; NaN marks an absent value.
    A record goes into a kind's frame where at least one of that kind's quantities is
    present; a position needs both latitude and longitude.  Values are converted to the
    canonical units (factor per suffix), headings of exactly 2*pi become 0, and
    implausible values reject the record from that kind (counted by reason with the
    line number).  Two quantities naming the same canonical column (``stw_kn`` and
    ``stw_mps``) in one file are an error of the file, rejected where both are present.
    ``recv_ns`` (aligned with ``time_ns``; default all ``MISSING_NS``): the receive time of
    records timed by their own time of fix (an MCAP message's stamp).
    """
    n = len(time_ns)
    by_kind: dict[str, dict[str, np.ndarray]] = {}
    for name, arr in values.items():
        q = QUANTITIES[name]
        cols = by_kind.setdefault(q.kind, {})
        if q.column == "reference":
            ref, bad = (
                normalize_boolean(arr, BOOLEAN_FIELDS[name])
                if name in BOOLEAN_FIELDS
                else normalize_reference(arr)
            )
            if "reference" in cols:  # two fields give it: they must agree
                prev = cols["reference"]
                clash = (prev != None) & (ref != None) & (prev != ref)  # noqa: E711
                bad |= clash
                ref = np.where(prev != None, prev, ref)  # noqa: E711
                bad_prev = cols.pop("_ref_bad")
                bad |= bad_prev
            cols["reference"] = ref
            cols["_ref_bad"] = bad
            if bad.any():
                idx = np.flatnonzero(bad)
                raw = np.asarray(arr, dtype=object)
                add_rejects(
                    rejects, REJECT_REASON, file, line[idx], [f"{name}={raw[i]!r}" for i in idx[:5]]
                )
            continue
        v = np.asarray(arr, dtype=np.float64) * q.factor
        if q.column in cols:
            prev = cols[q.column]
            both = ~np.isnan(prev) & ~np.isnan(v)
            if both.any():
                idx = np.flatnonzero(both)
                add_rejects(
                    rejects,
                    f"{q.column} given twice in different units",
                    file,
                    line[idx],
                    [f"{name}" for _ in idx[:5]],
                )
                v = np.where(both, np.nan, v)
                prev = np.where(both, np.nan, prev)
            cols[q.column] = np.where(np.isnan(prev), v, prev)
        else:
            cols[q.column] = v
    frames: dict[str, pd.DataFrame] = {}
    src, sen = _labels(source, n), _labels(sentence, n)
    tal = _labels("" if talker is None else talker, n)
    for kind, cols in by_kind.items():
        ref_bad = cols.pop("_ref_bad", None)
        numeric = {c: v for c, v in cols.items() if c != "reference"}
        present = np.zeros(n, dtype=bool)
        for v in numeric.values():
            present |= ~np.isnan(v)
        if "reference" in cols and not numeric:
            continue  # a reference alone says nothing
        keep = present.copy()
        if kind == "position":
            lat = numeric.get("lat_rad", np.full(n, np.nan))
            lon = numeric.get("lon_rad", np.full(n, np.nan))
            half = present & (np.isnan(lat) | np.isnan(lon))
            if half.any():
                idx = np.flatnonzero(half)
                add_rejects(
                    rejects,
                    "position without both lat and lon",
                    file,
                    line[idx],
                    [str(src[i]) for i in idx[:5]],
                )
            keep &= ~half
        for c, v in numeric.items():
            bad = keep & ~_valid_mask(c, v)
            if bad.any():
                idx = np.flatnonzero(bad)
                add_rejects(
                    rejects,
                    f"{c} out of range",
                    file,
                    line[idx],
                    [f"{c}={v[i]:.6g} (canonical unit)" for i in idx[:5]],
                )
                keep &= ~bad
        if ref_bad is not None:
            keep &= ~ref_bad  # counted above: never read as true or magnetic by accident
        if not keep.any():
            continue
        idx = np.flatnonzero(keep)
        data: dict[str, Any] = {
            "time_ns": np.asarray(time_ns)[idx],
            "source": src[idx],
            "sentence": sen[idx],
            "line": np.asarray(line)[idx],
            "talker": tal[idx],
        }
        for c, v in numeric.items():
            v = v[idx]
            if c in ("heading_rad", "cog_rad"):
                v = np.where(v == 2 * math.pi, 0.0, v)
            if c == "quality":
                v = np.where(np.isnan(v), 1, v).astype(np.int8)
            data[c] = v
        if "reference" in cols:
            data["reference"] = cols["reference"][idx]
        if kind == "heading" and "reference" not in cols:
            data["reference"] = np.full(len(idx), "T", dtype=object)
        if kind == "position" and "quality" not in numeric:
            data["quality"] = np.ones(len(idx), dtype=np.int8)
        if recv_ns is not None:
            data["recv_ns"] = np.asarray(recv_ns, dtype=np.int64)[idx]
        frames[kind] = make_frame(kind, data)
    return frames


def frame_quantities(kind: str, df: pd.DataFrame) -> dict[str, np.ndarray]:
    """The inverse of :func:`build_frames` for writers: canonical columns as quantity
    columns in the units a navigator reads (degrees, knots, nautical miles), named so."""
    out: dict[str, np.ndarray] = {}
    for col in KIND_COLUMNS[kind]:
        if col not in df:
            continue
        if col in ("quality", "hdop"):
            out[col] = df[col].to_numpy(dtype=np.float64)
        elif col == "reference":
            out[col] = df[col].astype(object).to_numpy()
        elif col.endswith("_rad"):
            out[col[:-4] + "_deg"] = df[col].to_numpy(dtype=np.float64) / DEG_RAD
        elif col.endswith("_radps"):
            out[col[:-6] + "_degpmin"] = df[col].to_numpy(dtype=np.float64) * 60.0 / DEG_RAD
        elif col.endswith("_mps"):
            out[col[:-4] + "_kn"] = df[col].to_numpy(dtype=np.float64) / KN_MPS
        elif col == "alt_m":
            out[col] = df[col].to_numpy(dtype=np.float64)
        elif col.endswith("_m"):
            out[col[:-2] + "_nmi"] = df[col].to_numpy(dtype=np.float64) / NMI_M
    return out


def renumber_examples(rejects: Rejects, numbers: np.ndarray) -> None:
    """Rewrite reject examples numbered by position in a list of sentences (1-based) to the
    numbers of their origin (CSV line, MCAP message), in place."""
    for reason, ex in rejects.examples.items():
        rejects.examples[reason] = [
            (f, int(numbers[ln - 1]) if 1 <= ln <= len(numbers) else ln, t) for f, ln, t in ex
        ]
