"""The ``dracc.fix/1`` document and the terminal tables of a :class:`FixReport`.

:func:`to_json` builds the JSON object (:data:`JSON_SCHEMA`, draft 2020-12; every key is
documented in docs/fix.md): strict JSON, an undefined value is ``null``.  :func:`render`
prints the position, the error ellipse, DOP, the residual table and the verdict, laid out by
:mod:`dracc.report.textout` (never squeezed, wrapped on spaces).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from rich.console import Console

from dracc.core.numbers import finite_or_none as _finite
from dracc.ingest.observations import DatumRecord
from dracc.math.fix import FixReport, format_dm
from dracc.pipeline.fix import FreeGyroModel
from dracc.report.textout import Layout, Page, labelled, layout

SCHEMA = "dracc.fix/1"


def datum_json(d: DatumRecord) -> dict[str, Any]:
    """One entry of ``datums``: which transformation moved which observation, how far."""
    t = d.transformation
    return {
        "observation": d.label,
        "datum": t.datum,
        "crs": t.crs,
        "crs_name": t.crs_name,
        "operation": t.operation,
        "operation_code": t.operation_code,
        "method": t.method,
        "accuracy_m": t.accuracy_m,
        "grid_free": t.grid_free,
        "fallback": t.fallback,
        "missing_operation": t.missing_operation,
        "missing_accuracy_m": t.missing_accuracy_m,
        "missing_grids": list(t.missing_grids),
        "epsg_version": t.epsg_version,
        "points_given_deg": [list(p) for p in d.points_given_deg],
        "points_wgs84_deg": [list(p) for p in d.points_wgs84_deg],
        "shift_m": list(d.shift_m),
    }


def to_json(
    rep: FixReport, datums: Sequence[DatumRecord] = (), free_gyro: FreeGyroModel | None = None
) -> dict[str, Any]:
    """The ``dracc.fix/1`` object (see :data:`JSON_SCHEMA` and docs/fix.md); ``datums``:
    the datum transformations applied before fusion (``[]`` when all were WGS-84);
    ``free_gyro``: the gyro vectors' error model (``null`` without gyro vectors)."""
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
        "observations": [{"label": sp.label, "source": sp.source} for sp in rep.observations],
        "datums": [datum_json(d) for d in datums],
        "free_gyro": None if free_gyro is None else free_gyro_json(free_gyro),
    }


_NUMBER = {"type": "number"}
_POINTS = {
    "type": "array",
    "minItems": 1,
    "items": {"type": "array", "minItems": 2, "maxItems": 2, "items": _NUMBER},
}
_DATUM_OPTIONAL_TEXT = ("operation_code", "missing_operation", "epsg_version")
_DATUM_KEYS = (
    "observation",
    "datum",
    "crs",
    "crs_name",
    "operation",
    "operation_code",
    "method",
    "accuracy_m",
    "grid_free",
    "fallback",
    "missing_operation",
    "missing_accuracy_m",
    "missing_grids",
    "epsg_version",
    "points_given_deg",
    "points_wgs84_deg",
    "shift_m",
)
_MATRIX_OR_NULL = {
    "oneOf": [{"type": "null"}, {"type": "array", "items": {"type": "array", "items": _NUMBER}}]
}
_NUMBER_OR_NULL = {"type": ["number", "null"]}
_FREE_GYRO = {
    "type": "object",
    "additionalProperties": False,
    "required": [
        "gyro_vectors",
        "sigma_theta_deg",
        "sigma_u_deg",
        "sigma_t_s",
        "fdop_printed",
        "dop_trace",
        "dop_paper",
        "dop_model",
        "cofactor_rad2",
        "cov_m2",
        "drms_m",
        "reason",
    ],
    "properties": {
        "gyro_vectors": {"type": "array", "items": {"type": "string"}},
        "sigma_theta_deg": {"type": "array", "items": _NUMBER},
        "sigma_u_deg": {"type": "array", "items": _NUMBER},
        "sigma_t_s": {"type": "number", "minimum": 0},
        "fdop_printed": _NUMBER_OR_NULL,
        "dop_trace": _NUMBER_OR_NULL,
        "dop_paper": _NUMBER_OR_NULL,
        "dop_model": _NUMBER_OR_NULL,
        "cofactor_rad2": _MATRIX_OR_NULL,
        "cov_m2": _MATRIX_OR_NULL,
        "drms_m": _NUMBER_OR_NULL,
        "reason": {"type": ["string", "null"]},
    },
}
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
        "datums",
        "free_gyro",
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
        "datums": {
            "type": "array",
            "items": {
                "type": "object",
                "additionalProperties": False,
                "required": list(_DATUM_KEYS),
                "properties": {
                    **{k: {"type": "string"} for k in ("observation", "datum", "crs")},
                    **{k: {"type": "string"} for k in ("crs_name", "operation", "method")},
                    **{k: {"type": ["string", "null"]} for k in _DATUM_OPTIONAL_TEXT},
                    "accuracy_m": {"type": ["number", "null"], "minimum": 0},
                    "missing_accuracy_m": {"type": ["number", "null"], "minimum": 0},
                    "grid_free": {"type": "boolean"},
                    "fallback": {"type": "boolean"},
                    "missing_grids": {"type": "array", "items": {"type": "string"}},
                    "points_given_deg": _POINTS,
                    "points_wgs84_deg": _POINTS,
                    "shift_m": {"type": "array", "items": {"type": "number", "minimum": 0}},
                },
            },
        },
        "free_gyro": {"oneOf": [{"type": "null"}, _FREE_GYRO]},
    },
}


def fix_page(
    rep: FixReport,
    lay: Layout,
    datums: Sequence[DatumRecord] = (),
    free_gyro: FreeGyroModel | None = None,
) -> Page:
    """The fix laid out for ``lay`` (:mod:`dracc.report.textout`): the title, the
    position, the error ellipse, DOP, chi-square and the prior under their labels, the
    datum transformations (if any), the free-gyro error model (if gyro vectors were
    given), the residual table and the verdict."""
    s = rep.solution
    lat, lon = math.degrees(s.lat_rad), math.degrees(s.lon_rad)
    e = s.ellipse
    page = Page(lay)
    page.heading(
        f"dracc fix ({'WLS (W4)' if s.weighted else 'LS (W1)'}, "
        f"{len(rep.observations)} observation(s), {s.iterations} iteration(s))"
    )
    head = (
        ("position", f"{format_dm(lat, 'lat')}  {format_dm(lon, 'lon')}"),
        ("decimal", f"{lat:.7f}, {lon:.7f}"),
        (
            "error ellipse (1σ)",
            f"{float(e.semi_major_m):.2f} m × {float(e.semi_minor_m):.2f} m, "
            f"major axis {math.degrees(float(e.orientation_rad)):05.1f}° true",
        ),
        ("drms / 2drms", f"{float(s.drms_m):.2f} m / {float(s.two_drms_m):.2f} m"),
        ("DOP", f"{float(s.dop):.3f}"),
        ("chi-square", f"{float(s.chi2):.3f}, redundancy {s.redundancy}"),
        (
            "prior",
            f"{format_dm(rep.prior_lat_deg, 'lat')}  "
            f"{format_dm(rep.prior_lon_deg, 'lon')} ({rep.prior_source})",
        ),
    )
    column = max(len(label) for label, _ in head) + 2
    for label, value in head:
        page.add(labelled(label, value, lay.width, column))
    if datums:
        page.blank()
        page.table(
            ("observation", "datum", "transformation", "accuracy", "shift"),
            [
                (
                    d.label,
                    d.transformation.datum,
                    d.transformation.operation
                    + (
                        f" ({d.transformation.operation_code})"
                        if d.transformation.operation_code
                        else ""
                    ),
                    "unknown"
                    if d.transformation.accuracy_m is None
                    else f"±{d.transformation.accuracy_m:g} m",
                    f"{max(d.shift_m):.1f} m",
                )
                for d in datums
            ],
            right=(False, False, False, True, True),
            priorities=(0, 1, 0, 1, 0),
            title="positions brought to WGS-84 before fusion",
        )
        for note in sorted({_fallback_note(d) for d in datums if d.transformation.fallback}):
            page.wrapped(note, hang=2)
    if free_gyro is not None:
        page.blank()
        for label, value in free_gyro_lines(free_gyro):
            page.add(labelled(label, value, lay.width, column))
    rows = []
    for r in rep.residuals:
        digits = 3 if r.unit == "deg" else 2
        sigma = f"{r.sigma:.{digits}f} {r.unit}" + (" (default)" if r.sigma_default else "")
        rows.append(
            (
                r.label,
                r.row,
                f"{r.residual:+.{digits}f} {r.unit}",
                sigma,
                f"{r.normalised:+.2f}",
                "-" if not math.isfinite(r.w) else f"{r.w:+.2f}",
            )
        )
    page.blank()
    page.table(
        ("observation", "row", "residual", "σ", "r/σ", "w"),
        rows,
        right=(False, False, True, True, True, True),
        priorities=(0, 1, 0, 1, 0, 2),
        title="residuals (measured − fitted)",
    )
    page.blank()
    page.wrapped(f"verdict: {rep.verdict}", hang=2)
    return page


def _fallback_note(d: DatumRecord) -> str:
    t = d.transformation
    better = "" if t.missing_accuracy_m is None else f" (±{t.missing_accuracy_m:g} m)"
    return (
        f"note: {t.datum}: {t.missing_operation}{better} needs the grid "
        f"{', '.join(t.missing_grids) or 'file'}, not installed; the grid-free "
        f"{t.operation} (±{t.accuracy_m:g} m) was used instead (docs/fix.md, Datums)"
        if t.accuracy_m is not None
        else f"note: {t.datum}: {t.missing_operation}{better} needs a grid that is not "
        f"installed; {t.operation} was used instead (docs/fix.md, Datums)"
    )


def render(
    rep: FixReport,
    console: Console,
    datums: Sequence[DatumRecord] = (),
    free_gyro: FreeGyroModel | None = None,
) -> None:
    """The fix (:func:`fix_page`) laid out for ``console`` (the CLI's stdout) and printed."""
    fix_page(rep, layout(console), datums, free_gyro).print(console)


def _matrix(m: Any) -> list[list[float]] | None:
    return None if m is None else [[float(v) for v in row] for row in m]


def free_gyro_json(m: FreeGyroModel) -> dict[str, Any]:
    """The ``free_gyro`` object: seeds/002's DOP figures and the covariance of (33)."""
    d = m.dop
    return {
        "gyro_vectors": list(m.labels),
        "sigma_theta_deg": list(m.sigma_theta_deg),
        "sigma_u_deg": list(m.sigma_u_deg),
        "sigma_t_s": m.sigma_t_s,
        "fdop_printed": None if d is None else _finite(d.fdop_printed),
        "dop_trace": None if d is None else _finite(d.dop),
        "dop_paper": None if d is None else _finite(d.dop_paper),
        "dop_model": None if d is None else _finite(d.dop_model),
        "cofactor_rad2": None if d is None else _matrix(d.cofactor_rad2),
        "cov_m2": _matrix(m.cov_m2),
        "drms_m": m.drms_m,
        "reason": m.reason,
    }


def free_gyro_lines(m: FreeGyroModel) -> list[tuple[str, str]]:
    """(label, value) lines of the free-gyro error model for the terminal."""
    n = len(m.labels)
    if m.dop is None or m.cov_m2 is None or m.drms_m is None:
        return [("free-gyro model", f"{n} gyro vector(s): {m.reason}")]
    d, c = m.dop, m.cov_m2
    return [
        ("free-gyro model", f"{n} gyro vectors, Jeong's error model (30)-(38) (docs/free-gyro.md)"),
        ("FDOP (37) printed", f"{d.fdop_printed:.4g} (rad², as the paper prints it)"),
        ("DOP, trace form", f"{d.dop:.3f} (dracc, METHODS §5)"),
        ("DOP, (34) one σ", f"{d.dop_paper:.3f} (equal σθ: {d.dop_model:.3f} exact)"),
        (
            "model covariance",
            f"σN {math.sqrt(c[0, 0]):.1f} m, σE {math.sqrt(c[1, 1]):.1f} m, "
            f"ρ {c[0, 1] / math.sqrt(c[0, 0] * c[1, 1]):+.2f}, drms {m.drms_m:.1f} m "
            f"(from σθ, σu and σt = {m.sigma_t_s:g} s)",
        ),
    ]


__all__ = [
    "JSON_SCHEMA",
    "SCHEMA",
    "datum_json",
    "fix_page",
    "format_dm",
    "free_gyro_json",
    "free_gyro_lines",
    "render",
    "to_json",
]
