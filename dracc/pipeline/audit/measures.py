"""The night's measures a fleet ranks: one small record per unit and quantity.

:func:`night_measures` reads an :class:`~dracc.pipeline.results.Analysis` into the
figures the fleet ranking compares across vessels and along each unit's own nights
(:mod:`dracc.pipeline.fleet.ranking`).  The same list goes into the fleet cache, the
audit document (``measures``) and the audit state database, so a shore office ranks a
fleet from the nightly documents alone and gets what the raw logs would give.

Quantities (``measure_unit`` in brackets) and how each is obtained:

``lat_m_y``, ``lon_m_y`` [m]  the unit's own RMS position error: against GNSS where the
    analysis has a reference (``method='reference'``, Table 1's error RMS, with its
    independent samples as degrees of freedom); else the three-cornered hat
    (``'hat'``, degrees of freedom from its Wishart upper bound); else the factor method m_y = k m_u
    (``'factor'``, K5, which blames all three units for one bad one) where there is no
    hat (fewer than three units).  A negative hat variance (a unit much better than the
    others) gives no figure: the factor method would blame it for its neighbour.
``course_m_y`` [deg]  the hat where three units give one, else the factor method.
``log_scale`` [%]     the speed log's scale error s with its sigma (calibration).
``compass_error`` [deg]  the compass error with its sigma (calibration).
``dr_consistency`` [%]  the DR's containment in 2M over the scored epochs (n), whose
    binomial sigma at the nominal 95 % is sqrt(0.95 * 0.05 / n).
``latency`` [s]       the 95th percentile of |receive time - time of fix| per source.
``availability`` [%]  the share of the night without a drop-out per source.

RMS quantities carry ``dof`` (their spread in log is about 1/sqrt(2 dof)); the others a
``sigma`` where the analysis gives one.  A figure the analysis could not make is left
out, never zero.  ``position`` is the night's mean position (the sea area of the log).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from dracc.core.numbers import finite_or_none
from dracc.core.vocabulary import CHANNELS

if TYPE_CHECKING:
    from dracc.pipeline.results import Analysis

#: quantity -> the unit of its figures
QUANTITY_UNITS = {
    "lat_m_y": "m",
    "lon_m_y": "m",
    "course_m_y": "deg",
    "log_scale": "%",
    "compass_error": "deg",
    "dr_consistency": "%",
    "latency": "s",
    "availability": "%",
}

#: the nominal containment of a 2M circle
_P_2M = 0.95


def channel_quantity(channel: str) -> str:
    """The quantity of an INS channel's RMS error: 'lat' -> 'lat_m_y'."""
    return f"{channel}_m_y"


def _measure(
    unit: str,
    quantity: str,
    value: float | None,
    *,
    sigma: float | None = None,
    dof: float | None = None,
    n: int | None = None,
    method: str,
) -> dict[str, Any] | None:
    v = finite_or_none(value)
    if v is None:
        return None
    return {
        "unit": unit,
        "quantity": quantity,
        "measure_unit": QUANTITY_UNITS[quantity],
        "value": v,
        "sigma": finite_or_none(sigma),
        "dof": finite_or_none(dof),
        "n": None if n is None else int(n),
        "method": method,
    }


def _hat_dof(variance: float, var_upper: float, dof: float) -> float | None:
    """The degrees of freedom of a chi-square law whose 97.5 % bound sits where the hat's
    upper bound does: var_upper / var = exp(1.96 sqrt(2 / nu)), so nu = 2 (1.96 /
    ln(var_upper / var))^2 (never more than the pair variances' own ``dof``).  A good unit
    beside a bad one has a wide bound, so few degrees of freedom: its hat says little."""
    if not (variance > 0 and math.isfinite(var_upper) and var_upper > variance):
        return dof if math.isfinite(dof) else None
    nu = 2.0 * (1.959964 / math.log(var_upper / variance)) ** 2
    return min(nu, dof) if math.isfinite(dof) else nu


def _ins_measures(a: Analysis) -> list[dict[str, Any] | None]:
    dev = a.deviation
    if dev is None:
        return []
    rows: list[dict[str, Any] | None] = []
    for unit, per in sorted(dev.whole.units.items()):
        for ch in CHANNELS:
            quantity = channel_quantity(ch)
            ref = per.reference.get(ch)
            hat = per.hat.get(ch)
            st = per.channels.get(ch)
            if ref is not None and ref.n >= 2 and math.isfinite(ref.rmse):
                ref_dof = ref.n_independent if math.isfinite(ref.n_independent) else ref.n
                rows.append(
                    _measure(unit, quantity, ref.rmse, dof=ref_dof, n=ref.n, method="reference")
                )
            elif hat is not None and not hat.negative and math.isfinite(hat.sigma):
                hat_dof = _hat_dof(hat.variance, hat.var_upper, hat.dof)
                rows.append(_measure(unit, quantity, hat.sigma, dof=hat_dof, n=hat.n, method="hat"))
            elif hat is None and st is not None and st.n >= 2:  # fewer than three units
                st_dof = st.n_eff if math.isfinite(st.n_eff) else st.n
                rows.append(_measure(unit, quantity, st.m_y, dof=st_dof, n=st.n, method="factor"))
    return rows


def _mean_position(a: Analysis) -> dict[str, float] | None:
    """The night's mean position from the GNSS track (else any track), degrees."""
    tracks = sorted(a.tracks, key=lambda t: (t.role != "gnss", t.source))
    for t in tracks:
        ok = [i for i in range(len(t.lat_rad)) if math.isfinite(t.lat_rad[i])]
        if not ok:
            continue
        lat = sum(float(t.lat_rad[i]) for i in ok) / len(ok)
        # the circular mean of longitude (a voyage across the antimeridian)
        s = sum(math.sin(float(t.lon_rad[i])) for i in ok)
        c = sum(math.cos(float(t.lon_rad[i])) for i in ok)
        return {"lat_deg": math.degrees(lat), "lon_deg": math.degrees(math.atan2(s, c))}
    return None


def night_measures(a: Analysis) -> dict[str, Any]:
    """``{"position": {lat_deg, lon_deg} | None, "rows": [measure, …]}`` of one analysis."""
    rows = _ins_measures(a)
    cal = a.calibration
    if cal is not None and cal.log_scale is not None:
        s = cal.log_scale
        rows.append(
            _measure(
                "log",
                "log_scale",
                100.0 * s.value,
                sigma=100.0 * s.sigma,
                n=cal.n,
                method="calibration",
            )
        )
    if cal is not None and cal.compass_error_deg is not None:
        e = cal.compass_error_deg
        rows.append(
            _measure(
                "compass", "compass_error", e.value, sigma=e.sigma, n=cal.n, method="calibration"
            )
        )
    dr = a.dead_reckoning
    if dr is not None and dr.n_scored > 0:
        rows.append(
            _measure(
                "dr",
                "dr_consistency",
                100.0 * dr.containment_2m,
                sigma=100.0 * math.sqrt(_P_2M * (1 - _P_2M) / dr.n_scored),
                n=dr.n_scored,
                method="reference",
            )
        )
    integ = a.integrity
    for src in integ.sources if integ is not None else ():
        unit = str(src.role or src.source)
        lat = src.latency_s or {}
        if lat.get("n"):
            p95 = max(abs(finite_or_none(lat.get("p95")) or 0.0), 0.0)
            rows.append(_measure(unit, "latency", p95, n=int(lat["n"]), method="integrity"))
        if src.availability is not None:
            rows.append(
                _measure(
                    unit,
                    "availability",
                    100.0 * src.availability,
                    n=src.records,
                    method="integrity",
                )
            )
    kept = [r for r in rows if r is not None]
    # one figure per unit and quantity (a source in two roles is counted once)
    seen: set[tuple[str, str]] = set()
    unique = []
    for r in kept:
        key = (r["unit"], r["quantity"])
        if key not in seen:
            seen.add(key)
            unique.append(r)
    return {"position": _mean_position(a), "rows": unique}
