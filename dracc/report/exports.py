"""Exports for the tools navigators already run: GPX 1.1, KML 2.2 and GeoJSON (RFC 7946).

``dracc analyze ... --gpx F --kml F --geojson F`` (written atomically, renamed into place
together with the other reports by :func:`dracc.report.write.write_reports`).  Every export
holds up to three tracks, each split into one part per DR leg (restart to restart):

``ep``         the estimated position (the DR with the learned corrections and current),
               with its 2M (2 drms, B30 B31) and 1-sigma error ellipse at every point
``dr``         the water track (heading and log alone); when the analysis learned nothing
               the two are one track, ``dr``, and it carries the 2M
``reference``  the reference the DR is scored against (the GNSS fixes), cut at the legs'
               start times

and, where ``analyze`` computed it, the aided-DR estimated position of seeds/003
(``aided_ep``: its track and 2-sigma ellipses, :mod:`dracc.report.ep_exports`).

Track points are the full-rate DR rows thinned to one every :data:`TRACK_STEP_S` seconds
of each leg (a row is kept where the whole number of steps since the leg's first row
grows), plus each leg's first and last row; the reference is the source's positions as
the plots have them (``Analysis.tracks``: at most 4000 a source), a fix logged twice at
one instant written once.  Misses are the reporting epochs after a fix where the reference
lies outside 2M.  ``inside`` is the analysis's one judgement (``DRTrackResult.inside``):
the reference within the drawn 2M at a scored epoch, null where the epoch is not scored;
the fraction inside over the scored epochs is the report's containment.

GPX 1.1 (OpenCPN, chart plotters): ``trk`` per track, ``trkseg`` per leg, ``time`` per
point; the schema's own elements only, in its order, and dracc's values in
``extensions`` under the namespace :data:`NS_DRACC` (prefix ``dracc``)::

    <trkpt lat=".." lon=".."><time>..</time><extensions><dracc:uncertainty>
      <dracc:radius_2m_m/> <dracc:semi_major_m/> <dracc:semi_minor_m/>
      <dracc:orientation_deg/> <dracc:since_fix_s/> <dracc:ref_error_m/> (where known)
    </dracc:uncertainty></extensions></trkpt>

with ``<dracc:leg index=".." fix_source=".."/>`` in each ``trkseg``'s extensions and a
``wpt`` at each miss (at the estimated position, ``type`` "2M miss").

KML 2.2 (Google Earth): a ``gx:MultiTrack`` per track (a ``gx:Track`` per leg, ``when``
per point: the time slider), the EP's 2M and 1-sigma semi-axes as ``gx:SimpleArrayData``
(:data:`KML_ARRAYS`); the 2M circles at the reporting epochs as polygons shown over
[epoch, next epoch of the leg); misses as points with their ``TimeStamp``.  The reference comes last, so it is drawn above the DR.

GeoJSON (RFC 7946: WGS-84, longitude before latitude): a ``LineString`` per track and
leg, and per reporting epoch two ``Polygon`` features, the 2M circle (``shape``
"circle") and the 2-sigma error ellipse (``shape`` "ellipse", semi-axes twice the
1-sigma ones), their vertices computed on the ellipsoid (:mod:`dracc.core.geodesy`),
rings closed and counter-clockwise, cut at the antimeridian.  Properties: ``time_utc``,
``leg``, ``since_fix_s``, ``radius_2m_m``, ``semi_major_m``, ``semi_minor_m`` (1 sigma),
``orientation_deg`` (major axis, clockwise from north), ``ref_error_m``, ``inside``
(null without a reference), ``scored``.
"""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from dracc import __version__
from dracc.core import atomic
from dracc.core.geodesy import offset_ne_m
from dracc.core.safetext import printable
from dracc.core.timefmt import iso_utc
from dracc.core.vocabulary import DR_OVER_GROUND, WATER_TRACK
from dracc.pipeline.results import Analysis, DRSection, DRTrackResult, Track
from dracc.report import ep_exports
from dracc.report.ep_exports import (
    CIRCLE_VERTICES,
    ELLIPSE_SCALE,
    NS_GX,
    NS_KML,
    kml_polygon,
    polygon_geometry,
    ring_deg,
)
from dracc.report.ep_exports import deg as _deg
from dracc.report.ep_exports import latlon_attrs as _latlon
from dracc.report.ep_exports import line_geometry as _line_geometry
from dracc.report.ep_exports import nullable as _nullable
from dracc.report.ep_exports import num_text as _num
from dracc.report.ep_exports import sub_element as _sub
from dracc.report.ep_exports import xml_text as _text

__all__ = [
    "CIRCLE_VERTICES",
    "ELLIPSE_SCALE",
    "NS_DRACC",
    "TRACK_STEP_S",
    "write_geojson",
    "write_gpx",
    "write_kml",
]

#: the GPX extension namespace of dracc's values (prefix ``dracc``)
NS_DRACC = "https://dracc.example/gpx/1"
NS_GPX = "http://www.topografix.com/GPX/1/1"
NS_XSI = "http://www.w3.org/2001/XMLSchema-instance"
#: seconds between exported track points (each leg's first and last row always)
TRACK_STEP_S = 10.0
#: the per-point uncertainty values, in the order written
UNCERTAINTY = ("radius_2m_m", "semi_major_m", "semi_minor_m", "orientation_deg", "since_fix_s")
#: those of them a KML track carries per point (Google Earth's elevation profile shows them)
KML_ARRAYS = ("radius_2m_m", "semi_major_m", "semi_minor_m")

_WHAT = {
    "ep": f"{DR_OVER_GROUND}: the {WATER_TRACK} plus the current and the compass and log "
    "corrections learned from earlier fixes",
    "dr": f"{WATER_TRACK}: the dead reckoning from heading and log alone, no current",
    "reference": "the reference the DR is scored against",
}


# ------------------------------------------------------------------ what is exported


@dataclass(frozen=True)
class _Part:
    """One leg of one track: times, degrees and (EP/DR) the uncertainty per point."""

    leg: int | None
    time_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    values: dict[str, np.ndarray] | None  #: UNCERTAINTY (+ ref_error_m), or None
    fix_source: str | None = None


@dataclass(frozen=True)
class _Line:
    key: str  #: 'ep', 'dr' or 'reference'
    name: str
    parts: tuple[_Part, ...]


def export_rows(tr: DRTrackResult, step_s: float = TRACK_STEP_S) -> np.ndarray:
    """Indices of the full-rate rows exported: one each ``step_s`` of every leg, and each
    leg's first and last row."""
    leg = np.asarray(tr.leg, dtype=np.int64)
    t = np.asarray(tr.time_ns, dtype=np.int64)
    ok = (leg >= 0) & np.isfinite(tr.lat_rad) & np.isfinite(tr.lon_rad)
    idx = np.flatnonzero(ok)
    if idx.size == 0:
        return idx
    leg, t = leg[idx], t[idx]
    first = np.r_[True, leg[1:] != leg[:-1]]
    last = np.r_[leg[1:] != leg[:-1], True]
    start = t[np.maximum.accumulate(np.where(first, np.arange(t.size), 0))]
    steps = np.floor((t - start) / (step_s * 1e9)).astype(np.int64)
    grows = np.r_[False, steps[1:] > steps[:-1]]
    return idx[first | last | grows]


def _values(tr: DRTrackResult, idx: np.ndarray) -> dict[str, np.ndarray]:
    return {
        "radius_2m_m": np.asarray(tr.radius_2m_m, float)[idx],
        "semi_major_m": np.asarray(tr.semi_major_m, float)[idx],
        "semi_minor_m": np.asarray(tr.semi_minor_m, float)[idx],
        "orientation_deg": np.degrees(np.asarray(tr.orientation_rad, float)[idx]),
        "since_fix_s": np.asarray(tr.since_fix_s, float)[idx],
        "ref_error_m": np.asarray(tr.ref_error_m, float)[idx],
    }


def water_differs(tr: DRTrackResult) -> bool:
    """Whether the water track is a track of its own (more than 0.5 m from the DR over the
    ground)."""
    if not len(tr.time_ns):
        return False
    n, e = offset_ne_m(tr.water_lat_rad, tr.water_lon_rad, tr.lat_rad, tr.lon_rad)
    with np.errstate(invalid="ignore"):
        return bool(np.any(np.hypot(n, e) > 0.5))


def reference_track(a: Analysis) -> Track | None:
    """The positions of the reference: the DR's fix source, else the first GNSS source."""
    dr = a.dead_reckoning
    key = dr.fix_source_key if dr is not None else None
    for t in a.tracks:
        if key is not None and t.source == key:
            return t
    if dr is not None and dr.reference_role not in (None, "gnss"):
        return None  # the INS mean: no one source holds it
    return next((t for t in a.tracks if t.role == "gnss"), None)


def _lines(a: Analysis) -> list[_Line]:
    """The tracks to export, in drawing order (the reference last, on top)."""
    lines: list[_Line] = []
    dr = a.dead_reckoning
    starts: list[int] = []
    leg_ids: list[int] = []
    ends = 0
    if dr is not None and len(dr.track.time_ns):
        tr = dr.track
        rows = export_rows(tr)
        legs = np.asarray(tr.leg, dtype=np.int64)[rows]
        fix = {leg.index: leg.fix_source for leg in dr.legs}
        split = [rows[legs == k] for k in dict.fromkeys(legs.tolist())]
        starts = [int(tr.time_ns[r[0]]) for r in split]
        leg_ids = [int(tr.leg[r[0]]) for r in split]
        ends = int(tr.time_ns[split[-1][-1]]) if split else 0
        both = water_differs(tr)

        def parts(water: bool, values: bool) -> tuple[_Part, ...]:
            out = []
            for r in split:
                k = int(tr.leg[r[0]])
                lat, lon = (
                    _deg(tr.water_lat_rad[r], tr.water_lon_rad[r])
                    if water
                    else _deg(tr.lat_rad[r], tr.lon_rad[r])
                )
                vals = _values(tr, r) if values else None
                out.append(_Part(k, tr.time_ns[r], lat, lon, vals, fix.get(k)))
            return tuple(out)

        if both:
            lines.append(_Line("dr", WATER_TRACK, parts(water=True, values=False)))
            lines.append(_Line("ep", DR_OVER_GROUND, parts(water=False, values=True)))
        else:
            lines.append(_Line("dr", WATER_TRACK, parts(water=False, values=True)))
    ref = reference_track(a)
    if ref is not None and len(ref.time_ns):
        t = np.asarray(ref.time_ns, dtype=np.int64)
        ok = np.isfinite(ref.lat_rad) & np.isfinite(ref.lon_rad)
        # a fix logged twice (GGA and RMC of one instant) is one point
        ok[1:] &= ~(
            (t[1:] == t[:-1])
            & (ref.lat_rad[1:] == ref.lat_rad[:-1])
            & (ref.lon_rad[1:] == ref.lon_rad[:-1])
        )
        lat, lon = _deg(ref.lat_rad, ref.lon_rad)
        pieces: list[_Part] = []
        if starts:
            bounds = [*starts[1:], ends + 1]
            for k, lo, hi in zip(leg_ids, starts, bounds, strict=True):
                sel = ok & (t >= lo) & (t < hi)
                pieces.append(_Part(k, t[sel], lat[sel], lon[sel], None))
        else:
            pieces.append(_Part(None, t[ok], lat[ok], lon[ok], None))
        name = f"reference ({dr.reference_role if dr else ref.role}: {ref.source})"
        lines.append(_Line("reference", name, tuple(pieces)))
    return lines


def inside_flags(dr: DRSection) -> tuple[np.ndarray, np.ndarray]:
    """(judged, inside) at each reporting epoch: the section's one judgement of the
    reference against the drawn 2M (``DRTrackResult.inside``); not judged where the epoch
    is not scored (at the fix, before anything was learned, no reference)."""
    v = np.asarray(dr.epochs.inside, float)
    judged = np.isfinite(v)
    return judged, judged & (v == 1.0)


def misses(dr: DRSection) -> np.ndarray:
    """Indices of the scored reporting epochs with the reference outside 2M."""
    judged, inside = inside_flags(dr)
    return np.flatnonzero(judged & ~inside)


def _miss_text(dr: DRSection, i: int) -> str:
    ep = dr.epochs
    return (
        f"reference ({dr.reference_role}) {float(ep.ref_error_m[i]):,.0f} m from the "
        f"{DR_OVER_GROUND if water_differs(dr.track) else WATER_TRACK}, "
        f"outside its 2M of {float(ep.radius_2m_m[i]):,.0f} m "
        f"(leg {int(ep.leg[i])}, {float(ep.since_fix_s[i]) / 60:.0f} min after the fix)"
    )


def _title(a: Analysis) -> str:
    names = ", ".join(Path(f.path).name for f in a.inputs[:3])
    more = f" and {len(a.inputs) - 3} more" if len(a.inputs) > 3 else ""
    return f"dracc: {names}{more}" if names else "dracc"


def _describe(a: Analysis) -> str:
    dr = a.dead_reckoning
    when = f"{iso_utc(a.start_ns)} to {iso_utc(a.end_ns)}" if a.start_ns is not None else ""
    return "; ".join(s for s in (when, dr.verdict if dr is not None else "") if s)


# --------------------------------------------------------------------------- GPX


def _uncertainty(values: dict[str, float]) -> str:
    """The ``extensions`` element of a point: dracc's values that are known."""
    inner = "".join(
        f"<dracc:{name}>{_num(v)}</dracc:{name}>"
        for name in (*UNCERTAINTY, "ref_error_m")
        if math.isfinite(v := values.get(name, math.nan))
    )
    return f"<extensions><dracc:uncertainty>{inner}</dracc:uncertainty></extensions>"


def gpx_document(a: Analysis) -> bytes:
    """The GPX 1.1 document (UTF-8 bytes; written as text, the points being most of it)."""
    out = [
        "<?xml version='1.0' encoding='utf-8'?>\n",
        f'<gpx xmlns="{NS_GPX}" xmlns:dracc="{NS_DRACC}" xmlns:xsi="{NS_XSI}" '
        f'version="1.1" creator={quoteattr(f"dracc {__version__}")} '
        f'xsi:schemaLocation="{NS_GPX} http://www.topografix.com/GPX/1/1/gpx.xsd">',
    ]
    lines = _lines(a)
    out.append("<metadata>" + _text("name", _title(a)))
    desc = _describe(a)
    if desc:
        out.append(_text("desc", desc))
    aided = a.estimated_position if a.dead_reckoning is not None else None  # rides on the DR
    la, lo = _deg(aided.lat_rad, aided.lon_rad) if aided is not None else (np.zeros(0),) * 2
    lats = np.concatenate([p.lat_deg for ln in lines for p in ln.parts] + [la])
    lons = np.concatenate([p.lon_deg for ln in lines for p in ln.parts] + [lo])
    lats, lons = lats[np.isfinite(lats)], lons[np.isfinite(lons)]
    if lats.size:
        out.append(
            f'<bounds minlat="{_num(lats.min(), 8)}" minlon="{_num(lons.min(), 8)}" '
            f'maxlat="{_num(lats.max(), 8)}" maxlon="{_num(lons.max(), 8)}"/>'
        )
    out.append("</metadata>\n")
    dr = a.dead_reckoning
    if dr is not None:
        ep = dr.epochs
        lat, lon = _deg(ep.lat_rad, ep.lon_rad)
        for i in misses(dr):
            when = iso_utc(int(ep.time_ns[i]))
            vals = _values(ep, np.array([i]))
            out.append(
                f"<wpt {_latlon(lat[i], lon[i])}>"
                + _text("time", when)
                + _text("name", f"2M miss {when[11:16]}")
                + _text("desc", _miss_text(dr, int(i)))
                + _text("sym", "Danger Area")
                + _text("type", "2M miss")
                + _uncertainty({k: float(v[0]) for k, v in vals.items()})
                + "</wpt>\n"
            )
    for ln in lines:
        if ln.key == "reference" and aided is not None:  # the aided EP below the reference
            out.append(ep_exports.gpx_track(aided, f"dracc {__version__}"))
            aided = None
        out.append(
            "<trk>"
            + _text("name", ln.name)
            + _text("desc", _WHAT[ln.key])
            + _text("src", f"dracc {__version__}")
            + _text("type", ln.key)
            + "\n"
        )
        for part in ln.parts:
            out.append("<trkseg>\n")
            times = iso_utc(np.asarray(part.time_ns, dtype=np.int64), unit="auto")
            cols = list(part.values.items()) if part.values is not None else []
            for j in range(part.time_ns.size):
                ext = _uncertainty({k: float(v[j]) for k, v in cols}) if cols else ""
                out.append(
                    f"<trkpt {_latlon(part.lat_deg[j], part.lon_deg[j])}>"
                    f"<time>{times[j]}</time>{ext}</trkpt>\n"
                )
            if part.leg is not None:
                fix = (
                    f" fix_source={quoteattr(printable(part.fix_source))}"
                    if part.fix_source
                    else ""
                )
                out.append(f'<extensions><dracc:leg index="{part.leg}"{fix}/></extensions>')
            out.append("</trkseg>\n")
        out.append("</trk>\n")
    if aided is not None:
        out.append(ep_exports.gpx_track(aided, f"dracc {__version__}"))
    out.append("</gpx>\n")
    return "".join(out).encode("utf-8")


def write_gpx(a: Analysis, path: str | Path) -> None:
    """Write the GPX 1.1 export to ``path`` (atomically)."""
    atomic.write_bytes(path, gpx_document(a))


# ---------------------------------------------------------------------- polygons


def _epoch_shapes(dr: DRSection) -> list[tuple[int, str, np.ndarray, np.ndarray]]:
    """(epoch, 'circle' | 'ellipse', lat ring, lon ring) for every drawable epoch."""
    ep = dr.epochs
    out = []
    for i in range(len(ep.time_ns)):
        lat, lon = float(ep.lat_rad[i]), float(ep.lon_rad[i])
        r = float(ep.radius_2m_m[i])
        a, b = float(ep.semi_major_m[i]), float(ep.semi_minor_m[i])
        if not (math.isfinite(lat) and math.isfinite(lon)):
            continue
        if math.isfinite(r) and r > 0:
            out.append((i, "circle", *ring_deg(lat, lon, r, r, 0.0)))
        if math.isfinite(a) and math.isfinite(b) and b > 0:
            s = ELLIPSE_SCALE
            out.append(
                (i, "ellipse", *ring_deg(lat, lon, s * a, s * b, float(ep.orientation_rad[i])))
            )
    return out


# ----------------------------------------------------------------------- GeoJSON


def geojson_document(a: Analysis) -> dict[str, Any]:
    """The GeoJSON FeatureCollection (RFC 7946)."""
    features: list[dict[str, Any]] = []
    for ln in _lines(a):
        for part in ln.parts:
            geom = _line_geometry(part.lat_deg, part.lon_deg)
            if geom is None:
                continue  # a leg of one point is no line
            features.append(
                {
                    "type": "Feature",
                    "geometry": geom,
                    "properties": {
                        "kind": "track",
                        "track": ln.key,
                        "name": ln.name,
                        "leg": part.leg,
                        "start_utc": iso_utc(int(part.time_ns[0])),
                        "end_utc": iso_utc(int(part.time_ns[-1])),
                    },
                }
            )
    dr = a.dead_reckoning
    if dr is not None:
        ep = dr.epochs
        has, inside = inside_flags(dr)
        for i, shape, lat, lon in _epoch_shapes(dr):
            features.append(
                {
                    "type": "Feature",
                    "geometry": polygon_geometry(lat, lon),
                    "properties": {
                        "kind": "2m_circle" if shape == "circle" else "ellipse_2sigma",
                        "shape": shape,
                        "scale": 1.0 if shape == "circle" else ELLIPSE_SCALE,
                        "time_utc": iso_utc(int(ep.time_ns[i])),
                        "leg": int(ep.leg[i]),
                        "since_fix_s": float(ep.since_fix_s[i]),
                        "radius_2m_m": _nullable(float(ep.radius_2m_m[i])),
                        "semi_major_m": _nullable(float(ep.semi_major_m[i])),
                        "semi_minor_m": _nullable(float(ep.semi_minor_m[i])),
                        "orientation_deg": _nullable(math.degrees(float(ep.orientation_rad[i]))),
                        "ref_error_m": _nullable(float(ep.ref_error_m[i])),
                        "inside": bool(inside[i]) if has[i] else None,
                        "scored": bool(ep.scored[i]),
                    },
                }
            )
    if a.estimated_position is not None and dr is not None:  # the EP rides on the DR
        features += ep_exports.geojson_features(a.estimated_position)
    return {
        "type": "FeatureCollection",
        "name": _title(a),
        "generator": f"dracc {__version__}",
        "features": features,
    }


def write_geojson(a: Analysis, path: str | Path) -> None:
    """Write the GeoJSON export to ``path`` (atomically)."""
    text = json.dumps(geojson_document(a), separators=(",", ":"), allow_nan=False)
    atomic.write_text(path, text + "\n")


# --------------------------------------------------------------------------- KML

#: KML colours are aabbggrr
_STYLES = {
    "dr": ("ff7f7f7f", 2.0),
    "ep": ("ff000000", 2.5),
    "reference": ("ffb4771f", 3.5),  # #1f77b4, wider: drawn last, above the DR
}


def _kml_styles(doc: ET.Element) -> None:
    k = NS_KML
    for sid, (colour, width) in _STYLES.items():
        st = _sub(doc, f"{{{k}}}Style", id=sid)
        ls = _sub(st, f"{{{k}}}LineStyle")
        _sub(ls, f"{{{k}}}color", colour)
        _sub(ls, f"{{{k}}}width", _num(width))
    for sid, line, fill in (
        ("circle", "ff0e7fff", "330e7fff"),
        ("circle_miss", "ff2827d6", "402827d6"),
    ):
        st = _sub(doc, f"{{{k}}}Style", id=sid)
        ls = _sub(st, f"{{{k}}}LineStyle")
        _sub(ls, f"{{{k}}}color", line)
        _sub(ls, f"{{{k}}}width", "1.5")
        ps = _sub(st, f"{{{k}}}PolyStyle")
        _sub(ps, f"{{{k}}}color", fill)
    st = _sub(doc, f"{{{k}}}Style", id="miss")
    ic = _sub(st, f"{{{k}}}IconStyle")
    _sub(ic, f"{{{k}}}color", "ff2827d6")
    icon = _sub(ic, f"{{{k}}}Icon")
    _sub(icon, f"{{{k}}}href", "http://maps.google.com/mapfiles/kml/shapes/caution.png")


def _kml_schema(doc: ET.Element) -> None:
    """The per-point arrays' schema.  OGC KML 2.2 puts a Document's ``Schema`` after its
    styles (a feature's ``StyleSelector``) and before its features; each
    ``gx:SimpleArrayField`` stands in the schema's ``kml:SchemaExtension`` slot."""
    k = NS_KML
    schema = _sub(doc, f"{{{k}}}Schema", id="uncertainty", name="uncertainty")
    for name in KML_ARRAYS:
        f = _sub(schema, f"{{{NS_GX}}}SimpleArrayField", name=name, type="float")
        _sub(f, f"{{{k}}}displayName", name)


def _kml_track(folder: ET.Element, ln: _Line) -> None:
    k, gx = NS_KML, NS_GX
    pm = _sub(folder, f"{{{k}}}Placemark")
    _sub(pm, f"{{{k}}}name", ln.name)
    _sub(pm, f"{{{k}}}description", _WHAT[ln.key])
    _sub(pm, f"{{{k}}}styleUrl", f"#{ln.key}")
    multi = _sub(pm, f"{{{gx}}}MultiTrack")
    _sub(multi, f"{{{gx}}}interpolate", "0")
    for part in ln.parts:
        if not part.time_ns.size:
            continue
        trk = _sub(multi, f"{{{gx}}}Track")
        for when in iso_utc(np.asarray(part.time_ns, dtype=np.int64)):
            _sub(trk, f"{{{k}}}when", str(when))
        for la, lo in zip(part.lat_deg, part.lon_deg, strict=True):
            _sub(trk, f"{{{gx}}}coord", f"{_num(lo, 8)} {_num(la, 8)} 0")
        if part.values is not None:
            ext = _sub(trk, f"{{{k}}}ExtendedData")
            sd = _sub(ext, f"{{{k}}}SchemaData", schemaUrl="#uncertainty")
            for name in KML_ARRAYS:
                arr = _sub(sd, f"{{{gx}}}SimpleArrayData", name=name)
                for v in part.values[name]:
                    _sub(arr, f"{{{gx}}}value", _num(float(v)))


def kml_document(a: Analysis) -> bytes:
    """The KML 2.2 document (UTF-8 bytes)."""
    k = NS_KML
    ET.register_namespace("", NS_KML)
    ET.register_namespace("gx", NS_GX)
    root = ET.Element(f"{{{k}}}kml")
    doc = _sub(root, f"{{{k}}}Document")
    _sub(doc, f"{{{k}}}name", _title(a))
    desc = _describe(a)
    if desc:
        _sub(doc, f"{{{k}}}description", desc)
    _kml_styles(doc)
    if a.estimated_position is not None and a.dead_reckoning is not None:
        ep_exports.kml_styles(doc)
    _kml_schema(doc)  # after every style, before the folders (the OGC schema's order)
    dr = a.dead_reckoning
    if dr is not None:
        ep = dr.epochs
        has, inside = inside_flags(dr)
        folder = _sub(doc, f"{{{k}}}Folder")
        _sub(folder, f"{{{k}}}name", "2M circles at the reporting epochs")
        t = np.asarray(ep.time_ns, dtype=np.int64)
        legs = np.asarray(ep.leg, dtype=np.int64)
        ends = {leg.index: int(leg.end_ns) for leg in dr.legs}
        step = int(dr.epoch_interval_s * 1e9)
        for i, shape, lat, lon in _epoch_shapes(dr):
            if shape != "circle":
                continue
            nxt = i + 1 < t.size and legs[i + 1] == legs[i]
            end = int(t[i + 1]) if nxt else max(ends.get(int(legs[i]), 0), int(t[i]) + step)
            pm = _sub(folder, f"{{{k}}}Placemark")
            _sub(pm, f"{{{k}}}name", f"2M {iso_utc(int(t[i]))[11:16]}")
            span = _sub(pm, f"{{{k}}}TimeSpan")
            _sub(span, f"{{{k}}}begin", iso_utc(int(t[i])))
            _sub(span, f"{{{k}}}end", iso_utc(end))
            miss = bool(has[i] and not inside[i])
            _sub(pm, f"{{{k}}}styleUrl", "#circle_miss" if miss else "#circle")
            ext = _sub(pm, f"{{{k}}}ExtendedData")
            for name, value in (
                ("radius_2m_m", ep.radius_2m_m[i]),
                ("semi_major_m", ep.semi_major_m[i]),
                ("semi_minor_m", ep.semi_minor_m[i]),
                ("orientation_deg", math.degrees(float(ep.orientation_rad[i]))),
                ("ref_error_m", ep.ref_error_m[i]),
                ("leg", legs[i]),
            ):
                d = _sub(ext, f"{{{k}}}Data", name=name)
                _sub(d, f"{{{k}}}value", _num(float(value)))
            kml_polygon(pm, lon, lat)
        found = misses(dr)
        if found.size:
            folder = _sub(doc, f"{{{k}}}Folder")
            _sub(folder, f"{{{k}}}name", "2M misses (reference outside 2M)")
            lat_d, lon_d = _deg(ep.lat_rad, ep.lon_rad)
            for i in found:
                pm = _sub(folder, f"{{{k}}}Placemark")
                _sub(pm, f"{{{k}}}name", f"miss {iso_utc(int(t[i]))[11:16]}")
                _sub(pm, f"{{{k}}}description", _miss_text(dr, int(i)))
                stamp = _sub(pm, f"{{{k}}}TimeStamp")
                _sub(stamp, f"{{{k}}}when", iso_utc(int(t[i])))
                _sub(pm, f"{{{k}}}styleUrl", "#miss")
                pt = _sub(pm, f"{{{k}}}Point")
                _sub(pt, f"{{{k}}}coordinates", f"{_num(lon_d[i], 8)},{_num(lat_d[i], 8)},0")
    if a.estimated_position is not None and dr is not None:  # the EP rides on the DR
        ep_exports.kml_parts(doc, a.estimated_position)
    folder = _sub(doc, f"{{{k}}}Folder")
    _sub(folder, f"{{{k}}}name", "Tracks")
    for ln in _lines(a):  # the reference last: drawn above the DR
        _kml_track(folder, ln)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def write_kml(a: Analysis, path: str | Path) -> None:
    """Write the KML 2.2 export to ``path`` (atomically)."""
    atomic.write_bytes(path, kml_document(a))
