"""``[reference]``: the berths of ``alongside`` (seeds/004, Figure 1), for the INS check.

``[reference] alongside = {pier = [LAT1, LON1, LAT2, LON2], side = "port"|"starboard",
half_breadth_m = ...}`` (one berth) or ``[[reference.alongside]]`` (several), the fields of
``dracc fix --pier`` and ``--abeam`` (docs/fix.md) and when the ship lay there.  The
schema machinery (types, ranges, messages naming the key) is :mod:`dracc.core.config`'s;
here are the berth's own rules: the pier's ends, the heading along the pier (within 15 deg
either way, as :class:`dracc.math.fusion.PierLine` demands), the period's order, no two
periods overlapping.  How ``analyze`` uses a berth: docs/deviation.md.
"""

from __future__ import annotations

import datetime as _dt
import itertools
import math
from dataclasses import dataclass

from dracc.core.errors import ConfigError

__all__ = [
    "PIER_MISALIGNMENT_MAX_DEG",
    "BerthConfig",
    "ReferenceConfig",
    "check_abeam",
    "check_alongside",
    "check_berth",
    "check_pier",
    "check_utc",
    "one_or_many",
    "toml_datetime",
    "utc_ns",
]


@dataclass(frozen=True)
class BerthConfig:
    """One berth of ``[reference] alongside`` (``[[reference.alongside]]``): the ``dracc fix
    --pier`` form (seeds/004, Figure 1) and when the ship lay there (docs/deviation.md)."""

    pier: tuple[float, ...]  #: LAT1, LON1, LAT2, LON2 (decimal degrees, WGS-84): the pier line A->B
    side: str  #: the ship's side to the pier: "port" or "starboard"
    half_breadth_m: float  #: centreline to the side touching the pier
    heading_deg: float | None = (
        None  #: the ship's true heading alongside (None: the compass, else the INS)
    )
    sigma_m: float = 1.0  #: across the pier: the charted line, the gap and the ship's offsets
    gap_m: float = 0.0  #: fenders, side to pier line
    ref_stbd_m: float = 0.0  #: the reference point to starboard of the centreline (port -)
    abeam: tuple[float, ...] | None = None  #: LAT, LON of a pier mark abeam of the reference point
    abeam_sigma_m: float = 2.0  #: along the pier, of the abeam mark
    start_utc: str | None = None  #: when the ship lay there (ISO 8601 UTC); None: detected
    end_utc: str | None = None
    tolerance_m: float = 200.0  #: detection: the INS mean within this of the berth ...
    max_speed_kn: float = 0.5  #: ... and moving slower than this
    #: the datum the pier and abeam positions are charted on (ED50, 'EPSG:4230', ...);
    #: None: WGS-84.  Moved to WGS-84 by the analysis (dracc.ingest.datums, seeds/004 §2)
    datum: str | None = None

    @property
    def start_ns(self) -> int | None:
        """``start_utc`` as int64 UTC nanoseconds (None where not given)."""
        return utc_ns(self.start_utc)

    @property
    def end_ns(self) -> int | None:
        """``end_utc`` as int64 UTC nanoseconds (None where not given)."""
        return utc_ns(self.end_utc)


@dataclass(frozen=True)
class ReferenceConfig:
    """``[reference]``: reference positions for the INS check where there is no GNSS."""

    alongside: tuple[BerthConfig, ...] = ()  #: the berths (an inline table or an array of tables)


def _fail(section: str, key: str, value: object, what: str) -> ConfigError:
    """``[section] key = value: what`` (the form of dracc.core.config's messages)."""
    return ConfigError(f"[{section}] {key} = {value!r}: {what}")


#: a pier heading further than this from the pier line's azimuth (either way) is refused,
#: as ``dracc fix --pier`` does (dracc.math.fusion.PierLine)
PIER_MISALIGNMENT_MAX_DEG = 15.0


def utc_ns(text: str | None) -> int | None:
    """A checked ``...Z`` time (:func:`check_utc`) as int64 UTC nanoseconds."""
    if text is None:
        return None
    t = _dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    return int(t.timestamp()) * 1_000_000_000 + t.microsecond * 1000


def toml_datetime(value: object) -> object:
    """A TOML date-time (``start_utc = 2026-03-01T08:00:00Z``, unquoted) is its ISO text."""
    if isinstance(value, _dt.datetime):
        return value.isoformat()
    return value


def check_utc(value: str | None, section: str, key: str) -> str | None:
    """An ISO 8601 UTC time ("2026-03-01T08:00:00Z"; no offset: UTC), normalised to ``...Z``."""
    if value is None:
        return None
    try:
        t = _dt.datetime.fromisoformat(value.strip().replace("Z", "+00:00"))
    except ValueError:
        raise _fail(section, key, value, 'expected a UTC time "YYYY-MM-DDTHH:MM:SSZ"') from None
    if t.tzinfo is not None:
        t = t.astimezone(_dt.timezone.utc).replace(tzinfo=None)
    return t.isoformat() + "Z"


def _check_lat_lon(values: tuple[float, ...], section: str, key: str, n: int) -> None:
    if len(values) != n:
        what = "LAT1, LON1, LAT2, LON2" if n == 4 else "LAT, LON"
        raise _fail(section, key, list(values), f"expected {n} numbers ({what}, decimal degrees)")
    for i in range(0, n, 2):
        if not (-90.0 <= values[i] <= 90.0 and -180.0 <= values[i + 1] <= 180.0):
            raise _fail(
                section,
                key,
                list(values),
                "latitudes must lie in [-90, 90], longitudes in [-180, 180]",
            )


def _pier_ne_m(pier: tuple[float, ...]) -> tuple[float, float]:
    """B of the pier line from A, north and east metres (B18, B19 inverted)."""
    from dracc.core.geodesy import offset_ne_m  # core's own geodesy, on use

    lat1, lon1, lat2, lon2 = (math.radians(v) for v in pier)
    n_m, e_m = offset_ne_m(lat2, lon2, lat1, lon1)
    return float(n_m), float(e_m)


def check_pier(value: tuple[float, ...], section: str, key: str) -> tuple[float, ...]:
    _check_lat_lon(value, section, key, 4)
    if math.hypot(*_pier_ne_m(value)) < 1.0:
        raise _fail(
            section, key, list(value), "the two ends of the pier line are less than 1 m apart"
        )
    return value


def check_abeam(value: tuple[float, ...], section: str, key: str) -> tuple[float, ...]:
    _check_lat_lon(value, section, key, 2)
    return value


def check_berth(b: BerthConfig, where: str) -> BerthConfig:
    """A berth whose fields are checked (by :mod:`dracc.core.config`'s schema): the heading
    against the pier's azimuth and the period's order."""
    if b.heading_deg is not None:
        north, east = _pier_ne_m(b.pier)
        azimuth = math.degrees(math.atan2(east, north))
        off = abs((b.heading_deg - azimuth + 180.0) % 360.0 - 180.0)
        if min(off, 180.0 - off) > PIER_MISALIGNMENT_MAX_DEG:
            raise _fail(
                where,
                "heading_deg",
                b.heading_deg,
                f"not along the pier (its azimuth is {azimuth % 360:.1f} deg; more than "
                f"{PIER_MISALIGNMENT_MAX_DEG:g} deg off either way)",
            )
    if b.start_ns is not None and b.end_ns is not None and b.end_ns <= b.start_ns:
        raise _fail(where, "end_utc", b.end_utc, f"must be after start_utc = {b.start_utc}")
    return b


def one_or_many(value: object) -> object:
    """``alongside = {...}`` (one berth) or ``[[reference.alongside]]`` (several)."""
    return [value] if isinstance(value, dict) else value


def check_alongside(
    berths: tuple[BerthConfig, ...], section: str, key: str
) -> tuple[BerthConfig, ...]:
    """Configured periods do not overlap (the ship lies at one berth at a time)."""
    spans = sorted(
        (b.start_ns if b.start_ns is not None else -(2**62), i, b)
        for i, b in enumerate(berths)
        if b.start_ns is not None or b.end_ns is not None
    )
    for (_, i, b0), (s1, j, _) in itertools.pairwise(spans):
        end0 = b0.end_ns if b0.end_ns is not None else 2**62
        if s1 < end0:
            raise ConfigError(
                f"[{section}] {key}[{i}] and {key}[{j}] overlap in time: the ship lies "
                "at one berth at a time (give start_utc and end_utc)"
            )
    return berths
