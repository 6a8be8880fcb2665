"""The JSON report, schema ``dracc.analysis/1`` (``analysis.schema.json`` beside this file).

:func:`to_dict` turns an :class:`~dracc.pipeline.results.Analysis` into plain JSON types; NaN
and infinities become ``null``; times are ISO 8601 UTC strings (``*_utc``); angles in
degrees and speeds in knots appear only here, with the unit in the key.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from dracc.core import atomic
from dracc.core.numbers import finite_or_none as _num
from dracc.core.timefmt import iso_utc
from dracc.core.units import mps_to_kn
from dracc.math.clock import SourceClock
from dracc.math.integrity import Check, IntegrityResult
from dracc.math.integrity.causes import failed_with_consequences
from dracc.pipeline.results import (
    Analysis,
    CalibrationSection,
    CurrentSection,
    DRHonesty,
    DRSection,
    DRTrackResult,
    Estimate,
    EstimatedPositionSection,
)

SCHEMA_PATH = Path(__file__).with_name("analysis.schema.json")


def load_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the report."""
    return cast(dict[str, Any], json.loads(SCHEMA_PATH.read_text(encoding="utf-8")))


def _deg(x_rad: Any) -> float | None:
    v = _num(x_rad)
    return None if v is None else math.degrees(v)


def _estimate(e: Estimate | None) -> dict[str, Any] | None:
    return None if e is None else {"value": _num(e.value), "sigma": _num(e.sigma)}


def _deviation(a: Analysis) -> dict[str, Any]:
    """The deviation section: :meth:`DeviationResult.to_dict` (its owner settles the keys),
    plus where the reference came from."""
    assert a.deviation is not None  # called only when the analysis has a deviation section
    d = a.deviation.to_dict()
    d["reference_source"] = a.deviation_reference
    return d


def _epochs(t: DRTrackResult) -> list[dict[str, Any]]:
    lat_deg = np.degrees(t.lat_rad)
    lon_deg = np.degrees(t.lon_rad)
    water_lat_deg = np.degrees(t.water_lat_rad)
    water_lon_deg = np.degrees(t.water_lon_rad)
    orient_deg = np.degrees(t.orientation_rad)
    out = []
    for i in range(len(t.time_ns)):
        out.append(
            {
                "time_utc": iso_utc(int(t.time_ns[i])),
                "lat_deg": _num(lat_deg[i]),
                "lon_deg": _num(lon_deg[i]),
                "since_fix_s": _num(t.since_fix_s[i]),
                "radius_2m_m": _num(t.radius_2m_m[i]),
                "ellipse": {
                    "semi_major_m": _num(t.semi_major_m[i]),
                    "semi_minor_m": _num(t.semi_minor_m[i]),
                    "orientation_deg": _num(orient_deg[i]),
                },
                "ref_error_m": _num(t.ref_error_m[i]),
                "leg": int(t.leg[i]),
                "water_lat_deg": _num(water_lat_deg[i]),
                "water_lon_deg": _num(water_lon_deg[i]),
                "scored": bool(t.scored[i]),
                "inside": _flag(t.inside[i]),
                "p_inside": _num(t.p_inside[i]),
                "pit": _num(t.pit[i]),
            }
        )
    return out


def _flag(x: float) -> bool | None:
    """1.0/0.0 -> true/false, NaN (not judged) -> null."""
    return None if not math.isfinite(x) else bool(x)


def _honesty(h: DRHonesty | None) -> dict[str, Any] | None:
    if h is None:
        return None
    return {
        "predictive": h.predictive,
        "method": h.method,
        "inflation": {"min": _num(h.inflation_min), "max": _num(h.inflation_max)},
        "shape_min": _num(h.shape_min),
        "n_scored": h.n_scored,
        "n_misleading": h.n_misleading,
        "stated_inside": _num(h.stated_inside),
        "beyond_99": {"n": h.n_beyond_99, "expected": _num(h.expected_beyond_99)},
        "pit_counts": list(h.pit_counts),
        "first_leg": {"inside": _num(h.first_leg_inside), "stated": _num(h.first_leg_stated)},
    }


def _learned(learned: dict[str, object] | None) -> dict[str, Any] | None:
    """The model learned from the voyage's fixes (``DRSection.learned``): numbers (NaN ->
    null), counts and the ``config_block`` text as they are."""
    if learned is None:
        return None
    out: dict[str, Any] = {}
    for k, v in learned.items():
        if isinstance(v, str) or v is None:
            out[str(k)] = v
        elif isinstance(v, (bool, np.bool_)):
            out[str(k)] = bool(v)
        elif isinstance(v, (int, np.integer)):
            out[str(k)] = int(v)
        else:
            out[str(k)] = _num(v)
    return out


def _legs(dr: DRSection) -> list[dict[str, Any]]:
    """The legs; the NEES figures where the leg was scored (``dr.leg_checks``), else null."""
    checks = {int(lc.leg): lc for lc in dr.leg_checks}
    out = []
    for leg in dr.legs:
        lc = checks.get(int(leg.index))
        out.append(
            {
                "index": leg.index,
                "start_utc": iso_utc(leg.start_ns),
                "end_utc": iso_utc(leg.end_ns),
                "fix_source": leg.fix_source,
                "containment_2m": _num(leg.containment_2m),
                "n_scored": int(leg.n_scored),
                "max_error_m": _num(leg.max_error_m),
                "mean_nees": None if lc is None else _num(lc.mean_nees),
                "last_nees": None if lc is None else _num(lc.last_nees),
                "nees_upper": None if lc is None else _num(lc.nees_upper),
            }
        )
    return out


def _dead_reckoning(dr: DRSection) -> dict[str, Any]:
    return {
        "heading_source": dr.heading_source,
        "speed_source": dr.speed_source,
        "reset": dr.reset,
        "epoch_interval_s": float(dr.epoch_interval_s),
        "reference_source": dr.reference_role,
        "epochs": _epochs(dr.epochs),
        "containment_2m": _num(dr.containment_2m),
        "n_scored": int(dr.n_scored),
        "expected_inside": _num(dr.expected_inside),
        "error_over_m_rms": _num(dr.error_over_m_rms),
        "gaps_bridged": int(dr.n_gaps_bridged),
        "breaks": int(dr.n_breaks),
        "consistent": dr.consistent,
        "verdict": dr.verdict,
        "legs": _legs(dr),
        "notes": list(dr.notes),
        "mean_nees": _num(dr.mean_nees),
        "nees": {
            "statistic": _num(dr.nees_statistic),
            "lower": _num(dr.nees_lower),
            "upper": _num(dr.nees_upper),
        },
        "dominant_source": dr.dominant_source,
        "dominant_key": dr.dominant_key,
        "learned_model": _learned(dr.learned),
        "reference_sigma_m": _num(dr.reference_sigma_m),
        "scored_out_of_sample": bool(dr.scored_out_of_sample),
        "honesty": _honesty(dr.honesty),
    }


def _calibration(c: CalibrationSection) -> dict[str, Any]:
    return {
        "reference_source": c.reference_role,
        "method": c.method,
        "n_fixes": int(c.n_fixes),
        "compass_error_deg": _estimate(c.compass_error_deg),
        "log_scale": _estimate(c.log_scale),
        "log_offset_kn": _estimate(c.log_offset_kn),
        "n": int(c.n),
        "segment_s": float(c.segment_s),
        "residual_rms_kn": _num(c.residual_rms_kn),
        "notes": list(c.notes),
        "not_determinable": dict(c.not_determinable),
    }


def _current(c: CurrentSection) -> dict[str, Any]:
    return {
        "set_deg": _estimate(c.set_deg),
        "drift_kn": _estimate(c.drift_kn),
        "n_updates": int(c.n_updates),
        "series": [
            {
                "time_utc": iso_utc(int(t)),
                "set_deg": _deg(s),
                "drift_kn": _num(mps_to_kn(v)),
                "drift_sigma_kn": _num(mps_to_kn(sv)),
            }
            for t, s, v, sv in zip(
                c.time_ns, c.set_rad, c.drift_mps, c.drift_sigma_mps, strict=True
            )
        ],
        "notes": list(c.notes),
    }


def _estimated_position(e: EstimatedPositionSection) -> dict[str, Any]:
    lat, lon, orient = np.degrees(e.lat_rad), np.degrees(e.lon_rad), np.degrees(e.orientation_rad)
    return {
        "fix_interval_s": _num(e.fix_interval_s),
        "n_fix_updates": int(e.n_fix_updates),
        "n_lop_updates": int(e.n_lop_updates),
        "observations_outside": int(e.observations_outside),
        "epochs": [
            {
                "time_utc": iso_utc(int(e.time_ns[i])),
                "lat_deg": _num(lat[i]),
                "lon_deg": _num(lon[i]),
                "radius_2m_m": _num(e.radius_2m_m[i]),
                "ellipse": {
                    "semi_major_m": _num(e.semi_major_m[i]),
                    "semi_minor_m": _num(e.semi_minor_m[i]),
                    "orientation_deg": _num(orient[i]),
                },
                "since_update_s": _num(e.since_update_s[i]),
                "update": e.update_kind[i],
            }
            for i in range(len(e.time_ns))
        ],
        "fix_interval_study": [
            {
                "interval_s": _num(r.interval_s),
                "n_updates": int(r.n_updates),
                "mean_2m_before_m": _num(r.mean_2m_before_m),
                "max_2m_before_m": _num(r.max_2m_before_m),
                "containment": _num(r.containment),
                "expected_containment": _num(r.expected_containment),
                "model": r.model,
            }
            for r in e.interval_study
        ],
        "notes": list(e.notes),
    }


def _plain(x: Any) -> Any:
    """Settings may hold numpy scalars, tuples or paths: make them JSON types."""
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (bool, str)) or x is None:
        return x
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return _num(x)
    return str(x)


def clock_dict(c: SourceClock | None) -> dict[str, Any] | None:
    """``sources[KEY].clock``: offset_s > 0 is data stamped after the instant described."""
    if c is None:
        return None
    return {
        "offset_s": _num(c.offset_s),
        "offset_sigma_s": _num(c.offset_sigma_s),
        "drift_ppm": _num(c.drift_ppm),
        "method": c.method,
        "basis": c.basis,
        "samples": int(c.samples),
        "spread_records": int(c.spread),
        "spread_mean_s": _num(c.spread_mean_s),
        "stamp_resolution_s": c.stamp_s,
    }


def to_dict(a: Analysis, judged: Analysis | None = None) -> dict[str, Any]:
    """The report as plain JSON types (validates against ``analysis.schema.json``).
    ``judged``: the analysis whose a priori values pick ``worst_ins_unit`` (the audit's
    yardstick, :func:`dracc.report.audit_json.audit_analysis`, as its page does); ``a``
    itself by default."""
    from dracc.report.verdict import worst_unit

    worst = worst_unit(a if judged is None else judged)
    by_role: dict[str, dict[str, Any]] = {}
    for s in a.sources:
        for role in s.roles:
            entry = by_role.setdefault(role, {"keys": [], "records": 0})
            entry["keys"].append(s.key)
            entry["records"] += int(s.records)
    return {
        "schema": a.schema,
        "dracc_version": a.dracc_version,
        "settings": _plain(a.settings),
        "inputs": [
            {
                "path": f.path,
                "format": f.format,
                "lines": int(f.lines),
                "records": int(f.records),
                "rejected": {k: int(v) for k, v in f.rejected.items()},
                "ignored": {k: int(v) for k, v in f.ignored.items()},
            }
            for f in a.inputs
        ],
        "lines": int(a.lines),
        "rejected": {k: int(v) for k, v in a.rejected.items()},
        "ignored": {k: int(v) for k, v in a.ignored.items()},
        "reject_examples": {
            k: [{"file": f, "line": int(n), "text": t} for f, n, t in v]
            for k, v in a.reject_examples.items()
        },
        "time_events": {
            "duplicates": a.time.duplicates,
            "backsteps": a.time.backsteps,
            "gaps": a.time.gaps,
            "rollovers": a.time.rollovers,
            "implausible_dates": a.time.implausible_dates,
            "assumed_date": a.time.assumed_date,
            "decisions": list(a.time.decisions),
        },
        "sources": by_role,
        "source_keys": {
            s.key: {
                "roles": list(s.roles),
                "records": int(s.records),
                "sentences": {k: int(v) for k, v in s.sentences.items()},
                "first_utc": iso_utc(s.first_ns),
                "last_utc": iso_utc(s.last_ns),
                "witness_for": s.witness_for,
                "choice": s.choice,
                "clock": clock_dict(s.clock),
            }
            for s in a.sources
        },
        "period": {
            "start_utc": iso_utc(a.start_ns),
            "end_utc": iso_utc(a.end_ns),
            "duration_s": _num(a.duration_s),
        },
        "deviation": None if a.deviation is None else _deviation(a),
        "dead_reckoning": None if a.dead_reckoning is None else _dead_reckoning(a.dead_reckoning),
        "calibration": None if a.calibration is None else _calibration(a.calibration),
        "current": None if a.current is None else _current(a.current),
        "estimated_position": (
            None if a.estimated_position is None else _estimated_position(a.estimated_position)
        ),
        "missing": list(a.missing),
        "notes": list(a.notes),
        "faults": [f.to_dict() for f in a.faults],
        "integrity": None if a.integrity is None else integrity_dict(a.integrity),
        "worst_ins_unit": None if worst is None else worst.to_dict(),
    }


def check_dict(c: Check, consequences: Sequence[Check] = ()) -> dict[str, Any]:
    """One integrity check (dracc.math.integrity) as plain JSON types; ``consequences``:
    the failed checks it caused (:func:`dracc.math.integrity.causes.failed_with_consequences`)."""
    window = {
        "start_utc": iso_utc(c.window.get("start_ns")),
        "end_utc": iso_utc(c.window.get("end_ns")),
    }
    return {
        "check": c.check,
        "name": c.name,
        "source": c.source,
        "role": c.role,
        "status": c.status,
        "clause": c.clause,
        "statistic": _plain(c.statistic),
        "threshold": _plain(c.threshold),
        "window": window,
        "false_alarm": _num(c.false_alarm),
        "message": c.message,
        "evidence": [_plain(e) for e in c.evidence],
        "why_not": c.why_not,
        "detail": _plain(c.detail),
        "consequences": [
            {"check": k.check, "name": k.name, "source": k.source, "message": k.message}
            for k in consequences
        ],
    }


def integrity_dict(r: IntegrityResult) -> dict[str, Any]:
    """The integrity section: every check of every source, and the per-source figures."""
    under = {id(cause): caused for cause, caused in failed_with_consequences(r)}
    return {
        "false_alarm_per_check": _num(r.alpha),
        "false_alarm_per_night": _num(r.false_alarm_per_night),
        "period": {"start_utc": iso_utc(r.start_ns), "end_utc": iso_utc(r.end_ns)},
        "checks": [check_dict(c, under.get(id(c), ())) for c in r.checks],
        "sources": {
            s.source: {
                "role": s.role,
                "records": s.records,
                "cadence_s": _num(s.cadence_s),
                "availability": _num(s.availability),
                "latency_s": None if s.latency_s is None else _plain(s.latency_s),
            }
            for s in r.sources
        },
    }


def dumps(a: Analysis, indent: int | None = 1) -> str:
    """The report as JSON text (strict: no NaN literals)."""
    return json.dumps(to_dict(a), indent=indent, allow_nan=False, ensure_ascii=False) + "\n"


def write_json(a: Analysis, path: str | Path) -> None:
    """Write the report atomically to ``path``."""
    atomic.write_text(path, dumps(a))
