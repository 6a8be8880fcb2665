"""An MCAP that Foxglove opens: the voyage's inputs, the DR and EP with their covariance,
the 2M circles, the deviations and the current, on one timeline.

``dracc analyze ... --mcap F`` (:func:`write_mcap_export`; written atomically and renamed
into place with the other reports inside :func:`dracc.core.atomic.together`).  The file is
zstd-chunked, indexed, with a summary; every message's log and publish time is the time of
the record it carries (the fix, the epoch, the sample), and messages are written in
log-time order, so Foxglove's timeline plays the voyage.

Encoding: JSON messages (``json``) with JSON-Schema channel schemas (``jsonschema``).  The
Foxglove schemas are the published ones (:data:`LOCATION_FIX_SCHEMA`, :data:`GEOJSON_SCHEMA`,
from https://github.com/foxglove/schemas, ``schemas/jsonschema/``, MIT licence); Foxglove
recognises a channel by the schema's name (``foxglove.LocationFix``), so its Map panel
draws the fixes, their covariance and the GeoJSON without any extension.  JSON needs no
dependency beyond the ``mcap`` writer and keeps every message readable (``mcap cat
--json``); zstd takes the bulk of its size.

Channels (topic: schema, fields; units in every dracc field name)

``/input/<name>/fix``      foxglove.LocationFix: each position source as the plots have it
                           (``Track``: every record up to 4000 points a source);
                           ``<name>`` is the source's role where no other source has it
                           (``gnss``, ``ins1``), else its key; ``frame_id`` the key;
                           covariance UNKNOWN (the logs do not give one)
``/input/<name>/heading``  dracc.Heading ``{heading_deg, reference}`` ('true', 'magnetic'
                           or null): each heading source, thinned to one record per 10 s
                           (``overview.HEADING_STEP_S``)
``/dracc/ep``              foxglove.LocationFix: the DR over the ground (the water track
                           with the learned corrections and current) with ``position_covariance``
                           its propagated covariance, ENU in m^2, row-major 3 x 3,
                           type KNOWN (3); the vertical is not estimated: its row and
                           column are 0, altitude 0 (sea level)
``/dracc/dr``              foxglove.LocationFix: the water track (heading and log alone);
                           the analysis propagates no covariance of its own for it, so
                           its type is UNKNOWN (0).  Where the analysis learned nothing
                           the DR is the one track: ``/dracc/dr`` then carries the
                           covariance (KNOWN) and there is no ``/dracc/ep``
``/dracc/dr_error``        dracc.DRError at the same rows: ``radius_2m_m`` (2 drms, B30
                           B31), ``semi_major_m``/``semi_minor_m`` (1 sigma),
                           ``orientation_deg``, ``since_fix_s``, ``ref_error_m``, ``leg``
``/dracc/dr_2m``           foxglove.GeoJSON at each reporting epoch: a FeatureCollection of
                           the 2M circle and the 2-sigma error ellipse as polygons
                           (vertices from :func:`dracc.core.geodesy.add_offset_ne`, rings
                           closed and counter-clockwise, longitudes continuous across the
                           antimeridian), with ``name``, a leaflet ``style`` (miss red,
                           inside blue, unscored grey) and ``time_utc``, ``leg``,
                           ``radius_2m_m``, ``ref_error_m``, ``inside`` (the reference within
                           2M widened by its own noise, as the consistency check counts;
                           null where the epoch is not scored), ``scored``
``/dracc/aided_ep``        foxglove.LocationFix: the fix-updated EP (seeds/003's aided DR,
                           ``Analysis.estimated_position``) at its epochs, covariance KNOWN
                           (3) from its 1-sigma ellipse (ENU m^2, as ``/dracc/ep``)
``/dracc/aided_ep_error``  dracc.AidedEPError at the same epochs: ``radius_2m_m``,
                           ``semi_major_m``/``semi_minor_m`` (1 sigma), ``orientation_deg``,
                           ``since_update_s``, ``update`` ('gnss', 'bearing 1'; '' none)
``/dracc/aided_ep_2m``     foxglove.GeoJSON at each of its epochs: the 2M circle and the
                           2-sigma error ellipse as polygons (as ``/dracc/dr_2m``), with
                           ``time_utc``, ``radius_2m_m``, ``since_update_s``, ``update``
``/dracc/reference``       foxglove.LocationFix: the reference the DR is scored against,
                           covariance DIAGONAL_KNOWN (2) from the reference noise the
                           analysis estimated (east, north sigma^2)
``/dracc/deviation/<unit>``  dracc.Deviation per INS unit at the sampling instants:
                           ``lat_m`` (north), ``lon_m`` (east), ``course_deg``; null where
                           the unit had no sample
``/dracc/current``         dracc.Current at the filter's steps: ``set_deg`` (towards, true),
                           ``drift_kn``, ``drift_sigma_kn``, ``north_kn``, ``east_kn``

Rows of the DR and EP: the full-rate rows thinned to one every :data:`EXPORT_STEP_S`
seconds of each leg, plus each leg's first and last row and every reporting epoch (so a
2M polygon always has its fix).  The channels of the three positions carry their names
as the reports use them in the channel metadata ``name`` (:mod:`dracc.core.vocabulary`:
water track, DR over the ground, fix-updated EP).  A ``dracc.export`` metadata record
names the version, the inputs and these choices.  The Foxglove layout ``docs/foxglove/dracc-layout.json``
names these channels.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dracc import __version__
from dracc.core.atomic import atomic_path
from dracc.core.geodesy import add_offset_ne, wrap_pi
from dracc.core.timefmt import iso_utc
from dracc.core.units import KN_MPS
from dracc.core.vocabulary import (
    CHANNEL_KEYS,
    CHANNELS,
    DR_OVER_GROUND,
    FIX_UPDATED_EP,
    WATER_TRACK,
)
from dracc.pipeline.results import Analysis, DRSection, DRTrackResult, EstimatedPositionSection
from dracc.report.exports import inside_flags

__all__ = [
    "EXPORT_STEP_S",
    "GEOJSON_SCHEMA",
    "LOCATION_FIX_SCHEMA",
    "RING_VERTICES",
    "enu_covariance",
    "export_rows",
    "inside_2m",
    "mcap_streams",
    "ring_lonlat_deg",
    "write_mcap_export",
]

#: the DR and EP rows: one every this many seconds of each leg (plus firsts, lasts, epochs)
EXPORT_STEP_S = 10.0
#: vertices of each 2M circle and error ellipse (the ring closes with one more)
RING_VERTICES = 72
#: the error ellipse drawn beside the 2M circle: this many sigma
ELLIPSE_SIGMA = 2.0

#: foxglove.PositionCovarianceType
COVARIANCE_UNKNOWN, COVARIANCE_DIAGONAL_KNOWN, COVARIANCE_KNOWN = 0, 2, 3

_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
}

#: foxglove.LocationFix, as published (foxglove/schemas schemas/jsonschema/LocationFix.json)
LOCATION_FIX_SCHEMA: dict[str, Any] = {
    "title": "foxglove.LocationFix",
    "description": "A navigation satellite fix for any Global Navigation Satellite System",
    "$comment": "Generated by https://github.com/foxglove/foxglove-sdk",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of the message"},
        "frame_id": {
            "type": "string",
            "description": "Frame for the sensor. Latitude and longitude readings are at "
            "the origin of the frame.",
        },
        "latitude": {"type": "number", "description": "Latitude in degrees"},
        "longitude": {"type": "number", "description": "Longitude in degrees"},
        "altitude": {"type": "number", "description": "Altitude in meters"},
        "position_covariance": {
            "type": "array",
            "items": {"type": "number"},
            "minItems": 9,
            "maxItems": 9,
            "description": "Position covariance (m^2) defined relative to a tangential plane "
            "through the reported position. The components are East, North, and Up (ENU), "
            "in row-major order.",
        },
        "position_covariance_type": {
            "title": "foxglove.PositionCovarianceType",
            "description": "If `position_covariance` is available, `position_covariance_type` "
            "must be set to indicate the type of covariance.",
            "oneOf": [
                {"title": "UNKNOWN", "const": 0},
                {"title": "APPROXIMATED", "const": 1},
                {"title": "DIAGONAL_KNOWN", "const": 2},
                {"title": "KNOWN", "const": 3},
            ],
        },
    },
}

#: foxglove.GeoJSON, as published (foxglove/schemas schemas/jsonschema/GeoJSON.json)
GEOJSON_SCHEMA: dict[str, Any] = {
    "title": "foxglove.GeoJSON",
    "description": "GeoJSON data for annotating maps",
    "$comment": "Generated by https://github.com/foxglove/foxglove-sdk",
    "type": "object",
    "properties": {
        "geojson": {"type": "string", "description": "GeoJSON data encoded as a UTF-8 string"}
    },
}

_STYLE = {
    True: {"color": "#1f77b4", "weight": 1, "fillOpacity": 0.05},  # reference inside 2M
    False: {"color": "#d62728", "weight": 2, "fillOpacity": 0.15},  # a miss
    None: {"color": "#7f7f7f", "weight": 1, "fillOpacity": 0.0},  # not scored
}


def _dracc_schema(title: str, fields: dict[str, str]) -> dict[str, Any]:
    """A JSON schema of a dracc message: the time, the frame and ``fields`` (name -> type)."""
    props: dict[str, Any] = {"timestamp": _TIME, "frame_id": {"type": "string"}}
    props.update({k: {"type": [t, "null"]} for k, t in fields.items()})
    return {"title": title, "type": "object", "properties": props}


HEADING_SCHEMA = _dracc_schema("dracc.Heading", {"heading_deg": "number", "reference": "string"})
DEVIATION_SCHEMA = _dracc_schema("dracc.Deviation", {CHANNEL_KEYS[c]: "number" for c in CHANNELS})
CURRENT_SCHEMA = _dracc_schema(
    "dracc.Current",
    dict.fromkeys(("set_deg", "drift_kn", "drift_sigma_kn", "north_kn", "east_kn"), "number"),
)
DR_ERROR_SCHEMA = _dracc_schema(
    "dracc.DRError",
    {
        "radius_2m_m": "number",
        "semi_major_m": "number",
        "semi_minor_m": "number",
        "orientation_deg": "number",
        "since_fix_s": "number",
        "ref_error_m": "number",
        "leg": "integer",
    },
)

AIDED_EP_ERROR_SCHEMA = _dracc_schema(
    "dracc.AidedEPError",
    {
        "radius_2m_m": "number",
        "semi_major_m": "number",
        "semi_minor_m": "number",
        "orientation_deg": "number",
        "since_update_s": "number",
        "update": "string",
    },
)
#: the aided EP's polygons (Foxglove's Map draws GeoJSON with leaflet styles)
_AIDED_STYLE = {"color": "#2ca02c", "weight": 1, "fillOpacity": 0.1}


@dataclass
class Stream:
    """One channel: its topic, schema and messages (log times, JSON bytes); ``name``: the
    position it carries as the reports name it (the channel's metadata ``name``)."""

    topic: str
    schema: dict[str, Any]
    name: str = ""
    times: list[int] = field(default_factory=list)
    messages: list[bytes] = field(default_factory=list)

    def add(self, time_ns: int, obj: dict[str, Any]) -> None:
        self.times.append(int(time_ns))
        self.messages.append(json.dumps(obj, separators=(",", ":"), allow_nan=False).encode())


# ------------------------------------------------------------------------ helpers


def _num(x: Any) -> float | None:
    v = float(x)
    return v if math.isfinite(v) else None


def _stamp(time_ns: int) -> dict[str, int]:
    sec, nsec = divmod(int(time_ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def enu_covariance(
    semi_major_m: np.ndarray, semi_minor_m: np.ndarray, orientation_rad: np.ndarray
) -> np.ndarray:
    """(n, 9) row-major ENU covariances (m^2) of the 1-sigma ellipses: P = a^2 u u^T +
    b^2 v v^T with u the major axis at azimuth ``orientation_rad`` (from north towards
    east), u = (sin, cos) in (east, north), v perpendicular; the vertical row and column 0.
    The inverse of :func:`dracc.math.ellipse.error_ellipse`."""
    a2 = np.asarray(semi_major_m, float) ** 2
    b2 = np.asarray(semi_minor_m, float) ** 2
    s, c = np.sin(orientation_rad), np.cos(orientation_rad)
    out = np.zeros((a2.size, 9))
    out[:, 0] = a2 * s * s + b2 * c * c  # east-east
    out[:, 1] = out[:, 3] = (a2 - b2) * s * c  # east-north
    out[:, 4] = a2 * c * c + b2 * s * s  # north-north
    return out


def export_rows(
    tr: DRTrackResult, epochs_ns: np.ndarray, step_s: float = EXPORT_STEP_S
) -> np.ndarray:
    """Indices of the rows of ``tr`` to export: one every ``step_s`` seconds of each leg
    (where the whole number of steps since the leg's first row grows), each leg's first
    and last row, and the rows at ``epochs_ns``; rows without a position left out."""
    n = tr.time_ns.size
    if n == 0:
        return np.zeros(0, np.int64)
    t = tr.time_ns.astype(np.int64)
    leg = tr.leg
    first = np.r_[True, leg[1:] != leg[:-1]]
    last = np.r_[leg[1:] != leg[:-1], True]
    start = t[np.maximum.accumulate(np.where(first, np.arange(n), 0))]
    k = (t - start) // int(round(step_s * 1e9))
    keep = first | last | np.r_[True, k[1:] != k[:-1]] | np.isin(t, epochs_ns)
    keep &= np.isfinite(tr.lat_rad) & np.isfinite(tr.lon_rad)
    return np.flatnonzero(keep)


def ring_lonlat_deg(
    lat_rad: float, lon_rad: float, a_m: float, b_m: float, azimuth_rad: float
) -> list[list[float]]:
    """A closed counter-clockwise ring [[lon, lat], ...] in degrees: the ellipse with
    semi-axes ``a_m`` (at ``azimuth_rad`` from north) and ``b_m`` about the point (a circle
    for a = b).  Longitudes stay within 180 degrees of the centre's (no wrap), so a ring
    across the antimeridian stays one ring."""
    t = np.linspace(0.0, 2.0 * np.pi, RING_VERTICES, endpoint=False)
    ue, un = math.sin(azimuth_rad), math.cos(azimuth_rad)  # major axis (east, north)
    ve, vn = -un, ue  # u turned 90 degrees counter-clockwise
    east = a_m * np.cos(t) * ue + b_m * np.sin(t) * ve
    north = a_m * np.cos(t) * un + b_m * np.sin(t) * vn
    lat, lon = add_offset_ne(lat_rad, lon_rad, north, east)
    lon = lon_rad + wrap_pi(lon - lon_rad)
    ring = [
        [math.degrees(x), math.degrees(y)] for x, y in zip(lon.tolist(), lat.tolist(), strict=True)
    ]
    return ring + [ring[0]]


def _topic_names(a: Analysis) -> dict[str, str]:
    """Source key -> topic name: the role where exactly one source has it, else the key;
    characters a topic should not hold become '_'."""
    roles: dict[str, set[str]] = {}
    keys = [t.source for t in a.tracks] + [h.source for h in a.headings]
    role_of = {t.source: t.role for t in a.tracks} | {h.source: h.role for h in a.headings}
    for k in keys:
        if role_of.get(k):
            roles.setdefault(str(role_of[k]), set()).add(k)
    names: dict[str, str] = {}
    used: set[str] = set()
    for k in dict.fromkeys(keys):
        r = role_of.get(k)
        want = r if r and len(roles.get(r, ())) == 1 else k
        name = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(want)).strip("_") or "source"
        base, i = name, 2
        while name in used:
            name, i = f"{base}_{i}", i + 1
        used.add(name)
        names[k] = name
    return names


# ---------------------------------------------------------------------- channels


def _fix(
    s: Stream,
    time_ns: int,
    frame: str,
    lat_rad: float,
    lon_rad: float,
    cov: Iterable[float],
    kind: int,
) -> None:
    s.add(
        time_ns,
        {
            "timestamp": _stamp(time_ns),
            "frame_id": frame,
            "latitude": math.degrees(lat_rad),
            "longitude": math.degrees(lon_rad),
            "altitude": 0.0,
            "position_covariance": [float(x) for x in cov],
            "position_covariance_type": kind,
        },
    )


def _input_streams(a: Analysis, names: dict[str, str]) -> list[Stream]:
    out = []
    zero = [0.0] * 9
    for t in a.tracks:
        s = Stream(f"/input/{names[t.source]}/fix", LOCATION_FIX_SCHEMA)
        for tn, la, lo in zip(
            t.time_ns.tolist(), t.lat_rad.tolist(), t.lon_rad.tolist(), strict=True
        ):
            _fix(s, tn, t.source, la, lo, zero, COVARIANCE_UNKNOWN)
        out.append(s)
    words = {"T": "true", "M": "magnetic"}
    for h in a.headings:
        s = Stream(f"/input/{names[h.source]}/heading", HEADING_SCHEMA)
        for tn, hd, ref in zip(
            h.time_ns.tolist(), h.heading_rad.tolist(), h.reference.tolist(), strict=True
        ):
            s.add(
                tn,
                {
                    "timestamp": _stamp(tn),
                    "frame_id": h.source,
                    "heading_deg": _num(math.degrees(hd)),
                    "reference": words.get(ref),
                },
            )
        out.append(s)
    return out


def _dr_streams(dr: DRSection) -> list[Stream]:
    """/dracc/ep (or /dracc/dr where nothing was learned) with the covariance, the water
    track, the error beside them and the 2M polygons at the epochs."""
    tr = dr.track
    idx = export_rows(tr, dr.epochs.time_ns)
    cov = enu_covariance(tr.semi_major_m[idx], tr.semi_minor_m[idx], tr.orientation_rad[idx])
    ok = np.isfinite(cov).all(axis=1)
    learned = dr.learned is not None
    main = Stream(
        "/dracc/ep" if learned else "/dracc/dr",
        LOCATION_FIX_SCHEMA,
        DR_OVER_GROUND if learned else WATER_TRACK,
    )
    err = Stream("/dracc/dr_error", DR_ERROR_SCHEMA)
    water = Stream("/dracc/dr", LOCATION_FIX_SCHEMA, WATER_TRACK) if learned else None
    zero = [0.0] * 9
    frame = "ep" if learned else "dr"
    for j, i in enumerate(idx.tolist()):
        tn = int(tr.time_ns[i])
        if ok[j]:
            _fix(main, tn, frame, tr.lat_rad[i], tr.lon_rad[i], cov[j], COVARIANCE_KNOWN)
        else:  # an indefinite covariance has no ellipse: reported as unknown, never repaired
            _fix(main, tn, frame, tr.lat_rad[i], tr.lon_rad[i], zero, COVARIANCE_UNKNOWN)
        if water is not None and math.isfinite(tr.water_lat_rad[i]):
            _fix(
                water, tn, "dr", tr.water_lat_rad[i], tr.water_lon_rad[i], zero, COVARIANCE_UNKNOWN
            )
        err.add(
            tn,
            {
                "timestamp": _stamp(tn),
                "frame_id": frame,
                "radius_2m_m": _num(tr.radius_2m_m[i]),
                "semi_major_m": _num(tr.semi_major_m[i]),
                "semi_minor_m": _num(tr.semi_minor_m[i]),
                "orientation_deg": _num(math.degrees(tr.orientation_rad[i])),
                "since_fix_s": _num(tr.since_fix_s[i]),
                "ref_error_m": _num(tr.ref_error_m[i]),
                "leg": int(tr.leg[i]),
            },
        )
    return [main, *([water] if water is not None else []), err, _polygons(dr)]


def inside_2m(dr: DRSection) -> list[bool | None]:
    """Per reporting epoch: the analysis's one judgement of the reference against the
    drawn 2M (``DRTrackResult.inside``, as the GeoJSON has it); None where not scored."""
    judged, inside = inside_flags(dr)
    return [bool(i) if j else None for j, i in zip(judged.tolist(), inside.tolist(), strict=True)]


def _polygons(dr: DRSection) -> Stream:
    ep = dr.epochs
    s = Stream("/dracc/dr_2m", GEOJSON_SCHEMA)
    for i, inside in enumerate(inside_2m(dr)):
        lat, lon, r = float(ep.lat_rad[i]), float(ep.lon_rad[i]), float(ep.radius_2m_m[i])
        if not (math.isfinite(lat) and math.isfinite(lon) and math.isfinite(r) and r > 0):
            continue
        tn = int(ep.time_ns[i])
        when = iso_utc(tn)
        props = {
            "time_utc": when,
            "leg": int(ep.leg[i]),
            "since_fix_s": _num(ep.since_fix_s[i]),
            "radius_2m_m": r,
            "semi_major_m": _num(ep.semi_major_m[i]),
            "semi_minor_m": _num(ep.semi_minor_m[i]),
            "orientation_deg": _num(math.degrees(ep.orientation_rad[i])),
            "ref_error_m": _num(ep.ref_error_m[i]),
            "inside": inside,
            "scored": bool(ep.scored[i]),
        }
        features = [
            {
                "type": "Feature",
                "properties": {
                    **props,
                    "shape": "circle",
                    "name": f"2M {when[11:16]}Z {r:,.0f} m"
                    + ("" if inside is not False else " (miss)"),
                    "style": _STYLE[inside],
                },
                "geometry": {
                    "type": "Polygon",
                    "coordinates": [ring_lonlat_deg(lat, lon, r, r, 0.0)],
                },
            }
        ]
        a, b = float(ep.semi_major_m[i]), float(ep.semi_minor_m[i])
        if math.isfinite(a) and math.isfinite(b) and b > 0:
            k = ELLIPSE_SIGMA
            features.append(
                {
                    "type": "Feature",
                    "properties": {
                        **props,
                        "shape": "ellipse",
                        "name": f"{k:g}-sigma ellipse {when[11:16]}Z",
                        "style": {**_STYLE[inside], "dashArray": "4 4", "fillOpacity": 0.0},
                    },
                    "geometry": {
                        "type": "Polygon",
                        "coordinates": [
                            ring_lonlat_deg(lat, lon, k * a, k * b, float(ep.orientation_rad[i]))
                        ],
                    },
                }
            )
        doc = {"type": "FeatureCollection", "features": features}
        s.add(tn, {"geojson": json.dumps(doc, separators=(",", ":"), allow_nan=False)})
    return s


def _aided_streams(e: EstimatedPositionSection) -> list[Stream]:
    """/dracc/aided_ep with its covariance, its error beside it and its 2M polygons."""
    fix = Stream("/dracc/aided_ep", LOCATION_FIX_SCHEMA, FIX_UPDATED_EP)
    err = Stream("/dracc/aided_ep_error", AIDED_EP_ERROR_SCHEMA)
    poly = Stream("/dracc/aided_ep_2m", GEOJSON_SCHEMA)
    cov = enu_covariance(e.semi_major_m, e.semi_minor_m, e.orientation_rad)
    for i in range(len(e.time_ns)):
        lat, lon, r = float(e.lat_rad[i]), float(e.lon_rad[i]), float(e.radius_2m_m[i])
        if not (math.isfinite(lat) and math.isfinite(lon)):
            continue
        tn = int(e.time_ns[i])
        known = bool(np.isfinite(cov[i]).all())
        kind = COVARIANCE_KNOWN if known else COVARIANCE_UNKNOWN
        _fix(fix, tn, "aided_ep", lat, lon, cov[i] if known else [0.0] * 9, kind)
        vals = {
            "radius_2m_m": _num(r),
            "semi_major_m": _num(e.semi_major_m[i]),
            "semi_minor_m": _num(e.semi_minor_m[i]),
            "orientation_deg": _num(math.degrees(e.orientation_rad[i])),
            "since_update_s": _num(e.since_update_s[i]),
            "update": e.update_kind[i],
        }
        err.add(tn, {"timestamp": _stamp(tn), "frame_id": "aided_ep", **vals})
        a, b = float(e.semi_major_m[i]), float(e.semi_minor_m[i])
        if not (math.isfinite(r) and r > 0 and math.isfinite(a) and math.isfinite(b) and b > 0):
            continue
        when = iso_utc(tn)
        rings = (
            (
                "circle",
                f"{FIX_UPDATED_EP} 2M {when[11:16]}Z {r:,.0f} m",
                ring_lonlat_deg(lat, lon, r, r, 0.0),
            ),
            (
                "ellipse",
                f"{FIX_UPDATED_EP} {ELLIPSE_SIGMA:g}-sigma ellipse {when[11:16]}Z",
                ring_lonlat_deg(
                    lat,
                    lon,
                    ELLIPSE_SIGMA * a,
                    ELLIPSE_SIGMA * b,
                    float(e.orientation_rad[i]),
                ),
            ),
        )
        features = [
            {
                "type": "Feature",
                "properties": {
                    "time_utc": when,
                    **vals,
                    "shape": shape,
                    "name": name,
                    "style": _AIDED_STYLE,
                },
                "geometry": {"type": "Polygon", "coordinates": [ring]},
            }
            for shape, name, ring in rings
        ]
        doc = {"type": "FeatureCollection", "features": features}
        poly.add(tn, {"geojson": json.dumps(doc, separators=(",", ":"), allow_nan=False)})
    return [fix, err, poly]


def _reference_stream(a: Analysis, dr: DRSection) -> Stream | None:
    ref = next((t for t in a.tracks if t.role is not None and t.role == dr.reference_role), None)
    if ref is None:
        return None
    sig2 = float(dr.reference_sigma_m) ** 2
    known = math.isfinite(sig2) and sig2 > 0
    cov = [sig2, 0.0, 0.0, 0.0, sig2, 0.0, 0.0, 0.0, 0.0] if known else [0.0] * 9
    kind = COVARIANCE_DIAGONAL_KNOWN if known else COVARIANCE_UNKNOWN
    s = Stream("/dracc/reference", LOCATION_FIX_SCHEMA)
    for tn, la, lo in zip(
        ref.time_ns.tolist(), ref.lat_rad.tolist(), ref.lon_rad.tolist(), strict=True
    ):
        _fix(s, tn, ref.source, la, lo, cov, kind)
    return s


def _deviation_streams(a: Analysis) -> list[Stream]:
    d = a.deviation
    if d is None:
        return []
    out = []
    for u in d.units:
        s = Stream(f"/dracc/deviation/{u}", DEVIATION_SCHEMA)
        cols = {CHANNEL_KEYS[c]: d.samples[u][c] for c in CHANNELS if c in d.samples[u]}
        for i, tn in enumerate(d.time_ns.tolist()):
            vals = {k: _num(v[i]) for k, v in cols.items()}
            if all(v is None for v in vals.values()):
                continue
            s.add(tn, {"timestamp": _stamp(tn), "frame_id": u, **vals})
        out.append(s)
    return out


def _current_stream(a: Analysis) -> list[Stream]:
    c = a.current
    if c is None:
        return []
    s = Stream("/dracc/current", CURRENT_SCHEMA)
    rows = zip(
        c.time_ns.tolist(),
        c.set_rad.tolist(),
        c.drift_mps.tolist(),
        c.drift_sigma_mps.tolist(),
        strict=True,
    )
    for tn, st, v, sv in rows:
        s.add(
            tn,
            {
                "timestamp": _stamp(tn),
                "frame_id": "current",
                "set_deg": _num(math.degrees(st) % 360.0),
                "drift_kn": _num(v / KN_MPS),
                "drift_sigma_kn": _num(sv / KN_MPS),
                "north_kn": _num(v * math.cos(st) / KN_MPS),
                "east_kn": _num(v * math.sin(st) / KN_MPS),
            },
        )
    return [s]


def mcap_streams(a: Analysis) -> list[Stream]:
    """Every channel of the export, in the order they are registered (empty ones left out)."""
    streams = _input_streams(a, _topic_names(a))
    dr = a.dead_reckoning
    if dr is not None:
        streams += _dr_streams(dr)
        if a.estimated_position is not None:  # the aided EP rides on the DR
            streams += _aided_streams(a.estimated_position)
        ref = _reference_stream(a, dr)
        if ref is not None:
            streams.append(ref)
    streams += _deviation_streams(a) + _current_stream(a)
    return [s for s in streams if s.messages]


# -------------------------------------------------------------------------- writer


def write_mcap_export(a: Analysis, path: str | Path) -> None:
    """Write the analysis as an MCAP for Foxglove at ``path``, atomically (a temporary
    file renamed into place; inside :func:`dracc.core.atomic.together`, with the other
    reports at the end of the block).  See the module's docstring for the channels."""
    from mcap.writer import CompressionType, IndexType, Writer

    streams = mcap_streams(a)
    times = [np.asarray(s.times, np.int64) for s in streams]
    t_all = np.concatenate(times) if times else np.zeros(0, np.int64)
    ch_all = np.repeat(np.arange(len(streams)), [t.size for t in times])
    row_all = np.concatenate([np.arange(t.size) for t in times]) if times else np.zeros(0, np.int64)
    order = np.lexsort((ch_all, t_all))  # one log-time order over every channel
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        w = Writer(
            fh,
            chunk_size=1 << 20,
            compression=CompressionType.ZSTD,
            index_types=IndexType.ALL,
        )
        w.start(profile="", library=f"dracc {__version__}")
        schema_ids: dict[str, int] = {}
        ids = []
        for s in streams:
            title = str(s.schema["title"])
            if title not in schema_ids:
                schema_ids[title] = w.register_schema(
                    name=title, encoding="jsonschema", data=json.dumps(s.schema).encode()
                )
            ids.append(
                w.register_channel(
                    topic=s.topic,
                    message_encoding="json",
                    schema_id=schema_ids[title],
                    metadata={"name": s.name} if s.name else {},
                )
            )
        seq = [0] * len(streams)
        for c, r, t in zip(
            ch_all[order].tolist(), row_all[order].tolist(), t_all[order].tolist(), strict=True
        ):
            w.add_message(
                channel_id=ids[c],
                log_time=t,
                data=streams[c].messages[r],
                publish_time=t,
                sequence=seq[c],
            )
            seq[c] += 1
        w.add_metadata(
            "dracc.export",
            {
                "dracc_version": a.dracc_version,
                "schema": a.schema,
                "inputs": "; ".join(f.path for f in a.inputs),
                "dr_step_s": f"{EXPORT_STEP_S:g}",
                "covariance": "ENU m^2 row-major 3x3, vertical not estimated (0)",
                "ellipse_sigma": f"{ELLIPSE_SIGMA:g}",
            },
        )
        w.finish()
