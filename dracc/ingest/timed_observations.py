"""The observation file of ``dracc analyze --observations``: ``dracc fix``'s tables with a time.

Each ``[[fix]]``, ``[[range]]``, ``[[bearing]]`` or ``[[line]]`` table takes the keys of
:data:`dracc.ingest.observations.TABLE_FORMS` plus ``time`` (ISO 8601, UTC unless an
offset is given; a TOML date-time works too).  Each becomes one update of the
estimated-position filter at that time (a range, a bearing or a line: a single line of
position).  Pier lines, abeam marks and nadir circles are for ``dracc fix`` only.
Positions referred to another datum (a top-level ``datum = "ED50"``, or an item's own
``datum``) are moved to WGS-84 as ``dracc fix`` moves them
(:func:`dracc.ingest.observations.referred_to_wgs84`); the spec keeps the record.
"""

from __future__ import annotations

import datetime as dt
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dracc.core.errors import FixFileError
from dracc.core.timefmt import parse_utc
from dracc.ingest.observations import (
    DATUM_KINDS,
    TABLE_FORMS,
    ObsSpec,
    Pending,
    build_observation,
    checked_datum,
    load_obs_toml,
    referred_to_wgs84,
)

if sys.version_info >= (3, 11):
    pass
else:  # pragma: no cover
    pass

#: the tables the filter takes: one full fix or one line of position each
TIMED_TABLES = ("fix", "range", "bearing", "line")


@dataclass(frozen=True)
class TimedObservation:
    """An observation checked as ``dracc fix`` checks it, with its UTC time."""

    time_ns: int
    spec: ObsSpec


def _time_ns(raw: Any, where: str) -> int:
    try:
        t = raw if isinstance(raw, dt.datetime) else parse_utc(str(raw))
    except ValueError as e:
        raise FixFileError(f"{where}: time {raw!r} is not an ISO 8601 time ({e})") from e
    if t.tzinfo is None:
        t = t.replace(tzinfo=dt.timezone.utc)
    epoch = dt.datetime(1970, 1, 1, tzinfo=dt.timezone.utc)
    d = t - epoch
    return (d.days * 86400 + d.seconds) * 1_000_000_000 + d.microseconds * 1000


def read_timed_observations(path: Path) -> tuple[TimedObservation, ...]:
    """The file's observations in time order (exit 3 for a missing file, 4 for a bad one)."""
    data = load_obs_toml(path)
    out: list[TimedObservation] = []
    file_datum = None
    if "datum" in data:
        file_datum = checked_datum(f"{path}: datum", data.pop("datum"), FixFileError)
    for table, value in data.items():
        if table not in TIMED_TABLES:
            raise FixFileError(
                f"{path}: table {table!r} is not used by analyze "
                f"(tables: {', '.join(TIMED_TABLES)}, each with a time)"
            )
        kind, required, optional = TABLE_FORMS[table]
        allowed = {k for s in required + optional for k in s.split("|")} | {"time", "datum"}
        for i, entry in enumerate(value if isinstance(value, list) else [value], start=1):
            where = f"{path}: [[{table}]] #{i}"
            if not isinstance(entry, dict):
                raise FixFileError(f"{where}: expected a table with keys, got {entry!r}")
            unknown = sorted(set(entry) - allowed)
            if unknown:
                raise FixFileError(
                    f"{where}: unknown key {unknown[0]!r} (keys: {', '.join(sorted(allowed))})"
                )
            missing = [s for s in required if not any(k in entry for k in s.split("|"))]
            if "time" not in entry or missing:
                name = "time" if "time" not in entry else missing[0].replace("|", " or ")
                raise FixFileError(f"{where}: missing key {name!r}")
            fields = {k: v for k, v in entry.items() if k not in ("time", "datum")}
            datum = entry.get("datum", file_datum)
            if "datum" in entry:
                datum = checked_datum(f"{where}: datum", entry["datum"], FixFileError)
            k = kind
            if table == "bearing":
                at = fields.pop("observed_at", "ship")
                if at not in ("ship", "mark"):
                    raise FixFileError(f"{where}: observed_at must be 'ship' or 'mark', got {at!r}")
                k = "bearing_from_mark" if at == "mark" else kind
            spec = build_observation(Pending(k, where, fields), f"{table} {i}", 0)
            if datum is not None and k in DATUM_KINDS:
                spec = referred_to_wgs84(spec, datum)
            out.append(TimedObservation(_time_ns(entry["time"], where), spec))
    return tuple(sorted(out, key=lambda o: o.time_ns))


__all__ = ["TIMED_TABLES", "TimedObservation", "read_timed_observations"]
