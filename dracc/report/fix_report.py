"""The ``dracc.fix/1`` document and the terminal tables of a :class:`FixReport`.

:func:`to_json` builds the JSON object (:data:`JSON_SCHEMA`, draft 2020-12; every key is
documented in docs/fix.md): strict JSON, an undefined value is ``null``.  :func:`render`
prints the position, the error ellipse, DOP, the residual table and the verdict, laid out by
:mod:`dracc.report.textout` (never squeezed, wrapped on spaces).
"""

from __future__ import annotations

import math
from typing import Any

from rich.console import Console

from dracc.core.numbers import finite_or_none as _finite
from dracc.math.fix import FixReport, format_dm
from dracc.report.textout import Layout, Page, labelled, layout

SCHEMA = "dracc.fix/1"


def to_json(rep: FixReport) -> dict[str, Any]:
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
        "observations": [{"label": sp.label, "source": sp.source} for sp in rep.observations],
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


def fix_page(rep: FixReport, lay: Layout) -> Page:
    """The fix laid out for ``lay`` (:mod:`dracc.report.textout`): the title, the
    position, the error ellipse, DOP, chi-square and the prior under their labels, the
    residual table and the verdict."""
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


def render(rep: FixReport, console: Console) -> None:
    """The fix (:func:`fix_page`) laid out for ``console`` (the CLI's stdout) and printed."""
    fix_page(rep, layout(console)).print(console)


__all__ = ["JSON_SCHEMA", "SCHEMA", "fix_page", "format_dm", "render", "to_json"]
