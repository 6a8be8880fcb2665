"""``dracc fix``: fuse position fixes and lines of position at the chart table.

A thin layer over :mod:`dracc.math.fusion` (LS (W1) / WLS (W3, W4), seeds/004; DOP in the
trace form, METHODS §5).  This module parses the navigator's units (degrees and
degrees-minutes, metres, nautical miles, cables) at the edge, builds the library's
observations in radians and metres, picks the linearisation point, and renders the
solution as a table or as JSON (schema ``dracc.fix/1``, documented in docs/fix.md).

Exit codes: 0 a fix; 2 a bad option value (the message names the option and the
value); 3 the geometry cannot give a (unique) fix, or the observation file is missing;
4 the observation file (TOML) is invalid (the message names the file, table and key).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import typer
from rich.table import Table

from dracc.cli.app import app, out
from dracc.core.distributions import chi2_ppf
from dracc.core.errors import (
    FixFileError,
    FixUsageError,
    GeometryError,
    IngestError,
)
from dracc.core.geodesy import (
    add_offset_ne,
    circmean,
    distance_m,
    radius_meridian_m,
    radius_prime_vertical_m,
    wrap_pi,
)
from dracc.core.numbers import finite_or_none as _finite
from dracc.core.units import CABLE_M, NMI_M
from dracc.math.fusion import (
    BearingLOP,
    FixSolution,
    LineLOP,
    NadirCircle,
    Observation,
    PierLine,
    PositionFix,
    RangeLOP,
    abeam_line,
    fuse_fix,
    stack_rows,
    to_metres,
)

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib  # type: ignore[no-redef]

SCHEMA = "dracc.fix/1"

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


# --------------------------------------------------------------------- the edge: parsing

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


# ------------------------------------------------------------------- observations


@dataclass(frozen=True)
class ObsSpec:
    """One observation as the navigator gave it, and the library object built from it.

    ``unit``: ``"m"`` or ``"deg"``, the unit its residual is shown in; ``sigma``: its
    standard deviation in that unit; ``sigma_default``: True when no sigma was given;
    ``points_deg``: the charted points it names (for the default prior); ``scale_m``: a
    characteristic distance (range, or the circle's radius) for the search for other
    solutions; ``circle``: True for ranges and nadir circles (two can cross twice).
    """

    label: str
    source: str
    obs: Observation
    unit: str
    sigma: float
    sigma_default: bool
    points_deg: tuple[tuple[float, float], ...]
    scale_m: float | None = None
    circle: bool = False
    is_fix: bool = False


@dataclass(frozen=True)
class Pending:
    """Fields parsed from an option or a TOML table, before the observation is built."""

    kind: str
    source: str
    fields: dict


def _fields_error(where: str, exc_type: type, value: str, reason: str):
    return exc_type(f"{where} {value!r}: {reason}")


class _Reader:
    """Field access with one-line errors naming the option (or table) and the value."""

    def __init__(self, where: str, value: str | None, exc_type: type):
        self.where, self.value, self.exc_type = where, value, exc_type

    def fail(self, reason: str):
        if self.value is None:  # a file: name the table and key, not a re-joined value
            for field, key in (("BRG_DEG", "bearing_deg"), ("DIST", "dist")):
                reason = reason.replace(field, key)
            reason = re.sub(
                r"\b[A-Z][A-Z0-9_]*[A-Z0-9]\b(?= )", lambda m: m.group(0).lower(), reason
            )
            return self.exc_type(f"{self.where}: {reason}")
        return _fields_error(self.where, self.exc_type, self.value, reason)

    def coord(self, raw, axis: str, name: str) -> float:
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

    def num(self, raw, name: str, *, positive: bool = False, nonneg: bool = False) -> float:
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

    def dist(self, raw, name: str, *, unit_required: bool, positive: bool = False) -> float:
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


def _toml_pending(path: Path, table: str, index: int, entry) -> Pending:
    kind, required, optional = TABLE_FORMS[table]
    where = f"{path}: [[{table}]] #{index}"
    if not isinstance(entry, dict):
        raise FixFileError(f"{where}: expected a table ([[{table}]] with keys), got {entry!r}")
    allowed = {k for spec in required + optional for k in spec.split("|")}
    for key in entry:
        if key not in allowed:
            raise FixFileError(f"{where}: unknown key {key!r} (keys: {', '.join(sorted(allowed))})")
    fields: dict = {}
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
    return Pending(kind, where, fields)


def read_obs_file(path: Path) -> tuple[list[Pending], dict | None]:
    """Observations and an optional ``[prior]`` from a TOML file (data only, never executed)."""
    if not path.exists():
        raise IngestError(f"{path}: no such file")
    if not path.is_file():
        raise FixFileError(f"{path}: not a file")
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as e:
        raise FixFileError(f"{path}: not valid TOML ({e})") from e
    except (OSError, UnicodeDecodeError) as e:
        raise FixFileError(f"{path}: cannot read ({e})") from e
    pending: list[Pending] = []
    prior = None
    for key, value in data.items():
        if key == "prior":
            if not isinstance(value, dict) or set(value) != {"lat", "lon"}:
                raise FixFileError(f"{path}: [prior] must hold exactly lat and lon, got {value!r}")
            prior = value
            continue
        if key not in TABLE_FORMS:
            raise FixFileError(
                f"{path}: unknown table {key!r} (tables: prior, {', '.join(TABLE_FORMS)})"
            )
        entries = value if isinstance(value, list) else [value]
        for i, entry in enumerate(entries, start=1):
            pending.append(_toml_pending(path, key, i, entry))
    return pending, prior


def _rad(deg: float) -> float:
    return math.radians(deg)


def build_observation(p: Pending, label: str, piers: Sequence[ObsSpec]) -> ObsSpec:
    """The library observation (radians, metres) from parsed fields; one-line errors."""
    exc = FixUsageError if p.source.startswith("--") else FixFileError
    value = ",".join(str(v) for v in p.fields.values()) if exc is FixUsageError else None
    r = _Reader(p.source, value, exc)
    f = p.fields
    try:
        if p.kind == "fix":
            lat, lon = r.coord(f["lat"], "lat", "LAT"), r.coord(f["lon"], "lon", "LON")
            given = "sigma_m" in f
            sigma = r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_FIX_SIGMA_M
            obs = PositionFix.from_sigma(_rad(lat), _rad(lon), sigma)
            return ObsSpec(label, p.source, obs, "m", sigma, not given, ((lat, lon),), is_fix=True)
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
            obs = RangeLOP(_rad(lat), _rad(lon), dist, sigma)
            return ObsSpec(
                label,
                p.source,
                obs,
                "m",
                sigma,
                not given,
                ((lat, lon),),
                scale_m=dist,
                circle=True,
            )
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
            at = "mark" if p.kind == "bearing_from_mark" else "ship"
            obs = BearingLOP(
                _rad(lat), _rad(lon), _rad(brg) % (2 * math.pi), _rad(sigma), observed_at=at
            )
            return ObsSpec(label, p.source, obs, "deg", sigma, not given, ((lat, lon),))
        if p.kind == "line":
            pts = _two_points(r, f)
            given = "sigma_m" in f
            sigma = r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_LINE_SIGMA_M
            offset = r.num(f["offset_m"], "OFFSET_M") if "offset_m" in f else 0.0
            obs = LineLOP(*(_rad(v) for v in (*pts[0], *pts[1])), sigma, offset)
            return ObsSpec(label, p.source, obs, "m", sigma, not given, pts)
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
            obs = PierLine(
                *(_rad(v) for v in (*pts[0], *pts[1])),
                _rad(heading) % (2 * math.pi),
                side,
                half,
                sigma,
                ref_transverse_m=ref,
                gap_m=gap,
            )  # type: ignore[arg-type]
            return ObsSpec(label, p.source, obs, "m", sigma, not given, pts)
        if p.kind == "abeam":
            lat, lon = r.coord(f["lat"], "lat", "LAT"), r.coord(f["lon"], "lon", "LON")
            if len(piers) != 1:
                raise r.fail(
                    f"an abeam mark needs exactly one pier line (--pier or [[pier]]), "
                    f"{len(piers)} given"
                )
            given = "sigma_m" in f
            sigma = (
                r.num(f["sigma_m"], "SIGMA_M", positive=True) if given else DEFAULT_ABEAM_SIGMA_M
            )
            obs = abeam_line(piers[0].obs, _rad(lat), _rad(lon), sigma)  # type: ignore[arg-type]
            return ObsSpec(label, p.source, obs, "m", sigma, not given, ((lat, lon),))
        if p.kind == "nadir":
            lat, lon = r.coord(f["sublat"], "lat", "SUBLAT"), r.coord(f["sublon"], "lon", "SUBLON")
            nadir = r.num(f["nadir_deg"], "NADIR_DEG")
            if not 0.0 < nadir < 180.0:
                raise r.fail(f"NADIR_DEG must be in (0, 180), got {f['nadir_deg']!r}")
            given = "sigma_deg" in f
            sigma = (
                r.num(f["sigma_deg"], "SIGMA_DEG", positive=True)
                if given
                else DEFAULT_NADIR_SIGMA_DEG
            )
            obs = NadirCircle(_rad(lat), _rad(lon), _rad(nadir), _rad(sigma))
            r_m = float(np.sqrt(radius_meridian_m(_rad(lat)) * radius_prime_vertical_m(_rad(lat))))
            r_m *= _rad(nadir)  # the circle's radius on the Gaussian sphere, for the search
            return ObsSpec(
                label,
                p.source,
                obs,
                "deg",
                sigma,
                not given,
                ((lat, lon),),
                scale_m=r_m,
                circle=True,
            )
    except (
        GeometryError
    ) as e:  # the library refuses the observation itself (e.g. a pier misaligned)
        raise GeometryError(f"{p.source} {value!r}: {e}" if value else f"{p.source}: {e}") from None
    raise AssertionError(p.kind)  # pragma: no cover - kinds come from OPTION_FORMS/TABLE_FORMS


def _two_points(r: _Reader, f: dict) -> tuple[tuple[float, float], tuple[float, float]]:
    return (
        (r.coord(f["lat1"], "lat", "LAT1"), r.coord(f["lon1"], "lon", "LON1")),
        (r.coord(f["lat2"], "lat", "LAT2"), r.coord(f["lon2"], "lon", "LON2")),
    )


_ORDER = ("fix", "range", "bearing", "bearing_from_mark", "line", "pier", "abeam", "nadir")
_LABEL = {"bearing_from_mark": "bearing at mark"}


def build_observations(pending: Sequence[Pending]) -> list[ObsSpec]:
    """All observations in a fixed kind order (fixes, ranges, ... nadir circles), labelled."""
    specs: list[ObsSpec] = []
    counts: dict[str, int] = {}
    for kind in _ORDER:
        for p in (q for q in pending if q.kind == kind):
            counts[kind] = counts.get(kind, 0) + 1
            piers = [s for s in specs if isinstance(s.obs, PierLine)]
            specs.append(build_observation(p, f"{_LABEL.get(kind, kind)} {counts[kind]}", piers))
    return specs


# ------------------------------------------------------------------- the solution


def standardised_residuals(psi, r_m2, z, weighted: bool) -> np.ndarray:
    """Baarda's w statistic of each row: ``w_i = v_i / sqrt(C_v,ii)`` (NaN where C_v,ii ~ 0).

    Rows in metres (``Psi`` (k, 2) unit rows, ``R`` (k, k), post-fit residuals ``v``).
    ``H = Psi (Psi^T W Psi)^-1 Psi^T W`` with ``W = R^-1`` (WLS, W4) or ``I`` (LS, W1);
    ``v = (I - H) z`` so ``C_v = (I - H) R (I - H)^T`` (for WLS: ``R - Psi P Psi^T``).
    Under the sigmas each w is N(0, 1); the largest |w| names the likeliest blunder.
    """
    psi = np.asarray(psi, float)
    r_m2 = np.asarray(r_m2, float)
    w_mat = np.linalg.inv(r_m2) if weighted else np.eye(len(z))
    h = psi @ np.linalg.solve(psi.T @ w_mat @ psi, psi.T @ w_mat)
    i_h = np.eye(len(z)) - h
    c_v = i_h @ r_m2 @ i_h.T
    var = np.diag(c_v)
    tiny = 1e-9 * np.diag(r_m2)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(var > tiny, np.asarray(z, float) / np.sqrt(np.maximum(var, tiny)), np.nan)


@dataclass(frozen=True)
class ResidualRow:
    """One measurement row after the fit: residual (measured - fitted) in its own unit."""

    label: str
    row: str
    unit: str
    residual: float
    residual_m: float
    sigma: float
    sigma_default: bool
    normalised: float
    w: float


@dataclass(frozen=True)
class FixReport:
    """A fused fix with everything the table and the JSON show."""

    solution: FixSolution
    specs: tuple[ObsSpec, ...]
    residuals: tuple[ResidualRow, ...]
    prior_lat_deg: float
    prior_lon_deg: float
    prior_source: str
    chi2_bound_95: float | None
    consistent: bool | None
    verdict: str


def _residual_rows(specs: Sequence[ObsSpec], sol: FixSolution) -> tuple[ResidualRow, ...]:
    obs = [s.obs for s in specs]
    metres = to_metres(stack_rows(obs, sol.lat_rad, sol.lon_rad))
    w = standardised_residuals(metres.g, metres.cov, metres.residual, sol.weighted)
    rows: list[ResidualRow] = []
    i = 0
    for spec in specs:
        native = spec.obs.linearise(sol.lat_rad, sol.lon_rad)
        for j, kind in enumerate(native.kinds):
            value = float(native.residual[j])
            sigma_native = float(np.sqrt(native.cov[j, j]))
            if spec.unit == "deg":
                value, sigma_native = math.degrees(value), math.degrees(sigma_native)
            row = {"fix_north": "north", "fix_east": "east"}.get(kind, kind)
            rows.append(
                ResidualRow(
                    spec.label,
                    row,
                    spec.unit,
                    value,
                    float(metres.residual[i]),
                    sigma_native,
                    spec.sigma_default,
                    value / sigma_native,
                    float(w[i]),
                )
            )
            i += 1
    return tuple(rows)


def _verdict(
    sol: FixSolution, rows: Sequence[ResidualRow]
) -> tuple[float | None, bool | None, str]:
    if sol.redundancy == 0:
        return (
            None,
            None,
            (
                "no redundancy: the fix passes exactly through the observations, "
                "so they cannot be checked against each other"
            ),
        )
    bound = float(chi2_ppf(0.95, sol.redundancy))
    if sol.chi2 <= bound:
        return (
            bound,
            True,
            (
                f"residuals consistent with the sigmas (chi-square {sol.chi2:.2f} "
                f"<= {bound:.2f}, the 95 % bound for {sol.redundancy} degree(s) of freedom)"
            ),
        )
    ranked = sorted((r for r in rows if math.isfinite(r.w)), key=lambda r: -abs(r.w))
    head = (
        f"chi-square {sol.chi2:.2f} > {bound:.2f} (95 % bound, {sol.redundancy} degree(s) of "
        "freedom)"
    )
    if ranked and (len(ranked) == 1 or abs(ranked[0].w) > 1.01 * abs(ranked[1].w)):
        top = ranked[0]
        what = (
            top.label
            if top.row in ("range", "bearing", "line", "pier", "nadir")
            else f"{top.label} ({top.row})"
        )
        return (
            bound,
            False,
            (
                f"an observation disagrees: {what}, residual {top.residual:+.3g} "
                f"{top.unit} (w = {top.w:+.1f}); {head}; check it or its sigma"
            ),
        )
    return (
        bound,
        False,
        (
            f"the observations disagree: {head}; with so little redundancy the "
            "culprit cannot be told apart; check them or their sigmas"
        ),
    )


def default_prior_deg(specs: Sequence[ObsSpec]) -> tuple[float, float]:
    """Mean of the fixes if any, else of the charted marks and line ends (lon on the circle)."""
    fixes = [pt for s in specs if s.is_fix for pt in s.points_deg]
    pts = fixes or [pt for s in specs for pt in s.points_deg]
    lat = float(np.mean([p[0] for p in pts]))
    lon = math.degrees(float(wrap_pi(circmean(np.radians([p[1] for p in pts])))))
    return lat, lon


def solve(
    specs: Sequence[ObsSpec], prior_deg: tuple[float, float] | None, weighted: bool
) -> tuple[FixSolution, float, float, str]:
    """Fuse; with no prior, search for other solutions (two circles cross twice).

    Without ``--prior`` the fix is iterated from the default prior and from eight points
    around it (at the observations' own scale, 100 m to 50 km); converged solutions more
    than 1 m apart whose chi-square passes its 99.9 % bound (any, with no redundancy) are
    all candidates: more than one raises :class:`GeometryError` naming them.
    """
    obs = [s.obs for s in specs]
    if not obs:
        raise FixUsageError(
            "dracc fix: no observations; give --fix, --range, --bearing, --line, "
            "--pier, --nadir or --file"
        )
    if prior_deg is not None:
        lat, lon = prior_deg
        sol = fuse_fix(obs, _rad(lat), _rad(lon), weighted=weighted)
        return _near(sol, specs, lat, lon), lat, lon, "given"
    if all(isinstance(s.obs, NadirCircle) for s in specs):
        raise FixUsageError(
            "dracc fix: nadir circles are thousands of km wide; give --prior LAT,LON "
            "(the DR position) to choose the intersection"
        )
    lat0, lon0 = default_prior_deg(specs)
    scales = [s.scale_m for s in specs if s.scale_m is not None]
    scales += [
        float(distance_m(_rad(lat0), _rad(lon0), _rad(p[0]), _rad(p[1])))
        for s in specs
        for p in s.points_deg
    ]
    ring_m = float(np.clip(np.median(scales) if scales else 100.0, 100.0, 50_000.0))
    starts = [(_rad(lat0), _rad(lon0))]
    for az in np.radians(np.arange(0.0, 360.0, 45.0) + 22.5):
        la, lo = add_offset_ne(_rad(lat0), _rad(lon0), ring_m * math.cos(az), ring_m * math.sin(az))
        starts.append((float(la), float(lo)))
    found: list[FixSolution] = []
    first_error: GeometryError | None = None
    for la, lo in starts:
        try:
            sol = fuse_fix(obs, la, lo, weighted=weighted)
        except GeometryError as e:
            first_error = first_error or e
            continue
        if all(distance_m(sol.lat_rad, sol.lon_rad, f.lat_rad, f.lon_rad) > 1.0 for f in found):
            found.append(sol)
    if not found:
        assert first_error is not None
        raise first_error
    redundancy = found[0].redundancy
    bound = float(chi2_ppf(0.999, redundancy)) if redundancy > 0 else math.inf
    good = [s for s in found if s.chi2 <= bound or redundancy == 0]
    if len(good) > 1:
        cands = "; ".join(
            f"{format_dm(math.degrees(s.lat_rad), 'lat')} "
            f"{format_dm(math.degrees(s.lon_rad), 'lon')}"
            for s in good[:4]
        )
        raise GeometryError(
            f"the observations fit {len(good)} positions ({cands}); give --prior "
            "LAT,LON near the ship (e.g. the DR position) to choose one"
        )
    best = good[0] if good else min(found, key=lambda s: s.chi2)
    return (
        _near(best, specs, lat0, lon0),
        lat0,
        lon0,
        "mean of the fixes" if any(s.is_fix for s in specs) else "mean of the marks",
    )


def _near(
    sol: FixSolution, specs: Sequence[ObsSpec], lat_deg: float, lon_deg: float
) -> FixSolution:
    """Refuse a solution far beyond the observations' own scale (nearly parallel lines).

    Straight lines of position are great circles: two "parallel" transits (e.g. two
    meridians) meet thousands of km away, with an enormous DOP.  A solution more than
    max(100 km, 10 x the largest range or circle radius) from the prior is no fix.
    """
    limit_m = max([100_000.0] + [10.0 * s.scale_m for s in specs if s.scale_m is not None])
    d_m = float(distance_m(_rad(lat_deg), _rad(lon_deg), sol.lat_rad, sol.lon_rad))
    if d_m > limit_m:
        raise GeometryError(
            f"the lines of position meet {d_m / NMI_M:,.0f} nmi from the prior "
            f"(DOP {float(sol.dop):,.0f}): they are nearly parallel (or the prior is far off); no fix"
        )
    return sol


def fix_report(
    specs: Sequence[ObsSpec], prior_deg: tuple[float, float] | None, weighted: bool
) -> FixReport:
    """Solve and assess: residual rows, Baarda w, chi-square verdict."""
    sol, plat, plon, psrc = solve(specs, prior_deg, weighted)
    rows = _residual_rows(specs, sol)
    bound, consistent, verdict = _verdict(sol, rows)
    return FixReport(sol, tuple(specs), rows, plat, plon, psrc, bound, consistent, verdict)


# --------------------------------------------------------------------- rendering


def format_dm(value_deg: float, axis: str, decimals: int = 3) -> str:
    """Degrees and decimal minutes: ``54°36.500'N``, ``018°48.200'E``."""
    hemi = ("N" if value_deg >= 0 else "S") if axis == "lat" else ("E" if value_deg >= 0 else "W")
    a = abs(value_deg)
    deg = int(a)
    minutes = round((a - deg) * 60.0, decimals)
    if minutes >= 60.0:
        deg, minutes = deg + 1, 0.0
    width = 2 if axis == "lat" else 3
    return f"{deg:0{width}d}°{minutes:0{decimals + 3}.{decimals}f}'{hemi}"


def to_json(rep: FixReport) -> dict:
    """The ``dracc.fix/1`` object (see :data:`JSON_SCHEMA` and docs/fix.md)."""
    s = rep.solution
    lat, lon = math.degrees(s.lat_rad), math.degrees(s.lon_rad)
    return {
        "schema": SCHEMA,
        "lat_deg": lat,
        "lon_deg": lon,
        "lat_dm": format_dm(lat, "lat"),
        "lon_dm": format_dm(lon, "lon"),
        "cov_m2": [
            [float(s.cov_m2[0, 0]), float(s.cov_m2[0, 1])],
            [float(s.cov_m2[1, 0]), float(s.cov_m2[1, 1])],
        ],
        "ellipse": {
            "semi_major_m": float(s.ellipse.semi_major_m),
            "semi_minor_m": float(s.ellipse.semi_minor_m),
            "orientation_deg": math.degrees(float(s.ellipse.orientation_rad)),
        },
        "drms_m": float(s.drms_m),
        "two_drms_m": float(s.two_drms_m),
        "dop": float(s.dop),
        "residuals": [
            {
                "observation": r.label,
                "row": r.row,
                "unit": r.unit,
                "residual": r.residual,
                "residual_m": r.residual_m,
                "sigma": r.sigma,
                "sigma_default": r.sigma_default,
                "normalised": r.normalised,
                "w": _finite(r.w),
            }
            for r in rep.residuals
        ],
        "chi2": float(s.chi2),
        "redundancy": int(s.redundancy),
        "chi2_bound_95": rep.chi2_bound_95,
        "consistent": rep.consistent,
        "verdict": rep.verdict,
        "weighted": bool(s.weighted),
        "method": "WLS" if s.weighted else "LS",
        "iterations": int(s.iterations),
        "prior": {
            "lat_deg": rep.prior_lat_deg,
            "lon_deg": rep.prior_lon_deg,
            "source": rep.prior_source,
        },
        "observations": [{"label": sp.label, "source": sp.source} for sp in rep.specs],
    }


_NUMBER = {"type": "number"}
#: JSON Schema (draft 2020-12) of ``dracc fix --json``; every key is documented in docs/fix.md
JSON_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "additionalProperties": False,
    "required": [
        "schema",
        "lat_deg",
        "lon_deg",
        "lat_dm",
        "lon_dm",
        "cov_m2",
        "ellipse",
        "drms_m",
        "two_drms_m",
        "dop",
        "residuals",
        "chi2",
        "redundancy",
        "chi2_bound_95",
        "consistent",
        "verdict",
        "weighted",
        "method",
        "iterations",
        "prior",
        "observations",
    ],
    "properties": {
        "schema": {"const": SCHEMA},
        "lat_deg": {"type": "number", "minimum": -90, "maximum": 90},
        "lon_deg": {"type": "number", "minimum": -180, "maximum": 180},
        "lat_dm": {"type": "string"},
        "lon_dm": {"type": "string"},
        "cov_m2": {
            "type": "array",
            "minItems": 2,
            "maxItems": 2,
            "items": {"type": "array", "minItems": 2, "maxItems": 2, "items": _NUMBER},
        },
        "ellipse": {
            "type": "object",
            "additionalProperties": False,
            "required": ["semi_major_m", "semi_minor_m", "orientation_deg"],
            "properties": {
                "semi_major_m": {"type": "number", "minimum": 0},
                "semi_minor_m": {"type": "number", "minimum": 0},
                "orientation_deg": {"type": "number", "minimum": 0, "exclusiveMaximum": 180},
            },
        },
        "drms_m": {"type": "number", "minimum": 0},
        "two_drms_m": {"type": "number", "minimum": 0},
        "dop": {"type": "number", "minimum": 0},
        "residuals": {
            "type": "array",
            "items": {
                "type": "object",
                "additionalProperties": False,
                "required": [
                    "observation",
                    "row",
                    "unit",
                    "residual",
                    "residual_m",
                    "sigma",
                    "sigma_default",
                    "normalised",
                    "w",
                ],
                "properties": {
                    "observation": {"type": "string"},
                    "row": {"enum": ["north", "east", "range", "bearing", "line", "pier", "nadir"]},
                    "unit": {"enum": ["m", "deg"]},
                    "residual": _NUMBER,
                    "residual_m": _NUMBER,
                    "sigma": {"type": "number", "exclusiveMinimum": 0},
                    "sigma_default": {"type": "boolean"},
                    "normalised": _NUMBER,
                    "w": {"type": ["number", "null"]},
                },
            },
        },
        "chi2": {"type": "number", "minimum": 0},
        "redundancy": {"type": "integer", "minimum": 0},
        "chi2_bound_95": {"type": ["number", "null"]},
        "consistent": {"type": ["boolean", "null"]},
        "verdict": {"type": "string"},
        "weighted": {"type": "boolean"},
        "method": {"enum": ["WLS", "LS"]},
        "iterations": {"type": "integer", "minimum": 1},
        "prior": {
            "type": "object",
            "additionalProperties": False,
            "required": ["lat_deg", "lon_deg", "source"],
            "properties": {"lat_deg": _NUMBER, "lon_deg": _NUMBER, "source": {"type": "string"}},
        },
        "observations": {
            "type": "array",
            "items": {
                "type": "object",
                "additionalProperties": False,
                "required": ["label", "source"],
                "properties": {"label": {"type": "string"}, "source": {"type": "string"}},
            },
        },
    },
}


def render(rep: FixReport) -> None:
    """The fix as rich tables on stdout."""
    s = rep.solution
    lat, lon = math.degrees(s.lat_rad), math.degrees(s.lon_rad)
    e = s.ellipse
    head = Table(
        title=f"dracc fix ({'WLS (W4)' if s.weighted else 'LS (W1)'}, "
        f"{len(rep.specs)} observation(s), {s.iterations} iteration(s))",
        show_header=False,
        title_justify="left",
    )
    head.add_column("quantity")
    head.add_column("value")
    head.add_row("position", f"{format_dm(lat, 'lat')}  {format_dm(lon, 'lon')}")
    head.add_row("decimal", f"{lat:.7f}, {lon:.7f}")
    head.add_row(
        "error ellipse (1σ)",
        f"{float(e.semi_major_m):.2f} m × {float(e.semi_minor_m):.2f} m, "
        f"major axis {math.degrees(float(e.orientation_rad)):05.1f}° true",
    )
    head.add_row("drms / 2drms", f"{float(s.drms_m):.2f} m / {float(s.two_drms_m):.2f} m")
    head.add_row("DOP", f"{float(s.dop):.3f}")
    head.add_row("chi-square", f"{float(s.chi2):.3f}, redundancy {s.redundancy}")
    head.add_row(
        "prior",
        f"{format_dm(rep.prior_lat_deg, 'lat')}  "
        f"{format_dm(rep.prior_lon_deg, 'lon')} ({rep.prior_source})",
    )
    out.print(head)
    res = Table(title="residuals (measured − fitted)", title_justify="left")
    for name, justify in (
        ("observation", "left"),
        ("row", "left"),
        ("residual", "right"),
        ("σ", "right"),
        ("r/σ", "right"),
        ("w", "right"),
    ):
        res.add_column(name, justify=justify)  # type: ignore[arg-type]
    for r in rep.residuals:
        digits = 3 if r.unit == "deg" else 2
        sigma = f"{r.sigma:.{digits}f} {r.unit}" + (" (default)" if r.sigma_default else "")
        res.add_row(
            r.label,
            r.row,
            f"{r.residual:+.{digits}f} {r.unit}",
            sigma,
            f"{r.normalised:+.2f}",
            "-" if not math.isfinite(r.w) else f"{r.w:+.2f}",
        )
    out.print(res)
    out.print(f"verdict: {rep.verdict}", highlight=False, markup=False)


# -------------------------------------------------------------------------- command


def _prior(
    text: str | None, file_prior: dict | None, file: Path | None
) -> tuple[float, float] | None:
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


_OBS_HELP = "Repeatable. Coordinates: 54.6, -18.8, '54 36.5N', '018 48.2E', \"54°36.5'N\"."


@app.command("fix")
def fix_cmd(
    fix: list[str] = typer.Option(
        [],
        "--fix",
        metavar="LAT,LON[,SIGMA_M]",
        help=f"A position fix (default sigma {DEFAULT_FIX_SIGMA_M:g} m). {_OBS_HELP}",
    ),
    range_: list[str] = typer.Option(
        [],
        "--range",
        metavar="LAT,LON,DIST[,SIGMA]",
        help="Range of a mark, DIST with a unit: 2.4nmi, 2.4nm, 4cbl, 450m, "
        "1.2km; SIGMA the same (bare: metres; default: IMO radar, "
        "max(30 m, 1 % of DIST) / 2).",
    ),
    bearing: list[str] = typer.Option(
        [],
        "--bearing",
        metavar="LAT,LON,BRG_DEG[,SIGMA_DEG]",
        help="True bearing of the mark taken from the ship (default "
        f"sigma {DEFAULT_BEARING_SIGMA_DEG:g}°).",
    ),
    bearing_mark: list[str] = typer.Option(
        [],
        "--bearing-from-mark",
        metavar="LAT,LON,BRG_DEG[,SIGMA_DEG]",
        help="True bearing of the ship taken at the mark (D/F, VOR).",
    ),
    line: list[str] = typer.Option(
        [],
        "--line",
        metavar="LAT1,LON1,LAT2,LON2[,SIGMA_M[,OFFSET_M]]",
        help="Straight line of position A->B (a transit); OFFSET_M > 0: "
        f"the ship is right of A->B (default sigma {DEFAULT_LINE_SIGMA_M:g} m).",
    ),
    pier: list[str] = typer.Option(
        [],
        "--pier",
        metavar="LAT1,LON1,LAT2,LON2,HEADING_DEG,port|starboard,"
        "HALF_BREADTH_M[,SIGMA_M[,GAP_M[,REF_STBD_M]]]",
        help="Lying alongside the pier line A->B, SIDE to the pier (default "
        f"sigma {DEFAULT_PIER_SIGMA_M:g} m; GAP_M fenders; REF_STBD_M the "
        "reference point to starboard of the centreline).",
    ),
    abeam: list[str] = typer.Option(
        [],
        "--abeam",
        metavar="LAT,LON[,SIGMA_M]",
        help="A pier mark abeam of the reference point (needs one --pier; "
        f"default sigma {DEFAULT_ABEAM_SIGMA_M:g} m).",
    ),
    nadir: list[str] = typer.Option(
        [],
        "--nadir",
        metavar="SUBLAT,SUBLON,NADIR_DEG[,SIGMA_DEG]",
        help="Free-gyro nadir circle about the sub-point (default sigma "
        "1'; needs --prior when alone).",
    ),
    prior: str | None = typer.Option(
        None,
        "--prior",
        metavar="LAT,LON",
        help="Linearisation point, e.g. the DR position (default: the mean "
        "of the fixes, else of the marks; then other solutions are "
        "searched for and an ambiguity is an error).",
    ),
    file: Path | None = typer.Option(
        None,
        "--file",
        "-f",
        metavar="OBS.TOML",
        help="Observations as TOML table arrays named fix, range, bearing, "
        "line, pier, abeam, nadir, and an optional prior table "
        "(docs/fix.md); they combine with the options.",
    ),
    ls: bool = typer.Option(
        False, "--ls", help="Unweighted least squares (W1) instead of WLS (W4)."
    ),
    as_json: bool = typer.Option(
        False, "--json", help="Print the dracc.fix/1 JSON object instead of tables."
    ),
) -> None:
    """Fuse position fixes and lines of position (LS/WLS): position, error ellipse, DOP, residuals.

    Exit codes: 0 a fix; 2 a bad option value; 3 no (unique) fix from this geometry, or
    --file missing; 4 an invalid --file.
    """
    pending: list[Pending] = []
    for option, values in (
        ("--fix", fix),
        ("--range", range_),
        ("--bearing", bearing),
        ("--bearing-from-mark", bearing_mark),
        ("--line", line),
        ("--pier", pier),
        ("--abeam", abeam),
        ("--nadir", nadir),
    ):
        pending += [parse_option(option, v) for v in values]
    file_prior = None
    if file is not None:
        more, file_prior = read_obs_file(file)
        pending += more
    prior_deg = _prior(prior, file_prior, file)
    specs = build_observations(pending)
    rep = fix_report(specs, prior_deg, weighted=not ls)
    if as_json:
        out.file.write(
            json.dumps(to_json(rep), indent=2, allow_nan=False, ensure_ascii=False) + "\n"
        )
    else:
        render(rep)


__all__ = [
    "JSON_SCHEMA",
    "SCHEMA",
    "FixFileError",
    "FixReport",
    "FixUsageError",
    "ObsSpec",
    "build_observations",
    "default_prior_deg",
    "fix_report",
    "format_dm",
    "parse_coordinate_deg",
    "parse_distance_m",
    "parse_option",
    "read_obs_file",
    "solve",
    "standardised_residuals",
    "to_json",
]
