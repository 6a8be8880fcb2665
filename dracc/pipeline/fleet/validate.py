"""What a ship sends ashore, checked before the fleet uses it (issue 33).

An audit document (``dracc.audit/1``) or a night of an audit database comes from
outside: a damaged file, another program or a hostile sender may put anything in it.
The fleet reads a few dozen of its fields; each is checked here, before use, for its
type (``"logs": [1, 2, 3]``, ``"measures": "x"``), its size (texts, lists) and its range
(a night or time between 1980 and 2099 — ``9999-12-31`` would overflow the tables'
timestamps —, a finite number of at most 1e12 in magnitude, a count never negative, a
vessel name of at most 100 characters that fits a partition folder).  A field that is
absent or null is as the readers take it (no value); any other value of the wrong kind
makes the document (or database) one failed row, its reason naming the field::

    ins[0].m_y: expected a number or null, got a text

The checks mirror what :mod:`dracc.pipeline.fleet.documents`, the tables and the
ranking read, in the audit JSON Schema's own types (``dracc/report/audit.schema.json``:
``tests/test_fleet_hostile.py`` checks that it, too, accepts the good document and
refuses the wrong types), with the bounds the schema does not state.  No JSON Schema
validator runs here: ``jsonschema`` is a test dependency only, and the schema states
none of the bounds.  A document's checks take about a millisecond (its times parsed as
the tables parse them, :func:`pandas.to_datetime`).
"""

from __future__ import annotations

import datetime as dt
import math
import re
import unicodedata
from collections.abc import Callable, Mapping
from typing import Any

import pandas as pd

from dracc.core.vocabulary import CHANNELS
from dracc.pipeline.fleet.findings import COUNT_KEYS
from dracc.pipeline.fleet.query import hive_value

#: a check: raises :class:`Invalid` naming the field (its path) and what is wrong
Check = Callable[[Any, str], None]

#: the nights and times accepted (a night is a UTC date)
FIRST_NIGHT, LAST_NIGHT = dt.date(1980, 1, 1), dt.date(2099, 12, 31)
#: the largest magnitude of any number (an RMS in metres, a count of lines)
MAX_MAGNITUDE = 1e12
#: the longest text of any field (a finding's message is a few hundred characters)
MAX_TEXT = 10_000
#: the most items of any list or object (a night has a few dozen findings and rows)
MAX_ITEMS = 10_000
#: the longest vessel name (as :func:`dracc.pipeline.fleet.tasks.safe_name` keeps)
MAX_NAME = 100
#: the longest partition folder name ``vessel=<name>`` (most file systems' limit)
_NAME_MAX_BYTES = 255
_DATE = re.compile(r"[0-9]{4}-[0-9]{2}-[0-9]{2}")


class Invalid(ValueError):
    """A field of the wrong type, size or range."""


def _kind(x: Any) -> str:
    """What a JSON value is, in the error message's words."""
    if x is None:
        return "null"
    if isinstance(x, bool):
        return "a boolean"
    if isinstance(x, (int, float)):
        return f"the number {x!r}"
    if isinstance(x, str):
        return "a text"
    if isinstance(x, (list, tuple)):
        return "an array"
    if isinstance(x, Mapping):
        return "an object"
    return type(x).__name__


def _expected(at: str, what: str, x: Any) -> Invalid:
    return Invalid(f"{at}: expected {what} or null, got {_kind(x)}")


def text(x: Any, at: str) -> None:
    if not isinstance(x, str):
        raise _expected(at, "a text", x)
    if len(x) > MAX_TEXT:
        raise Invalid(f"{at}: a text of {len(x):,} characters (at most {MAX_TEXT:,})")


def number(x: Any, at: str) -> None:
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        raise _expected(at, "a number", x)
    if not math.isfinite(x) or abs(x) > MAX_MAGNITUDE:
        raise Invalid(f"{at}: {x!r} is out of range (a finite number of at most {MAX_MAGNITUDE:g})")


def count(x: Any, at: str) -> None:
    if isinstance(x, bool) or not isinstance(x, int):
        raise _expected(at, "a whole number", x)
    if not 0 <= x <= MAX_MAGNITUDE:
        raise Invalid(f"{at}: {x!r} is out of range (0 to {MAX_MAGNITUDE:g})")


def boolean(x: Any, at: str) -> None:
    if not isinstance(x, bool):
        raise _expected(at, "true or false", x)


def one_of(values: tuple[str, ...]) -> Check:
    """A text that is one of ``values`` (a channel: the tables and page know three)."""

    def check(x: Any, at: str) -> None:
        text(x, at)
        if x not in values:
            raise Invalid(f"{at}: {x[:40]!r} is not one of {', '.join(values)}")

    return check


def night(x: Any, at: str) -> None:
    """A night: a UTC date ``YYYY-MM-DD`` between 1980 and 2099."""
    text(x, at)
    try:
        d = dt.date.fromisoformat(x) if _DATE.fullmatch(x) else None
    except ValueError:
        d = None
    if d is None:
        raise Invalid(f"{at}: {x[:40]!r} is not a date YYYY-MM-DD")
    if not FIRST_NIGHT <= d <= LAST_NIGHT:
        raise Invalid(f"{at}: {x} is not a night between {FIRST_NIGHT} and {LAST_NIGHT}")


def timestamp(x: Any, at: str) -> None:
    """A time: ISO 8601 with its zone (``Z`` or an offset), between 1980 and 2099."""
    text(x, at)
    try:
        t = pd.to_datetime(x, format="ISO8601") if len(x) <= 64 else None
    except (ValueError, OverflowError):  # pandas' OutOfBoundsDatetime is a ValueError
        t = None
    if t is None or pd.isna(t) or t.tzinfo is None:
        raise Invalid(f"{at}: {x[:40]!r} is not an ISO 8601 time with its zone")
    if not FIRST_NIGHT <= t.tz_convert("UTC").date() <= LAST_NIGHT:
        raise Invalid(f"{at}: {x} is not a time between {FIRST_NIGHT} and {LAST_NIGHT}")


def vessel_name(x: Any, at: str) -> None:
    """A vessel name: a text of 1 to 100 characters without control characters, whose
    partition folder ``vessel=<name>`` fits a file name (255 bytes)."""
    text(x, at)
    if not x.strip() or len(x) > MAX_NAME:
        raise Invalid(f"{at}: a vessel name of {len(x):,} characters (1 to {MAX_NAME})")
    if any(unicodedata.category(c) == "Cc" for c in x):
        raise Invalid(f"{at}: the vessel name holds a control character")
    if len(f"vessel={hive_value(x)}".encode("utf-8", "surrogatepass")) > _NAME_MAX_BYTES:
        raise Invalid(f"{at}: the vessel name is too long for a partition folder")


def array(item: Check) -> Check:
    def check(x: Any, at: str) -> None:
        if not isinstance(x, (list, tuple)):
            raise _expected(at, "an array", x)
        if len(x) > MAX_ITEMS:
            raise Invalid(f"{at}: {len(x):,} items (at most {MAX_ITEMS:,})")
        for i, v in enumerate(x):
            if v is None:  # the readers take each item as it is: none may be missing
                raise Invalid(f"{at}[{i}]: null where an item is expected")
            item(v, f"{at}[{i}]")

    return check


def obj(
    fields: Mapping[str, Check], values: Check | None = None, required: tuple[str, ...] = ()
) -> Check:
    """An object whose ``fields`` (each absent, null or as its check says; ``required``
    ones present and not null) are read; ``values``: the check of every value (an object
    used as a map)."""

    def check(x: Any, at: str) -> None:
        if not isinstance(x, Mapping):
            raise _expected(at, "an object", x)
        if len(x) > MAX_ITEMS:
            raise Invalid(f"{at}: {len(x):,} keys (at most {MAX_ITEMS:,})")
        for k in required:
            if x.get(k) is None:
                raise Invalid(f"{at}.{k}: missing" if at else f"{k}: missing")
        for k, c in fields.items():
            if x.get(k) is not None:
                c(x[k], f"{at}.{k}" if at else k)
        if values is not None:
            for k, v in x.items():
                if v is not None:
                    values(v, f"{at}.{k}" if at else str(k))

    return check


def period(x: Any, at: str) -> None:
    """A period: its start and end times, the end not before the start."""
    obj({"start_utc": timestamp, "end_utc": timestamp})(x, at)
    start, end = x.get("start_utc"), x.get("end_utc")
    if start and end and pd.Timestamp(end) < pd.Timestamp(start):
        raise Invalid(f"{at}: ends ({end}) before it starts ({start})")


CHANNEL = obj(
    {
        "unit": text,
        "channel": one_of(CHANNELS),
        "n": count,
        "m_u": number,
        "m_y": number,
        "kurtosis": number,
        "limit_error": number,
    },
    required=("unit", "channel"),
)
MEASURES = obj(
    {
        "position": obj({"lat_deg": number, "lon_deg": number}),
        "rows": array(
            obj(
                {
                    "unit": text,
                    "quantity": text,
                    "measure_unit": text,
                    "value": number,
                    "sigma": number,
                    "dof": number,
                    "n": count,
                    "method": text,
                }
            )
        ),
    }
)
_NAMES = dict.fromkeys(("check", "kind", "name", "source", "subject", "role", "message"), text)
FINDING = obj(
    {
        **_NAMES,
        "window": obj({"start_utc": timestamp, "end_utc": timestamp}),
        "consequences": array(obj(_NAMES)),
    }
)
NOT_CHECKED = obj(dict.fromkeys(("check", "name", "source", "role", "why"), text))
DEAD_RECKONING = obj(
    {
        "containment_2m": number,
        "n_scored": count,
        "consistent": boolean,
        "verdict": text,
        "nees": number,
    }
)
CALIBRATION = obj(
    dict.fromkeys(
        ("compass_error_deg", "compass_error_sigma_deg", "log_scale", "log_scale_sigma"), number
    )
)
SOURCES = obj({}, values=text)

#: the fields of an audit document the fleet reads
DOCUMENT = obj(
    {
        "vessel": vessel_name,
        "night": night,
        "verdict": text,
        "status": text,
        "logs": obj({"lines": count, "rejected": count, "period": period}),
        "sources": SOURCES,
        "ins": array(CHANNEL),
        "dead_reckoning": DEAD_RECKONING,
        "calibration": CALIBRATION,
        "missing": array(text),
        "measures": MEASURES,
        "findings": array(FINDING),
        "not_checked": array(NOT_CHECKED),
        "integrity": obj(dict.fromkeys(COUNT_KEYS, count)),
        "analysis": obj(
            {"integrity": obj({"checks": array(obj({"status": text}))})},
        ),
    }
)

#: the fields of a night stored in an audit database the fleet reads
#: (:class:`dracc.pipeline.state.NightRecord`, its channels as objects)
RECORD = obj(
    {
        "vessel": vessel_name,
        "night": night,
        "period": period,
        "inputs": array(text),
        "sources": SOURCES,
        "lines": count,
        "rejected": count,
        "channels": array(CHANNEL),
        "dr": DEAD_RECKONING,
        "calibration": CALIBRATION,
        "missing": array(text),
        "measures": MEASURES,
        "findings": array(FINDING),
    }
)


def check_document(doc: Any) -> None:
    """Raise :class:`Invalid` unless every field of ``doc`` the fleet reads is of its
    type, size and range (the night is required)."""
    DOCUMENT(doc, "")
    if doc.get("night") is None:
        raise Invalid("night: missing (a night's document names its night)")
