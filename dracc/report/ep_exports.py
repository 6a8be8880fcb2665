"""The fix-updated EP (seeds/003's aided DR, :class:`EstimatedPositionSection`) in the GPX,
KML and GeoJSON exports, and the drawing primitives every export shares.

:mod:`dracc.report.exports` calls it: the EP is its own track, ``aided_ep``, beside the DR's
(``ep``, ``dr``, ``reference``), one part per stretch of DR (a stretch starts at its start fix:
the row with no time since an update and no update, :func:`stretch_starts`).

- GPX: a ``trk`` (``type`` "aided_ep"), a ``trkseg`` per stretch, a ``trkpt`` per EP epoch
  with ``<dracc:uncertainty>``: ``radius_2m_m`` (2 drms, B30 B31), ``semi_major_m``,
  ``semi_minor_m`` (1 sigma), ``orientation_deg``, ``since_update_s``, and ``<dracc:update>``
  (the updates applied since the row before: 'gnss', 'bearing 1') where there was one.
- KML: a folder of its own (before the tracks', so the reference is drawn above it): a
  ``gx:MultiTrack`` (a ``gx:Track`` per stretch) and the 2-sigma error ellipses (the
  1-sigma semi-axes times :data:`ELLIPSE_SCALE`, as the GeoJSON's) as polygons, each
  shown over [epoch, next epoch of the stretch).
- GeoJSON: a ``LineString`` per stretch and a ``Polygon`` per epoch (the 2-sigma ellipse).

Rings: vertices on the ellipsoid (:func:`dracc.core.geodesy.add_offset_ne`), closed and
counter-clockwise, cut at the antimeridian for GeoJSON (RFC 7946 3.1.9).
"""

from __future__ import annotations

import itertools
import math
import xml.etree.ElementTree as ET
from typing import Any
from xml.sax.saxutils import escape

import numpy as np

from dracc.core.geodesy import add_offset_ne
from dracc.core.safetext import printable
from dracc.core.timefmt import iso_utc
from dracc.core.vocabulary import AIDED_DR_PAPER, FIX_UPDATED_EP, WATER_TRACK
from dracc.pipeline.results import EstimatedPositionSection

__all__ = [
    "AIDED_KEY",
    "AIDED_NAME",
    "AIDED_VALUES",
    "CIRCLE_VERTICES",
    "ELLIPSE_SCALE",
    "NS_GX",
    "NS_KML",
    "geojson_features",
    "gpx_track",
    "kml_parts",
    "kml_styles",
    "polygon_geometry",
    "ring_deg",
    "stretch_starts",
]

NS_KML = "http://www.opengis.net/kml/2.2"
NS_GX = "http://www.google.com/kml/ext/2.2"
#: vertices of a circle or ellipse polygon (the ring closes with a repeat of the first)
CIRCLE_VERTICES = 72
#: the exported ellipse is the 1-sigma one times this (2 sigma, as 2M is 2 drms)
ELLIPSE_SCALE = 2.0
#: the aided EP's track key ('type' in GPX, 'track' in GeoJSON, the KML style)
AIDED_KEY = "aided_ep"
#: its name in every export (the track, the KML folder) and in the plots' legends
AIDED_NAME = FIX_UPDATED_EP
AIDED_WHAT = (
    f"{FIX_UPDATED_EP}: the {WATER_TRACK} plus a Gauss-Markov current, updated at each GNSS "
    f"fix and the observation file's lines of position (the filter of {AIDED_DR_PAPER})"
)
#: the per-point values of the aided EP, in the order written
AIDED_VALUES = ("radius_2m_m", "semi_major_m", "semi_minor_m", "orientation_deg", "since_update_s")


# ---------------------------------------------------------------- shared primitives


def num_text(x: float, digits: int = 6) -> str:
    """``x`` with at most ``digits`` decimals, trailing zeros dropped; 'nan' if not finite."""
    return f"{x:.{digits}f}".rstrip("0").rstrip(".") if math.isfinite(x) else "nan"


def xml_text(tag: str, text: str) -> str:
    return f"<{tag}>{escape(printable(text))}</{tag}>"


def latlon_attrs(lat: float, lon: float) -> str:
    return f'lat="{num_text(lat, 8)}" lon="{num_text(lon, 8)}"'


def sub_element(parent: ET.Element, tag: str, text: str | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, {k: printable(v) for k, v in attrib.items()})
    if text is not None:
        el.text = printable(text)  # a control character from a log is no XML
    return el


def kml_polygon(pm: ET.Element, lon_deg: Any, lat_deg: Any) -> None:
    """A tessellated KML Polygon of one ring (lon, lat degrees) inside placemark ``pm``."""
    k = NS_KML
    poly = sub_element(pm, f"{{{k}}}Polygon")
    sub_element(poly, f"{{{k}}}tessellate", "1")
    ring = sub_element(sub_element(poly, f"{{{k}}}outerBoundaryIs"), f"{{{k}}}LinearRing")
    coords = " ".join(
        f"{num_text(x, 8)},{num_text(y, 8)},0" for x, y in zip(lon_deg, lat_deg, strict=True)
    )
    sub_element(ring, f"{{{k}}}coordinates", coords)


def deg(lat_rad: np.ndarray, lon_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Degrees, the longitude in [-180, 180) (GPX)."""
    lon = np.degrees(np.asarray(lon_rad, float))
    lon = np.mod(lon + 180.0, 360.0) - 180.0
    return np.degrees(np.asarray(lat_rad, float)), lon


def nullable(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def ring_deg(
    lat_rad: float,
    lon_rad: float,
    semi_major_m: float,
    semi_minor_m: float,
    orientation_rad: float,
    n: int = CIRCLE_VERTICES,
) -> tuple[np.ndarray, np.ndarray]:
    """A closed counter-clockwise ring (lat, lon in degrees, n + 1 points; longitudes
    continuous around the centre, possibly beyond +-180) of the ellipse with these
    semi-axes, the major one at ``orientation_rad`` clockwise from north; equal axes make
    a circle.  Each vertex is the point on the ellipsoid at its north/east offset."""
    t = -np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)  # clockwise in (u, v): see below
    ca, sa = math.cos(orientation_rad), math.sin(orientation_rad)
    u, v = semi_major_m * np.cos(t), semi_minor_m * np.sin(t)
    north = u * ca - v * sa
    east = u * sa + v * ca
    if np.sum(east * np.roll(north, -1) - np.roll(east, -1) * north) < 0:  # keep it CCW
        north, east = north[::-1], east[::-1]
    lat, lon = add_offset_ne(lat_rad, lon_rad, north, east)
    lon = np.degrees(lon_rad + np.angle(np.exp(1j * (lon - lon_rad))))
    lat = np.degrees(lat)
    return np.r_[lat, lat[0]], np.r_[lon, lon[0]]


def _clip(ring: list[tuple[float, float]], keep_west: bool) -> list[tuple[float, float]]:
    """Sutherland-Hodgman: the part of a (lon, lat) ring west (or east) of lon 180."""
    out: list[tuple[float, float]] = []
    pts = ring[:-1]

    def inside(p: tuple[float, float]) -> bool:
        return p[0] <= 180.0 if keep_west else p[0] >= 180.0

    for k, cur in enumerate(pts):
        prev = pts[k - 1]
        if inside(cur) != inside(prev):
            f = (180.0 - prev[0]) / (cur[0] - prev[0])
            out.append((180.0, prev[1] + f * (cur[1] - prev[1])))
        if inside(cur):
            out.append(cur)
    return [*out, out[0]] if len(out) >= 3 else []


def polygon_geometry(lat_deg: np.ndarray, lon_deg: np.ndarray) -> dict[str, Any]:
    """A GeoJSON Polygon of a ring, or a MultiPolygon of its two halves where it crosses
    the antimeridian (RFC 7946 3.1.9)."""
    lon = np.asarray(lon_deg, float)
    shift = 360.0 if lon.min() < -180.0 else 0.0  # bring a crossing to +180
    ring = [(float(x) + shift, float(y)) for x, y in zip(lon, lat_deg, strict=True)]
    if max(p[0] for p in ring) <= 180.0:
        return {"type": "Polygon", "coordinates": [[_pos(x, y) for x, y in ring]]}
    west = _clip(ring, keep_west=True)
    east = [(x - 360.0, y) for x, y in _clip(ring, keep_west=False)]
    polys = [[[_pos(x, y) for x, y in part]] for part in (west, east) if part]
    return {"type": "MultiPolygon", "coordinates": polys}


def _pos(lon: float, lat: float) -> list[float]:
    return [round(lon, 8), round(lat, 8)]


def line_geometry(lat_deg: np.ndarray, lon_deg: np.ndarray) -> dict[str, Any] | None:
    """A LineString, or a MultiLineString cut where it crosses the antimeridian."""
    if lat_deg.size < 2:
        return None
    parts: list[list[list[float]]] = [[_pos(lon_deg[0], lat_deg[0])]]
    for k in range(1, lat_deg.size):
        x0, x1, y0, y1 = lon_deg[k - 1], lon_deg[k], lat_deg[k - 1], lat_deg[k]
        if abs(x1 - x0) > 180.0:  # across the antimeridian, the short way
            edge = 180.0 if x0 > 0 else -180.0
            x1u = x1 + (360.0 if x0 > 0 else -360.0)
            y = y0 + (edge - x0) / (x1u - x0) * (y1 - y0)
            parts[-1].append(_pos(edge, y))
            parts.append([_pos(-edge, y)])
        parts[-1].append(_pos(x1, y1))
    parts = [p for p in parts if len(p) >= 2]
    if len(parts) == 1:
        return {"type": "LineString", "coordinates": parts[0]}
    return {"type": "MultiLineString", "coordinates": parts}


# ------------------------------------------------------------------ the aided EP


def stretch_starts(e: EstimatedPositionSection) -> np.ndarray:
    """Indices of the rows that start a stretch of DR: at its start fix (no time since an
    update, no update applied), as :func:`dracc.math.ep.aided.epoch_rows` writes them."""
    kinds = np.array([k == "" for k in e.update_kind], dtype=bool)
    start = (np.asarray(e.since_update_s, float) == 0.0) & kinds
    if start.size:
        start[0] = True
    return np.flatnonzero(start)


def _stretches(e: EstimatedPositionSection) -> list[np.ndarray]:
    """Row indices of each stretch (rows with a position only)."""
    n = len(e.time_ns)
    bounds = [*stretch_starts(e).tolist(), n]
    ok = np.isfinite(e.lat_rad) & np.isfinite(e.lon_rad)
    parts = [np.arange(lo, hi) for lo, hi in itertools.pairwise(bounds)]
    return [p[ok[p]] for p in parts if ok[p].any()]


def _values(e: EstimatedPositionSection, i: int) -> dict[str, float]:
    return {
        "radius_2m_m": float(e.radius_2m_m[i]),
        "semi_major_m": float(e.semi_major_m[i]),
        "semi_minor_m": float(e.semi_minor_m[i]),
        "orientation_deg": math.degrees(float(e.orientation_rad[i])),
        "since_update_s": float(e.since_update_s[i]),
    }


def _ellipse_rings(
    e: EstimatedPositionSection,
) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """(row, lat ring, lon ring) of the 2-sigma ellipse at every drawable row."""
    out = []
    for i in range(len(e.time_ns)):
        la, lo = float(e.lat_rad[i]), float(e.lon_rad[i])
        sa, sb = (ELLIPSE_SCALE * float(x[i]) for x in (e.semi_major_m, e.semi_minor_m))
        if math.isfinite(la) and math.isfinite(lo) and math.isfinite(sa) and sb > 0:
            out.append((i, *ring_deg(la, lo, sa, sb, float(e.orientation_rad[i]))))
    return out


def gpx_track(e: EstimatedPositionSection, src: str) -> str:
    """The aided EP's ``trk`` element (a ``trkseg`` per stretch)."""
    lat, lon = deg(e.lat_rad, e.lon_rad)
    times = iso_utc(np.asarray(e.time_ns, dtype=np.int64), unit="auto")
    out = [
        "<trk>"
        + xml_text("name", AIDED_NAME)
        + xml_text("desc", AIDED_WHAT)
        + xml_text("src", src)
        + xml_text("type", AIDED_KEY)
        + "\n"
    ]
    for rows in _stretches(e):
        out.append("<trkseg>\n")
        for i in rows.tolist():
            vals = "".join(
                f"<dracc:{k}>{num_text(v)}</dracc:{k}>"
                for k, v in _values(e, i).items()
                if math.isfinite(v)
            )
            upd = xml_text("dracc:update", e.update_kind[i]) if e.update_kind[i] else ""
            out.append(
                f"<trkpt {latlon_attrs(lat[i], lon[i])}><time>{times[i]}</time><extensions>"
                f"<dracc:uncertainty>{vals}</dracc:uncertainty>{upd}</extensions></trkpt>\n"
            )
        out.append("</trkseg>\n")
    out.append("</trk>\n")
    return "".join(out)


def kml_styles(doc: ET.Element) -> None:
    """The aided EP's line style and its ellipses' style (KML colours aabbggrr)."""
    k = NS_KML
    st = sub_element(doc, f"{{{k}}}Style", id=AIDED_KEY)
    ls = sub_element(st, f"{{{k}}}LineStyle")
    sub_element(ls, f"{{{k}}}color", "ff2ca02c")  # #2ca02c green, apart from DR and reference
    sub_element(ls, f"{{{k}}}width", "2.5")
    st = sub_element(doc, f"{{{k}}}Style", id=f"{AIDED_KEY}_ellipse")
    ls = sub_element(st, f"{{{k}}}LineStyle")
    sub_element(ls, f"{{{k}}}color", "ff2ca02c")
    sub_element(ls, f"{{{k}}}width", "1.5")
    ps = sub_element(st, f"{{{k}}}PolyStyle")
    sub_element(ps, f"{{{k}}}color", "332ca02c")


def kml_parts(doc: ET.Element, e: EstimatedPositionSection) -> None:
    """The aided EP's folder: its track (a ``gx:MultiTrack``, a ``gx:Track`` per stretch),
    then its 2-sigma ellipses, each a polygon shown over [epoch, next epoch of its
    stretch) (the last of a stretch for one fix interval)."""
    k, gx = NS_KML, NS_GX
    folder = sub_element(doc, f"{{{k}}}Folder")
    sub_element(folder, f"{{{k}}}name", AIDED_NAME)
    pm = sub_element(folder, f"{{{k}}}Placemark")
    sub_element(pm, f"{{{k}}}name", AIDED_NAME)
    sub_element(pm, f"{{{k}}}description", AIDED_WHAT)
    sub_element(pm, f"{{{k}}}styleUrl", f"#{AIDED_KEY}")
    multi = sub_element(pm, f"{{{gx}}}MultiTrack")
    sub_element(multi, f"{{{gx}}}interpolate", "0")
    lat, lon = deg(e.lat_rad, e.lon_rad)
    t = np.asarray(e.time_ns, dtype=np.int64)
    last = np.zeros(t.size, dtype=bool)  # the last row of its stretch
    for rows in _stretches(e):
        trk = sub_element(multi, f"{{{gx}}}Track")
        for when in iso_utc(t[rows]):
            sub_element(trk, f"{{{k}}}when", str(when))
        for i in rows.tolist():
            sub_element(trk, f"{{{gx}}}coord", f"{num_text(lon[i], 8)} {num_text(lat[i], 8)} 0")
        last[rows[-1]] = True
    for i, rlat, rlon in _ellipse_rings(e):
        when = iso_utc(int(t[i]))
        pm = sub_element(folder, f"{{{k}}}Placemark")
        sub_element(pm, f"{{{k}}}name", f"{AIDED_NAME} {when[11:16]} 2-sigma ellipse")
        span = sub_element(pm, f"{{{k}}}TimeSpan")
        sub_element(span, f"{{{k}}}begin", when)
        end = int(t[i]) + int(e.fix_interval_s * 1e9) if last[i] else int(t[i + 1])
        sub_element(span, f"{{{k}}}end", iso_utc(end))
        sub_element(pm, f"{{{k}}}styleUrl", f"#{AIDED_KEY}_ellipse")
        ext = sub_element(pm, f"{{{k}}}ExtendedData")
        for name, value in _values(e, i).items():
            d = sub_element(ext, f"{{{k}}}Data", name=name)
            sub_element(d, f"{{{k}}}value", num_text(value))
        d = sub_element(ext, f"{{{k}}}Data", name="update")
        sub_element(d, f"{{{k}}}value", e.update_kind[i])
        kml_polygon(pm, rlon, rlat)


def geojson_features(e: EstimatedPositionSection) -> list[dict[str, Any]]:
    """The aided EP: a LineString per stretch and its 2-sigma ellipse at each epoch."""
    lat, lon = deg(e.lat_rad, e.lon_rad)
    out: list[dict[str, Any]] = []
    for s, rows in enumerate(_stretches(e)):
        geom = line_geometry(lat[rows], lon[rows])
        if geom is None:
            continue
        out.append(
            {
                "type": "Feature",
                "geometry": geom,
                "properties": {
                    "kind": "track",
                    "track": AIDED_KEY,
                    "name": AIDED_NAME,
                    "stretch": s,
                    "start_utc": iso_utc(int(e.time_ns[rows[0]])),
                    "end_utc": iso_utc(int(e.time_ns[rows[-1]])),
                },
            }
        )
    for i, rlat, rlon in _ellipse_rings(e):
        v = _values(e, i)
        out.append(
            {
                "type": "Feature",
                "geometry": polygon_geometry(rlat, rlon),
                "properties": {
                    "kind": "aided_ep_ellipse_2sigma",
                    "scale": ELLIPSE_SCALE,
                    "time_utc": iso_utc(int(e.time_ns[i])),
                    "update": e.update_kind[i],
                    **{name: nullable(x) for name, x in v.items()},
                },
            }
        )
    return out
