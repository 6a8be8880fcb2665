"""The navigator's observations for ``dracc fix``: option texts and the TOML file.

Parsing at the edge, in the navigator's units: coordinates in degrees and
degrees-minutes (:func:`parse_coordinate_deg`), distances in metres, nautical miles or
cables (:func:`parse_distance_m`).  An option value (``--range '54 36.5N,...'``, see
:data:`OPTION_FORMS`) or a table of the observation file (``[[range]]``, see
:data:`TABLE_FORMS`) becomes a :class:`Pending` (named fields, not yet checked), then an
:class:`ObsSpec` (checked numbers in degrees and metres, its sigma, its label).  The
library observations (radians, metres) are built from these by :mod:`dracc.math.fix`.

Errors are one line naming the option (or file, table and key) and the value:
:class:`FixUsageError` (exit 2) for the command line, :class:`FixFileError` (exit 4) for
the file, :class:`IngestError` (exit 3) for a missing file.

Datums (seeds/004 §2): a charted item's positions referred to another datum (``--datum``,
the file's ``datum``, an item's ``datum``) are moved to WGS-84 by
:func:`referred_to_wgs84` (:mod:`dracc.ingest.datums`) before fusion.
"""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from dracc.core.errors import ConfigError, DraccError, FixFileError, FixUsageError, IngestError
from dracc.core.units import CABLE_M, NMI_M
from dracc.ingest.datums import Transformation, resolve_datum, to_wgs84

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

#: a priori sigmas used where the navigator gives none (docs/fix.md says why)
DEFAULT_FIX_SIGMA_M = 10.0
DEFAULT_BEARING_SIGMA_DEG = 1.0
DEFAULT_LINE_SIGMA_M = 5.0
DEFAULT_PIER_SIGMA_M = 1.0
DEFAULT_ABEAM_SIGMA_M = 2.0
DEFAULT_NADIR_SIGMA_DEG = 1.0 / 60.0
#: radar range, IMO MSC.192(79): 30 m or 1 % of the range scale (95 %), taken as 2 sigma
RADAR_RANGE_FLOOR_M = 30.0
RADAR_RANGE_FRACTION = 0.01


# --------------------------------------------------------------- coordinates, distances

_HEMI = {"N": ("lat", 1.0), "S": ("lat", -1.0), "E": ("lon", 1.0), "W": ("lon", -1.0)}
_NUM = r"\d+(?:\.\d*)?|\.\d+"
_ANGLE_RE = re.compile(rf"^([+-])?\s*({_NUM})(?:\s+({_NUM}))?(?:\s+({_NUM}))?$")


def parse_coordinate_deg(text: str, axis: str) -> float:
    """A latitude (``axis="lat"``) or longitude (``"lon"``) in signed decimal degrees.

    Accepted forms: decimal degrees with a sign (``54.6``, ``-18.8``), degrees and
    decimal minutes (``54 36.5N``, ``018 48.2E``, ``54°36.5'N``, ``N54°36.5'``), degrees,
    minutes and seconds (``54°36'30"N``), a hemisphere letter before or after (not with
    a sign).  Minutes and seconds are in [0, 60); |lat| <= 90, |lon| <= 180.
    Raises ``ValueError`` with the reason (the caller adds the option and value).
    """
    s = text.strip().upper()
    for ch in "°º˚":
        s = s.replace(ch, " ")
    for ch in "'′\"″":
        s = s.replace(ch, " ")
    hemi = None
    if s[-1:] in _HEMI:
        hemi, s = s[-1], s[:-1]
    elif s[:1] in _HEMI:
        hemi, s = s[0], s[1:]
    s = " ".join(s.split())
    m = _ANGLE_RE.match(s)
    if not m or not text.strip():
        raise ValueError("not a coordinate (forms: 54.6, -18.8, 54 36.5N, 018 48.2E, 54°36.5'N)")
    sign_txt, deg_txt, min_txt, sec_txt = m.groups()
    deg = float(deg_txt)
    minutes = float(min_txt) if min_txt else 0.0
    seconds = float(sec_txt) if sec_txt else 0.0
    if min_txt and "." in deg_txt:
        raise ValueError("degrees must be whole when minutes follow")
    if sec_txt and "." in min_txt:
        raise ValueError("minutes must be whole when seconds follow")
    if minutes >= 60.0 or seconds >= 60.0:
        raise ValueError("minutes and seconds must be below 60")
    sign = -1.0 if sign_txt == "-" else 1.0
    if hemi is not None:
        hemi_axis, hemi_sign = _HEMI[hemi]
        if hemi_axis != axis:
            raise ValueError(
                f"'{hemi}' is a {'longitude' if axis == 'lat' else 'latitude'} "
                f"hemisphere, expected {'N or S' if axis == 'lat' else 'E or W'}"
            )
        if sign_txt:
            raise ValueError("give a sign or a hemisphere letter, not both")
        sign = hemi_sign
    value = sign * (deg + minutes / 60.0 + seconds / 3600.0)
    limit = 90.0 if axis == "lat" else 180.0
    if abs(value) > limit:
        raise ValueError(f"outside ±{limit:g}°")
    return value


_DIST_RE = re.compile(rf"^({_NUM})\s*(M|KM|NM|NMI|CBL)?$")
_DIST_UNITS_M = {"M": 1.0, "KM": 1000.0, "NM": NMI_M, "NMI": NMI_M, "CBL": CABLE_M}


def parse_distance_m(text: str, *, unit_required: bool) -> float:
    """A distance in metres from ``2.4nmi``, ``2.4nm``, ``4cbl``, ``450m``, ``1.2km``.

    A bare number is metres when ``unit_required`` is False.  1 nmi = 1852 m,
    1 cable = 185.2 m (exact).  Raises ``ValueError`` with the reason.
    """
    m = _DIST_RE.match(text.strip().upper())
    if not m:
        raise ValueError("not a distance (forms: 2.4nmi, 2.4nm, 4cbl, 450m, 1.2km)")
    if m.group(2) is None and unit_required:
        raise ValueError("give a unit: m, km, nmi (or nm) or cbl, e.g. 2.4nmi")
    return float(m.group(1)) * _DIST_UNITS_M[m.group(2) or "M"]


def _number(text: str) -> float:
    value = float(text)  # ValueError for non-numbers
    if not math.isfinite(value):
        raise ValueError("not a finite number")
    return value


# ------------------------------------------------------------------------ field reading


@dataclass(frozen=True)
class Pending:
    """Fields parsed from an option or a TOML table, before the observation is built."""

    kind: str
    source: str
    fields: dict[str, Any]
    datum: str | None = None  #: the datum its positions are referred to (None: WGS-84)

    @property
    def text(self) -> str | None:
        """The option's value as given (its fields re-joined); None for a file's table."""
        if not self.source.startswith("--"):
            return None
        return ",".join(str(v) for v in self.fields.values())


class _Reader:
    """Field access with one-line errors naming the option (or table) and the value."""

    def __init__(self, where: str, value: str | None, exc_type: type[DraccError]):
        self.where, self.value, self.exc_type = where, value, exc_type

    def fail(self, reason: str) -> DraccError:
        if self.value is None:  # a file: name the table and key, not a re-joined value
            for field_name, key in (("BRG_DEG", "bearing_deg"), ("DIST", "dist")):
                reason = reason.replace(field_name, key)
            reason = re.sub(
                r"\b[A-Z][A-Z0-9_]*[A-Z0-9]\b(?= )", lambda m: m.group(0).lower(), reason
            )
            return self.exc_type(f"{self.where}: {reason}")
        return self.exc_type(f"{self.where} {self.value!r}: {reason}")

    def coord(self, raw: Any, axis: str, name: str) -> float:
        if isinstance(raw, (int, float)) and not isinstance(raw, bool):
            text = repr(float(raw))
        elif isinstance(raw, str):
            text = raw
        else:
            raise self.fail(f"{name} must be a number or a text like '54 36.5N', got {raw!r}")
        try:
            return parse_coordinate_deg(text, axis)
        except ValueError as e:
            raise self.fail(f"{name} {text!r}: {e}") from None

    def num(self, raw: Any, name: str, *, positive: bool = False, nonneg: bool = False) -> float:
        try:
            if isinstance(raw, bool):
                raise ValueError
            value = _number(raw) if isinstance(raw, str) else float(raw)
            if not math.isfinite(value):
                raise ValueError
        except (TypeError, ValueError):
            raise self.fail(f"{name} {raw!r} is not a number") from None
        if positive and not value > 0:
            raise self.fail(f"{name} must be > 0, got {raw!r}")
        if nonneg and value < 0:
            raise self.fail(f"{name} must be >= 0, got {raw!r}")
        return value

    def dist(self, raw: Any, name: str, *, unit_required: bool, positive: bool = False) -> float:
        if isinstance(raw, (int, float)) and not isinstance(raw, bool):
            raw = repr(float(raw)) + ("" if unit_required else "m")
        if not isinstance(raw, str):
            raise self.fail(f"{name} must be a text like '2.4nmi', got {raw!r}")
        try:
            value = parse_distance_m(raw, unit_required=unit_required)
        except ValueError as e:
            raise self.fail(f"{name} {raw!r}: {e}") from None
        if positive and not value > 0:
            raise self.fail(f"{name} must be > 0, got {raw!r}")
        return value


# ------------------------------------------------------------- options and the TOML file

#: a free-gyro observation (seeds/002 (1)): the spin-axis unit vector in the inertial frame,
#: the time (s; the inertial x axis is at Greenwich at 0), the nadir angle, and the sigmas of
#: the nadir angle, of the gyro vector's direction (per axis) and of the clock
_GYRO_REQUIRED = ("ux", "uy", "uz", "time_s", "nadir_deg")
_GYRO_OPTIONAL = ("sigma_deg", "sigma_u_deg", "sigma_t_s")
#: |u| may differ from 1 by this much (rounding of the given components)
GYRO_UNIT_TOLERANCE = 1e-6

#: option name -> (kind, required field names, optional field names)
OPTION_FORMS = {
    "--fix": ("fix", ("lat", "lon"), ("sigma_m",)),
    "--range": ("range", ("lat", "lon", "dist"), ("sigma",)),
    "--bearing": ("bearing", ("lat", "lon", "bearing_deg"), ("sigma_deg",)),
    "--bearing-from-mark": ("bearing_from_mark", ("lat", "lon", "bearing_deg"), ("sigma_deg",)),
    "--line": ("line", ("lat1", "lon1", "lat2", "lon2"), ("sigma_m", "offset_m")),
    "--pier": (
        "pier",
        ("lat1", "lon1", "lat2", "lon2", "heading_deg", "side", "half_breadth_m"),
        ("sigma_m", "gap_m", "ref_stbd_m"),
    ),
    "--abeam": ("abeam", ("lat", "lon"), ("sigma_m",)),
    "--nadir": ("nadir", ("sublat", "sublon", "nadir_deg"), ("sigma_deg",)),
    "--gyro-vector": ("gyro_vector", _GYRO_REQUIRED, _GYRO_OPTIONAL),
}

#: TOML table name -> (kind, required keys, optional keys); alternatives "a|b" (one of)
TABLE_FORMS = {
    "fix": ("fix", ("lat", "lon"), ("sigma_m",)),
    "range": ("range", ("lat", "lon", "dist_m|dist_nmi|dist"), ("sigma_m|sigma",)),
    "bearing": ("bearing", ("lat", "lon", "bearing_deg"), ("sigma_deg", "observed_at")),
    "line": ("line", ("lat1", "lon1", "lat2", "lon2"), ("sigma_m", "offset_m")),
    "pier": (
        "pier",
        ("lat1", "lon1", "lat2", "lon2", "heading_deg", "side", "half_breadth_m"),
        ("sigma_m", "gap_m", "ref_stbd_m"),
    ),
    "abeam": ("abeam", ("lat", "lon"), ("sigma_m",)),
    "nadir": ("nadir", ("sublat", "sublon", "nadir_deg"), ("sigma_deg",)),
    "gyro_vector": ("gyro_vector", _GYRO_REQUIRED, _GYRO_OPTIONAL),
}


def parse_option(option: str, value: str) -> Pending:
    """``--range '54 36.5N,018 48.2E,2.4nmi'`` -> the named text fields (exit 2 on errors)."""
    kind, required, optional = OPTION_FORMS[option]
    parts = [p.strip() for p in value.split(",")]
    names = required + optional
    if not (len(required) <= len(parts) <= len(names)) or any(p == "" for p in parts):
        form = ",".join(n.upper() for n in required) + "".join(f"[,{n.upper()}" for n in optional)
        form += "]" * len(optional)
        raise FixUsageError(f"{option} {value!r}: expected {form} ({len(parts)} field(s) given)")
    return Pending(kind, option, dict(zip(names, parts, strict=False)))


def _toml_pending(path: Path, table: str, index: int, entry: Any) -> Pending:
    kind, required, optional = TABLE_FORMS[table]
    where = f"{path}: [[{table}]] #{index}"
    if not isinstance(entry, dict):
        raise FixFileError(f"{where}: expected a table ([[{table}]] with keys), got {entry!r}")
    entry = dict(entry)
    datum = entry.pop("datum", None)
    if datum is not None:
        if kind not in DATUM_KINDS:
            raise FixFileError(f"{where}: datum applies to charted positions, not to [[{table}]]")
        datum = checked_datum(f"{where}: datum", datum, FixFileError)
    allowed = {k for spec in required + optional for k in spec.split("|")}
    for key in entry:
        if key not in allowed:
            raise FixFileError(f"{where}: unknown key {key!r} (keys: {', '.join(sorted(allowed))})")
    fields: dict[str, Any] = {}
    for spec in required + optional:
        present = [k for k in spec.split("|") if k in entry]
        if len(present) > 1:
            raise FixFileError(f"{where}: give one of {', '.join(present)}, not several")
        if not present:
            if spec in required:
                raise FixFileError(f"{where}: missing key {spec.replace('|', ' or ')!r}")
            continue
        key = present[0]
        fields[key] = entry[key]
    if kind == "bearing" and fields.pop("observed_at", "ship") == "mark":
        kind = "bearing_from_mark"
    elif kind == "bearing" and entry.get("observed_at", "ship") != "ship":
        raise FixFileError(
            f"{where}: observed_at must be 'ship' or 'mark', got {entry['observed_at']!r}"
        )
    return Pending(kind, where, fields, datum)


def load_obs_toml(path: Path) -> dict[str, Any]:
    """An observation file's TOML tables (data only, never executed): exit 3 for a missing
    file (IngestError), 4 for one that is not a file or not TOML (FixFileError)."""
    if not path.exists():
        raise IngestError(f"{path}: no such file")
    if not path.is_file():
        raise FixFileError(f"{path}: not a file")
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as e:
        raise FixFileError(f"{path}: not valid TOML ({e})") from e
    except (OSError, UnicodeDecodeError) as e:
        raise FixFileError(f"{path}: cannot read ({e})") from e


def read_obs_file(path: Path) -> tuple[list[Pending], dict[str, Any] | None]:
    """Observations and an optional ``[prior]`` from a TOML file (data only, never executed)."""
    data = load_obs_toml(path)
    pending: list[Pending] = []
    prior = None
    file_datum = None
    for key, value in data.items():
        if key == "prior":
            if not isinstance(value, dict) or set(value) != {"lat", "lon"}:
                raise FixFileError(f"{path}: [prior] must hold exactly lat and lon, got {value!r}")
            prior = value
            continue
        if key == "datum":  # the file's datum: for every charted item without its own
            file_datum = checked_datum(f"{path}: datum", value, FixFileError)
            continue
        if key not in TABLE_FORMS:
            raise FixFileError(
                f"{path}: unknown table {key!r} (tables: prior, {', '.join(TABLE_FORMS)}; "
                "key: datum)"
            )
        entries = value if isinstance(value, list) else [value]
        for i, entry in enumerate(entries, start=1):
            pending.append(_toml_pending(path, key, i, entry))
    if file_datum is not None:
        pending = [
            replace(p, datum=file_datum) if p.datum is None and p.kind in DATUM_KINDS else p
            for p in pending
        ]
    return pending, prior


# ------------------------------------------------------------------------------ datums

#: the kinds whose positions are charted (or plotted) and so referred to a datum; a
#: nadir circle's sub-point is astronomical (seeds/002), not charted
DATUM_KINDS = ("fix", "range", "bearing", "bearing_from_mark", "line", "pier", "abeam")


def checked_datum(where: str, value: Any, exc_type: type[DraccError]) -> str:
    """A datum name or EPSG code, checked (:func:`dracc.ingest.datums.resolve_datum`)."""
    if not isinstance(value, str):
        raise exc_type(f"{where} must be a text such as 'ED50' or 'EPSG:4230', got {value!r}")
    try:
        resolve_datum(value)
    except ConfigError as e:
        raise exc_type(f"{where}: {e}") from None
    return value.strip()


@dataclass(frozen=True)
class DatumRecord:
    """How one observation's positions were brought to WGS-84 (seeds/004 §2).

    ``points_given_deg``: as the navigator gave them (on ``transformation.datum``);
    ``points_wgs84_deg``: as fused; ``shift_m``: each point's shift (geodesic metres).
    """

    label: str
    points_given_deg: tuple[tuple[float, float], ...]
    points_wgs84_deg: tuple[tuple[float, float], ...]
    shift_m: tuple[float, ...]
    transformation: Transformation


def referred_to_wgs84(spec: ObsSpec, datum: str) -> ObsSpec:
    """``spec`` with its charted points on WGS-84 and the :class:`DatumRecord`.

    Only positions move: ranges, bearings, offsets and pier distances stay as measured.
    WGS-84 itself leaves ``spec`` as it is (no record).
    """
    if resolve_datum(datum) == "EPSG:4326":
        return spec
    exc = FixUsageError if spec.source.startswith("--") else FixFileError
    lats = [p[0] for p in spec.points_deg]
    lons = [p[1] for p in spec.points_deg]
    try:
        pos = to_wgs84(lats, lons, datum)
    except ConfigError as e:
        raise _Reader(spec.source, spec.text, exc).fail(str(e)) from None
    points = tuple(zip(pos.lat_deg.tolist(), pos.lon_deg.tolist(), strict=True))
    record = DatumRecord(
        spec.label, spec.points_deg, points, tuple(pos.shift_m.tolist()), pos.transformation
    )
    return replace(spec, points_deg=points, datum=record)


def parse_prior(
    text: str | None, file_prior: dict[str, Any] | None, file: Path | None
) -> tuple[float, float] | None:
    """The linearisation point (degrees): ``--prior LAT,LON`` wins over the file's ``[prior]``."""
    if text is not None:
        parts = [p.strip() for p in text.split(",")]
        if len(parts) != 2:
            raise FixUsageError(f"--prior {text!r}: expected LAT,LON")
        r = _Reader("--prior", text, FixUsageError)
        return r.coord(parts[0], "lat", "LAT"), r.coord(parts[1], "lon", "LON")
    if file_prior is not None:
        r = _Reader(f"{file}: [prior]", None, FixFileError)
        return r.coord(file_prior["lat"], "lat", "lat"), r.coord(file_prior["lon"], "lon", "lon")
    return None


# -------------------------------------------------------------------- checked observations


@dataclass(frozen=True)
class ObsSpec:
    """One observation as the navigator gave it, checked, in degrees and metres.

    ``kind``: fix, range, bearing, bearing_from_mark, line, pier, abeam, nadir or gyro_vector;
    ``text``: the option's value (for messages; None from the file); ``unit``: ``"m"`` or
    ``"deg"``, the unit its residual is shown in; ``sigma``: its standard deviation in
    that unit; ``sigma_default``: True when no sigma was given; ``points_deg``: the
    charted points it names (the mark, the line's or pier's ends A and B, the nadir
    circle's sub-point).  ``values`` by kind: range ``dist_m``; bearings
    ``bearing_deg``; line ``offset_m``; pier ``heading_deg``, ``half_breadth_m``,
    ``gap_m``, ``ref_stbd_m`` (and ``side``); nadir ``nadir_deg``; gyro_vector (no point)
    ``ux``, ``uy``, ``uz``, ``time_s``, ``nadir_deg``, ``sigma_u_deg``, ``sigma_t_s``.
    """

    kind: str
    label: str
    source: str
    text: str | None
    unit: str
    sigma: float
    sigma_default: bool
    points_deg: tuple[tuple[float, float], ...]
    values: dict[str, float] = field(default_factory=dict)
    side: str | None = None
    datum: DatumRecord | None = None  #: set when its points were moved to WGS-84


def build_observation(p: Pending, label: str, n_piers: int) -> ObsSpec:
    """The checked observation from parsed fields (``n_piers`` pier lines come before it)."""
    exc = FixUsageError if p.source.startswith("--") else FixFileError
    r = _Reader(p.source, p.text, exc)
    f = p.fields

    def spec(
        unit: str,
        sigma: float,
        given: bool,
        points: tuple[tuple[float, float], ...],
        **values: float,
    ) -> ObsSpec:
        return ObsSpec(p.kind, label, p.source, p.text, unit, sigma, not given, points, values)

    if p.kind == "fix":
        lat, lon = r.coord(f["lat"], "lat", "LAT"), r.coord(f["lon"], "lon", "LON")
        given = "sigma_m" in f
        sigma = r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_FIX_SIGMA_M
        return spec("m", sigma, given, ((lat, lon),))
    if p.kind == "range":
        lat, lon = r.coord(f["lat"], "lat", "LAT"), r.coord(f["lon"], "lon", "LON")
        if "dist_m" in f:
            dist = r.num(f["dist_m"], "dist_m", nonneg=True)
        elif "dist_nmi" in f:
            dist = r.num(f["dist_nmi"], "dist_nmi", nonneg=True) * NMI_M
        else:
            dist = r.dist(f["dist"], "DIST", unit_required=True)
        skey = "sigma_m" if "sigma_m" in f else "sigma"
        given = skey in f
        if not given:  # (95 % bound) / 2, IMO radar range accuracy
            sigma = max(RADAR_RANGE_FLOOR_M, RADAR_RANGE_FRACTION * dist) / 2.0
        elif skey == "sigma_m":
            sigma = r.num(f[skey], "sigma_m", positive=True)
        else:
            sigma = r.dist(f[skey], "SIGMA", unit_required=False, positive=True)
        return spec("m", sigma, given, ((lat, lon),), dist_m=dist)
    if p.kind in ("bearing", "bearing_from_mark"):
        lat, lon = r.coord(f["lat"], "lat", "LAT"), r.coord(f["lon"], "lon", "LON")
        brg = r.num(f["bearing_deg"], "BRG_DEG")
        if not 0.0 <= brg <= 360.0:
            raise r.fail(f"BRG_DEG must be in [0, 360], got {f['bearing_deg']!r}")
        given = "sigma_deg" in f
        sigma = (
            r.num(f["sigma_deg"], "SIGMA_DEG", positive=True)
            if given
            else DEFAULT_BEARING_SIGMA_DEG
        )
        return spec("deg", sigma, given, ((lat, lon),), bearing_deg=brg)
    if p.kind == "line":
        pts = _two_points(r, f)
        given = "sigma_m" in f
        sigma = r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_LINE_SIGMA_M
        offset = r.num(f["offset_m"], "OFFSET_M") if "offset_m" in f else 0.0
        return spec("m", sigma, given, pts, offset_m=offset)
    if p.kind == "pier":
        pts = _two_points(r, f)
        heading = r.num(f["heading_deg"], "HEADING_DEG")
        if not 0.0 <= heading <= 360.0:
            raise r.fail(f"HEADING_DEG must be in [0, 360], got {f['heading_deg']!r}")
        side = str(f["side"]).strip().lower()
        if side not in ("port", "starboard"):
            raise r.fail(f"side must be port or starboard, got {f['side']!r}")
        half = r.num(f["half_breadth_m"], "HALF_BREADTH_M", positive=True)
        given = "sigma_m" in f
        sigma = r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_PIER_SIGMA_M
        gap = r.num(f["gap_m"], "GAP_M", nonneg=True) if "gap_m" in f else 0.0
        ref = r.num(f["ref_stbd_m"], "REF_STBD_M") if "ref_stbd_m" in f else 0.0
        values = {"heading_deg": heading, "half_breadth_m": half, "gap_m": gap, "ref_stbd_m": ref}
        return ObsSpec(
            p.kind, label, p.source, p.text, "m", sigma, not given, pts, values, side=side
        )
    if p.kind == "abeam":
        lat, lon = r.coord(f["lat"], "lat", "LAT"), r.coord(f["lon"], "lon", "LON")
        if n_piers != 1:
            raise r.fail(
                f"an abeam mark needs exactly one pier line (--pier or [[pier]]), {n_piers} given"
            )
        given = "sigma_m" in f
        sigma = r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_ABEAM_SIGMA_M
        return spec("m", sigma, given, ((lat, lon),))
    if p.kind == "nadir":
        lat, lon = r.coord(f["sublat"], "lat", "SUBLAT"), r.coord(f["sublon"], "lon", "SUBLON")
        nadir = r.num(f["nadir_deg"], "NADIR_DEG")
        if not 0.0 < nadir < 180.0:
            raise r.fail(f"NADIR_DEG must be in (0, 180), got {f['nadir_deg']!r}")
        given = "sigma_deg" in f
        sigma = (
            r.num(f["sigma_deg"], "SIGMA_DEG", positive=True) if given else DEFAULT_NADIR_SIGMA_DEG
        )
        return spec("deg", sigma, given, ((lat, lon),), nadir_deg=nadir)
    if p.kind == "gyro_vector":
        return _gyro_vector(r, f, spec)
    raise AssertionError(p.kind)  # pragma: no cover - kinds come from OPTION_FORMS/TABLE_FORMS


def _gyro_vector(r: _Reader, f: dict[str, Any], spec: Callable[..., ObsSpec]) -> ObsSpec:
    """A gyro-vector observation: ``values`` ux, uy, uz, time_s, nadir_deg, sigma_u_deg,
    sigma_t_s (0 when not given); no charted point (the sub-point comes from u and t)."""
    u = [r.num(f[k], k.upper()) for k in ("ux", "uy", "uz")]
    norm = math.sqrt(sum(c * c for c in u))
    if abs(norm - 1.0) > GYRO_UNIT_TOLERANCE:
        raise r.fail(f"the gyro vector UX,UY,UZ must be a unit vector, |u| = {norm:.7f}")
    time_s = r.num(f["time_s"], "TIME_S")
    nadir = r.num(f["nadir_deg"], "NADIR_DEG")
    if not 0.0 < nadir < 180.0:
        raise r.fail(f"NADIR_DEG must be in (0, 180), got {f['nadir_deg']!r}")
    given = "sigma_deg" in f
    sigma = r.num(f["sigma_deg"], "SIGMA_DEG", positive=True) if given else DEFAULT_NADIR_SIGMA_DEG
    sigma_u = r.num(f["sigma_u_deg"], "SIGMA_U_DEG", nonneg=True) if "sigma_u_deg" in f else 0.0
    sigma_t = r.num(f["sigma_t_s"], "SIGMA_T_S", nonneg=True) if "sigma_t_s" in f else 0.0
    values = dict(zip(("ux", "uy", "uz"), u, strict=True))
    values |= {"time_s": time_s, "nadir_deg": nadir, "sigma_u_deg": sigma_u, "sigma_t_s": sigma_t}
    return spec("deg", sigma, given, (), **values)


def _two_points(r: _Reader, f: dict[str, Any]) -> tuple[tuple[float, float], tuple[float, float]]:
    return (
        (r.coord(f["lat1"], "lat", "LAT1"), r.coord(f["lon1"], "lon", "LON1")),
        (r.coord(f["lat2"], "lat", "LAT2"), r.coord(f["lon2"], "lon", "LON2")),
    )


#: the solving order of the kinds; labels count within a kind
KIND_ORDER = (
    "fix",
    "range",
    "bearing",
    "bearing_from_mark",
    "line",
    "pier",
    "abeam",
    "nadir",
    "gyro_vector",
)
_LABEL = {"bearing_from_mark": "bearing at mark", "gyro_vector": "gyro vector"}


def iter_observations(pending: Sequence[Pending]) -> Iterator[ObsSpec]:
    """The checked observations in :data:`KIND_ORDER`, labelled (``range 2``).

    Lazy: each is checked when the consumer asks for it, so that the first error in
    solving order is the one reported, whether a field or the geometry of the library
    object built from the ones before (:func:`dracc.math.fix.fix_observations`).
    """
    counts: dict[str, int] = {}
    n_piers = 0
    for kind in KIND_ORDER:
        for p in (q for q in pending if q.kind == kind):
            counts[kind] = counts.get(kind, 0) + 1
            spec = build_observation(p, f"{_LABEL.get(kind, kind)} {counts[kind]}", n_piers)
            yield referred_to_wgs84(spec, p.datum) if p.datum is not None else spec
            n_piers += kind == "pier"


def read_observations(
    options: Sequence[tuple[str, Sequence[str]]],
    file: Path | None,
    prior: str | None,
    datum: str | None = None,
) -> tuple[Iterator[ObsSpec], tuple[float, float] | None]:
    """Everything ``dracc fix`` was given: the observations (lazy, in solving order) and
    the prior (degrees, or None).  ``options``: (option name, its values) pairs;
    ``datum``: the datum of the options' charted positions (``--datum``; the file names
    its own)."""
    pending = [parse_option(option, v) for option, values in options for v in values]
    if datum is not None:
        datum = checked_datum("--datum", datum, FixUsageError)
        pending = [replace(p, datum=datum) if p.kind in DATUM_KINDS else p for p in pending]
    file_prior = None
    if file is not None:
        more, file_prior = read_obs_file(file)
        pending += more
    return iter_observations(pending), parse_prior(prior, file_prior, file)


__all__ = [
    "DATUM_KINDS",
    "KIND_ORDER",
    "OPTION_FORMS",
    "TABLE_FORMS",
    "DatumRecord",
    "ObsSpec",
    "Pending",
    "build_observation",
    "checked_datum",
    "iter_observations",
    "parse_coordinate_deg",
    "parse_distance_m",
    "parse_option",
    "parse_prior",
    "read_obs_file",
    "read_observations",
    "referred_to_wgs84",
]
