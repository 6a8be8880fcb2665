"""Positions referred to a local geodetic datum, brought to WGS-84 before fusion.

Seeds/004 §2: all navigational and cartographic data must be brought to one reference
system (WGS-84) before they are fused, or the datum shift (about 100 m for ED50 in
Europe) becomes a systematic error far beyond the random ones.  The transformations are
the EPSG dataset's, chosen and applied by PROJ through pyproj; nothing here hand-codes a
parameter.

Choice (:func:`to_wgs84`): the EPSG transformations from the datum's geographic CRS to
WGS 84 (EPSG:4326) whose area of use contains the points' bounding box, ballpark (null)
offsets refused, in PROJ's order of preference (accuracy first).  PROJ runs offline here
(its network access stays as the user set it, off by default): a transformation whose
grid file is not installed (NADCON for NAD27, OSTN15 for OSGB36, ...) is skipped and the
best grid-free one (a Helmert / geocentric translation from the EPSG dataset) is used;
:class:`Transformation` says which, its accuracy, and the grid that was missing.

pyproj is imported only when a transformation is asked for (it costs 0.2 s to import).
"""

from __future__ import annotations

import re
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from dracc.core.errors import ConfigError

WGS84_CRS = "EPSG:4326"

#: common datum names (compared without case, spaces, hyphens or underscores) -> the
#: EPSG code of the datum's geographic 2D CRS
DATUM_CRS = {
    "WGS84": "EPSG:4326",
    "ED50": "EPSG:4230",
    "ED87": "EPSG:4231",
    "ETRS89": "EPSG:4258",
    "NAD27": "EPSG:4267",
    "NAD83": "EPSG:4269",
    "OSGB36": "EPSG:4277",
    "TOKYO": "EPSG:4301",
    "PULKOVO1942": "EPSG:4284",
    "SK42": "EPSG:4284",
    "WGS72": "EPSG:4322",
    "GDA94": "EPSG:4283",
    "JGD2000": "EPSG:4612",
}
_SHOWN = "WGS84, ED50, ED87, ETRS89, NAD27, NAD83, OSGB36, Tokyo, Pulkovo 1942 (SK42), WGS72, GDA94, JGD2000"
_EPSG_RE = re.compile(r"^EPSG:\s*(\d{4,6})$", re.IGNORECASE)


def _key(name: str) -> str:
    return re.sub(r"[\s_\-]", "", name).upper()


def resolve_datum(name: str) -> str:
    """The EPSG code (``"EPSG:4230"``) of a datum name (``ED50``, ``Pulkovo 1942``) or code.

    An ``EPSG:NNNN`` code must name a geographic 2D CRS of the EPSG dataset (checked by
    pyproj).  Raises :class:`ConfigError` naming the known datums otherwise.
    """
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(
            f"datum {name!r}: give a datum name or an EPSG code ({_SHOWN}; EPSG:4230)"
        )
    code = DATUM_CRS.get(_key(name))
    if code is not None:
        return code
    m = _EPSG_RE.match(name.strip())
    if m is None:
        raise ConfigError(
            f"unknown datum {name!r}: known datums are {_SHOWN}, or an EPSG code of a "
            "geographic CRS such as EPSG:4230"
        )
    code = f"EPSG:{int(m.group(1))}"
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        crs = CRS.from_user_input(code)
    except CRSError:
        raise ConfigError(f"datum {name!r}: {code} is not in the EPSG dataset") from None
    if not crs.is_geographic or len(crs.axis_info) != 2:
        raise ConfigError(
            f"datum {name!r}: {code} ({crs.name}) is not a geographic 2D CRS (latitude, "
            "longitude); give the datum's geographic CRS, e.g. EPSG:4230 for ED50"
        )
    return code


def is_wgs84(name: str) -> bool:
    """True when ``name`` is WGS-84 itself (nothing to transform)."""
    return resolve_datum(name) == WGS84_CRS


@dataclass(frozen=True)
class Transformation:
    """The EPSG transformation PROJ applied from ``crs`` to WGS 84.

    ``operation``: its EPSG name (``ED50 to WGS 84 (18)``); ``operation_code``:
    ``EPSG:1311`` (None when PROJ built it without an identifier); ``method``: the EPSG
    method (``Position Vector transformation (geog2D domain)``, ``Geocentric
    translations``, ``NTv2``); ``accuracy_m``: the EPSG accuracy (None if unknown);
    ``grid_free``: no grid file used; ``fallback``: a more accurate transformation for
    these points needs a grid that is not installed (``missing_operation``,
    ``missing_accuracy_m``, ``missing_grids``); ``epsg_version``: the EPSG dataset.
    """

    datum: str
    crs: str
    crs_name: str
    operation: str
    operation_code: str | None
    method: str
    accuracy_m: float | None
    grid_free: bool
    fallback: bool
    missing_operation: str | None
    missing_accuracy_m: float | None
    missing_grids: tuple[str, ...]
    epsg_version: str | None

    def describe(self) -> str:
        """One line: ``ED50 to WGS 84 (18) (EPSG:1311, Position Vector ..., ±1 m)``."""
        acc = "accuracy unknown" if self.accuracy_m is None else f"±{self.accuracy_m:g} m"
        code = f"{self.operation_code}, " if self.operation_code else ""
        text = f"{self.operation} ({code}{self.method}, {acc})"
        if self.fallback:
            grids = ", ".join(self.missing_grids) or "its grid"
            better = "" if self.missing_accuracy_m is None else f" (±{self.missing_accuracy_m:g} m)"
            text += (
                f"; the grid-free fallback for {self.missing_operation}{better}, whose grid "
                f"{grids} is not installed"
            )
        return text


@dataclass(frozen=True)
class WGS84Positions:
    """Points transformed to WGS-84: degrees, and each point's shift (geodesic metres
    between the coordinates as given and as transformed, on the WGS-84 ellipsoid)."""

    lat_deg: np.ndarray
    lon_deg: np.ndarray
    shift_m: np.ndarray
    transformation: Transformation


def _bbox(lat: np.ndarray, lon: np.ndarray) -> tuple[float, float, float, float]:
    """(west, south, east, north); west > east when the points straddle the antimeridian."""
    west, east = float(lon.min()), float(lon.max())
    if east - west > 180.0:  # across ±180°: the box from the easternmost negative side
        west, east = float(lon[lon > 0].min()), float(lon[lon < 0].max())
    return west, float(lat.min()), east, float(lat.max())


def _lon_inside(lon: float, west: float, east: float) -> bool:
    return west <= lon <= east if west <= east else (lon >= west or lon <= east)


def _contains(bounds: tuple[float, float, float, float], box: tuple[float, ...]) -> bool:
    """The area of use (west, south, east, north) holds the box (to 1e-9°)."""
    w, s, e, n = bounds
    bw, bs, be, bn = box
    eps = 1e-9
    inside_lat = s - eps <= bs and bn <= n + eps
    return inside_lat and _lon_inside(bw, w - eps, e + eps) and _lon_inside(be, w - eps, e + eps)


def _core(op_list: Any) -> list[Any]:
    """The transformation steps of a concatenated operation (axis swaps left out)."""
    return [o for o in op_list if o.type_name != "Conversion"]


def _ident(op: Any) -> str | None:
    ident = op.to_json_dict().get("id")
    return f"{ident['authority']}:{ident['code']}" if ident else None


def _where(lat: float, lon: float) -> str:
    return f"{abs(lat):.4f}°{'N' if lat >= 0 else 'S'} {abs(lon):.4f}°{'E' if lon >= 0 else 'W'}"


def choose_transformation(
    datum: str, lat_deg: ArrayLike, lon_deg: ArrayLike
) -> tuple[Any, Transformation]:
    """The pyproj Transformer (lon, lat order) and its :class:`Transformation` for the
    points ``lat_deg``, ``lon_deg`` (degrees) referred to ``datum`` (see module doc)."""
    import pyproj
    from pyproj.transformer import AreaOfInterest, TransformerGroup

    crs = resolve_datum(datum)
    lat = np.atleast_1d(np.asarray(lat_deg, float))
    lon = np.atleast_1d(np.asarray(lon_deg, float))
    if lat.shape != lon.shape or lat.size == 0:
        raise ConfigError(
            "datum transformation: give as many latitudes as longitudes (at least one)"
        )
    if not (np.all(np.isfinite(lat)) and np.all(np.isfinite(lon))):
        raise ConfigError("datum transformation: the coordinates must be finite numbers")
    if np.any(np.abs(lat) > 90.0) or np.any(np.abs(lon) > 180.0):
        raise ConfigError("datum transformation: latitude within ±90°, longitude within ±180°")
    box = _bbox(lat, lon)
    with warnings.catch_warnings():  # "best transformation is not available": reported below
        warnings.simplefilter("ignore", UserWarning)
        group = TransformerGroup(
            crs,
            WGS84_CRS,
            always_xy=True,
            allow_ballpark=False,
            area_of_interest=AreaOfInterest(*box),
        )
    usable = [
        t for t in group.transformers if t.area_of_use and _contains(t.area_of_use.bounds, box)
    ]
    src = pyproj.CRS.from_user_input(crs)
    if not usable:
        area = src.area_of_use.name if src.area_of_use else "its area"
        raise ConfigError(
            f"datum {datum!r} ({src.name}): no EPSG transformation to WGS 84 covers "
            f"{_where(float(lat[0]), float(lon[0]))}; {src.name} is used in: {area[:160]}"
        )
    chosen = usable[0]
    steps = _core(chosen.operations or ())
    accuracy = (
        float(chosen.accuracy) if chosen.accuracy is not None and chosen.accuracy >= 0 else None
    )
    better = [
        op
        for op in group.unavailable_operations
        if op.area_of_use
        and _contains(op.area_of_use.bounds, box)
        and op.accuracy is not None
        and op.accuracy >= 0
        and (accuracy is None or op.accuracy < accuracy)
    ]
    best = min(better, key=lambda op: op.accuracy) if better else None
    uses_grid = "grids=" in chosen.definition or any(s.grids for s in steps)
    info = Transformation(
        datum=datum.strip(),
        crs=crs,
        crs_name=src.name,
        operation=" + ".join(s.name for s in steps) if steps else chosen.description,
        operation_code=", ".join(c for c in (_ident(s) for s in steps) if c) or None,
        method=" + ".join(s.method_name for s in steps) if steps else chosen.name,
        accuracy_m=accuracy,
        grid_free=not uses_grid,
        fallback=best is not None,
        missing_operation=best.name if best is not None else None,
        missing_accuracy_m=float(best.accuracy) if best is not None else None,
        missing_grids=tuple(g.short_name for g in best.grids if not g.available) if best else (),
        epsg_version=pyproj.database.get_database_metadata("EPSG.VERSION"),
    )
    return chosen, info


def to_wgs84(lat_deg: ArrayLike, lon_deg: ArrayLike, datum: str) -> WGS84Positions:
    """Latitudes and longitudes (degrees) referred to ``datum`` as WGS-84 degrees.

    ``datum``: a name of :data:`DATUM_CRS` (``ED50``, ``NAD27``, ``OSGB36``, ``Tokyo``,
    ``Pulkovo 1942`` ...) or an EPSG code of a geographic CRS (``EPSG:4230``).  One EPSG
    transformation serves all the points: the most accurate installed one whose area of
    use contains their bounding box (:func:`choose_transformation`).  WGS-84 itself is
    returned unchanged.  Raises :class:`ConfigError` for an unknown datum or points that
    no transformation of the datum covers.
    """
    lat = np.atleast_1d(np.asarray(lat_deg, float))
    lon = np.atleast_1d(np.asarray(lon_deg, float))
    crs = resolve_datum(datum)
    if crs == WGS84_CRS:
        import pyproj

        ident = Transformation(
            datum.strip(), crs, "WGS 84", "none (already WGS 84)", None, "identity", 0.0,
            True, False, None, None, (), pyproj.database.get_database_metadata("EPSG.VERSION"),
        )  # fmt: skip
        return WGS84Positions(lat.copy(), lon.copy(), np.zeros(lat.shape), ident)
    transformer, info = choose_transformation(datum, lat, lon)
    out_lon, out_lat = transformer.transform(lon, lat, errcheck=False)
    out_lat = np.asarray(out_lat, float).reshape(lat.shape)
    out_lon = np.asarray(out_lon, float).reshape(lon.shape)
    if not (np.all(np.isfinite(out_lat)) and np.all(np.isfinite(out_lon))):
        raise ConfigError(
            f"datum {datum!r}: PROJ could not transform these points ({info.operation})"
        )
    from pyproj import Geod

    _, _, shift = Geod(ellps="WGS84").inv(lon, lat, out_lon, out_lat)
    return WGS84Positions(
        out_lat, out_lon, np.abs(np.asarray(shift, float)).reshape(lat.shape), info
    )


__all__ = [
    "DATUM_CRS",
    "WGS84_CRS",
    "Transformation",
    "WGS84Positions",
    "choose_transformation",
    "is_wgs84",
    "resolve_datum",
    "to_wgs84",
]
