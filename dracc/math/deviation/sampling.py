"""Sampling each unit's position and heading at the instants of the method.

The paper reads the INS every 1 h (or 2 h) *at the same instant*.  Real units sample at
their own phases (0.2-0.4 s apart is common), so dracc interpolates each unit from its
own time-tagged readings to the common instant ``offset + k * interval`` (from 00:00 UTC
of the first reading's day) with :func:`align_at`:

- the instant must lie inside the unit's data (first reading <= instant <= last): a
  reading is never held past the end of the data nor before its start
  (reason ``outside unit span``);
- a reading exactly at the instant is used as it is; otherwise the readings on both
  sides must lie within ``max_gap_s`` of the instant (reason ``gap too long``);
- between them: latitude linearly in time, longitude and heading on the circle (through
  :func:`angdiff`: 359 -> 1 deg passes through 0, the antimeridian does no harm); where
  the nearer reading is more than ``velocity_min_gap_s`` away, positions follow the
  unit's own velocity over ground (its VTG/RMC ``ground`` readings): the quadratic in
  time through both readings whose slope changes as the unit's velocity does (the line
  plus the sag of the turn), so the ship's turn between the readings is followed, and
  the readings' own noise is weighted exactly as by the line; without a velocity (and
  for heading, which has no rate per unit) the interpolation stays linear.

Where a unit is not sampled its value is NaN and the reason code is returned: never filled.
The course channel is each unit's *heading* output (HDT/THS), not its course over
ground.  No I/O; :func:`unit_series_from_voyage` only selects columns from the
canonical frames.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dracc.core.bounds import check_work
from dracc.core.geodesy import angdiff, k_lambda, k_phi, wrap_2pi, wrap_pi

if TYPE_CHECKING:
    import pandas as pd

    from dracc.frames import Voyage

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
ReasonArray = NDArray[np.int8]  #: SAMPLED, OUTSIDE_SPAN or GAP_TOO_LONG per instant

DAY_NS = 86_400 * 1_000_000_000
#: reason codes of :func:`align_at` (0: sampled)
SAMPLED, OUTSIDE_SPAN, GAP_TOO_LONG = 0, 1, 2
#: the reason of each code, as reported (``skipped`` of the deviation result)
REASONS = {OUTSIDE_SPAN: "outside unit span", GAP_TOO_LONG: "gap too long"}


@dataclass(frozen=True, eq=False)  # holds arrays: identity, not elementwise ==
class UnitSeries:
    """One unit's time-tagged readings (an INS, or the reference).

    Positions: ``pos_time_ns`` (int64 UTC ns), ``lat_rad``, ``lon_rad``;
    headings: ``hdg_time_ns``, ``heading_rad`` (true heading, [0, 2 pi)).
    ground velocity (optional, from VTG/RMC): ``vel_time_ns``, ``vn_mps``, ``ve_mps``
    (north and east components of the speed over ground), used to follow the ship's
    motion between position readings.
    Any part may be empty.  Readings need not be sorted; NaN readings are ignored.
    """

    pos_time_ns: IntArray = field(default_factory=lambda: np.empty(0, np.int64))
    lat_rad: FloatArray = field(default_factory=lambda: np.empty(0))
    lon_rad: FloatArray = field(default_factory=lambda: np.empty(0))
    hdg_time_ns: IntArray = field(default_factory=lambda: np.empty(0, np.int64))
    heading_rad: FloatArray = field(default_factory=lambda: np.empty(0))
    vel_time_ns: IntArray = field(default_factory=lambda: np.empty(0, np.int64))
    vn_mps: FloatArray = field(default_factory=lambda: np.empty(0))
    ve_mps: FloatArray = field(default_factory=lambda: np.empty(0))

    def __post_init__(self) -> None:
        if not (len(self.pos_time_ns) == len(self.lat_rad) == len(self.lon_rad)):
            raise ValueError("UnitSeries: pos_time_ns, lat_rad, lon_rad differ in length")
        if len(self.hdg_time_ns) != len(self.heading_rad):
            raise ValueError("UnitSeries: hdg_time_ns and heading_rad differ in length")
        if not (len(self.vel_time_ns) == len(self.vn_mps) == len(self.ve_mps)):
            raise ValueError("UnitSeries: vel_time_ns, vn_mps, ve_mps differ in length")

    def span_ns(self) -> tuple[int, int] | None:
        """(first, last) reading time over positions and headings, None if no readings."""
        t = np.concatenate(
            [np.asarray(self.pos_time_ns, np.int64), np.asarray(self.hdg_time_ns, np.int64)]
        )
        return (int(t.min()), int(t.max())) if len(t) else None


@dataclass(frozen=True, eq=False)  # holds arrays: identity, not elementwise ==
class SampledUnit:
    """One unit at the sampling instants; NaN where missing, with the reason codes
    (:data:`REASONS`; 0 where sampled) of positions and headings (None: not given)."""

    lat_rad: FloatArray
    lon_rad: FloatArray
    heading_rad: FloatArray
    pos_reason: ReasonArray | None = None
    hdg_reason: ReasonArray | None = None

    def select(self, keep: NDArray[np.bool_]) -> SampledUnit:
        """The unit at the instants where ``keep`` is true."""
        return SampledUnit(
            self.lat_rad[keep],
            self.lon_rad[keep],
            self.heading_rad[keep],
            None if self.pos_reason is None else self.pos_reason[keep],
            None if self.hdg_reason is None else self.hdg_reason[keep],
        )


def sampling_instants(
    first_ns: int, last_ns: int, interval_s: float, offset_s: float = 0.0
) -> IntArray:
    """Instants ``t_k = midnight(first) + offset + k * interval`` lying in [first, last].

    ``midnight(first)`` is 00:00 UTC of the day of ``first_ns``.  int64 ns, sorted.
    """
    if interval_s <= 0:
        raise ValueError(f"interval_s must be positive, got {interval_s}")
    check_work("deviation", "interval_s", interval_s, (last_ns - first_ns) / 1e9)
    step = int(round(interval_s * 1e9))
    off = int(round(offset_s * 1e9))
    origin = first_ns - first_ns % DAY_NS + off
    k0 = -((origin - first_ns) // step)  # ceil((first - origin) / step)
    k1 = (last_ns - origin) // step
    if k1 < k0:
        return np.empty(0, np.int64)
    return origin + np.arange(k0, k1 + 1, dtype=np.int64) * step


def _clean(t_ns: ArrayLike, values: ArrayLike) -> tuple[IntArray, FloatArray]:
    """Sorted (stable) readings with NaN values removed."""
    t = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[None, :]
    ok = ~np.any(np.isnan(v), axis=0)
    if not np.all(ok):
        t, v = t[ok], v[:, ok]
    if np.any(t[1:] < t[:-1]):  # logs are nearly always in order: sort only when not
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[:, order]
    return t, v


def interpolate_at(
    t_ns: ArrayLike,
    values: ArrayLike,
    instants_ns: ArrayLike,
    max_gap_s: float,
    circular: Sequence[bool] = (False,),
) -> FloatArray:
    """Interpolate readings to ``instants_ns``, holding the nearer reading where only one
    side lies within ``max_gap_s`` (also past the ends of the data).  The method does not
    use this rule (it invents values past a unit's data); it samples with :func:`align_at`.

    ``values``: shape (C, m) channels of readings at ``t_ns`` (m,); ``circular[c]``
    True makes channel c an angle (interpolated through angdiff, result in (-pi, pi]
    for longitude-like channels; the caller wraps headings).  Returns shape (C, k).
    """
    t, v = _clean(t_ns, values)
    inst = np.asarray(instants_ns, dtype=np.int64)
    n_ch = v.shape[0]
    out = np.full((n_ch, len(inst)), np.nan)
    if len(t) == 0 or len(inst) == 0:
        return out
    gap_ns = max_gap_s * 1e9
    # right neighbour index: first reading with t >= instant
    j = np.searchsorted(t, inst, side="left")
    jr = np.minimum(j, len(t) - 1)
    jl = np.maximum(j - 1, 0)
    exact = (j < len(t)) & (t[jr] == inst)
    jl = np.where(exact, jr, jl)  # an exact hit uses that reading alone
    dt_l = (inst - t[jl]).astype(float)  # >= 0 where a left neighbour exists
    dt_r = (t[jr] - inst).astype(float)
    has_l = (j > 0) | exact
    has_r = j < len(t)
    ok_l = has_l & (dt_l >= 0) & (dt_l <= gap_ns)
    ok_r = has_r & (dt_r >= 0) & (dt_r <= gap_ns)
    both = ok_l & ok_r & ~exact & (t[jr] > t[jl])
    span = np.where(both, (t[jr] - t[jl]).astype(float), 1.0)
    frac = np.where(both, dt_l / span, 0.0)
    for c in range(n_ch):
        vl, vr = v[c, jl], v[c, jr]
        circ = circular[c] if c < len(circular) else False
        step = angdiff(vr, vl) if circ else vr - vl
        interp = vl + frac * step
        if circ:
            interp = wrap_pi(interp)
        single = np.where(ok_l & (~ok_r | (dt_l <= dt_r)), vl, vr)
        val = np.where(both, interp, single)
        out[c] = np.where(ok_l | ok_r, val, np.nan)
    return out


def _clean_index(t_ns: ArrayLike, values: ArrayLike) -> NDArray[np.intp]:
    """Indices of the valid (non-NaN) readings, sorted (stable) by time."""
    t = np.asarray(t_ns, dtype=np.int64)
    v = np.asarray(values, dtype=float)
    if v.ndim == 1:
        v = v[None, :]
    idx = np.flatnonzero(~np.any(np.isnan(v), axis=0))
    if np.any(t[idx][1:] < t[idx][:-1]):
        idx = idx[np.argsort(t[idx], kind="stable")]
    return idx


def align_at(
    t_ns: ArrayLike,
    values: ArrayLike,
    instants_ns: ArrayLike,
    max_gap_s: float,
    circular: Sequence[bool] = (False,),
    rates: ArrayLike | None = None,
    velocity_min_gap_s: float = 0.0,
) -> tuple[FloatArray, ReasonArray]:
    """One unit's readings at the common ``instants_ns`` (rules in the module docstring).

    ``values``: (C, m) channels at ``t_ns`` (m,); ``circular[c]``: channel c is an angle
    (result in (-pi, pi]; the caller wraps headings).  ``rates``: None or (C, m) time
    derivatives per second at the readings (NaN where unknown): where both bracketing
    readings have one and the nearer reading is more than ``velocity_min_gap_s`` from the
    instant, the line plus the sag ``-h^2 s (1 - s) a / 2`` of a constant acceleration
    ``a = (rate_r - rate_l) / h`` (h the gap, s its fraction before the instant);
    otherwise linear.
    Returns ``(out (C, k), reason (k,) int8)``: reason 0 sampled, :data:`OUTSIDE_SPAN`
    (before the first or after the last valid reading), :data:`GAP_TOO_LONG`.
    """
    v_all = np.asarray(values, dtype=float)
    if v_all.ndim == 1:
        v_all = v_all[None, :]
    idx = _clean_index(t_ns, v_all)
    t = np.asarray(t_ns, dtype=np.int64)[idx]
    v = v_all[:, idx]
    inst = np.asarray(instants_ns, dtype=np.int64)
    n_ch = v.shape[0]
    out = np.full((n_ch, len(inst)), np.nan)
    reason = np.full(len(inst), OUTSIDE_SPAN, dtype=np.int8)
    if len(t) == 0 or len(inst) == 0:
        return out, reason
    inside = (inst >= t[0]) & (inst <= t[-1])
    j = np.clip(np.searchsorted(t, inst, side="left"), 0, len(t) - 1)
    exact = inside & (t[j] == inst)
    jr = j
    jl = np.where(exact, j, np.maximum(j - 1, 0))
    dt_l = (inst - t[jl]).astype(float) / 1e9
    dt_r = (t[jr] - inst).astype(float) / 1e9
    near = exact | ((dt_l <= max_gap_s) & (dt_r <= max_gap_s))
    ok = inside & near
    reason[inside & ~near] = GAP_TOO_LONG
    reason[ok] = SAMPLED
    h = np.where(ok & ~exact, (t[jr] - t[jl]).astype(float) / 1e9, 1.0)
    s = np.where(ok & ~exact, dt_l / h, 0.0)
    r = None if rates is None else np.asarray(rates, dtype=float)[:, idx]
    curved = ok & ~exact & (np.minimum(dt_l, dt_r) > velocity_min_gap_s)
    for c in range(n_ch):
        vl, vr = v[c, jl], v[c, jr]
        circ = circular[c] if c < len(circular) else False
        step = angdiff(vr, vl) if circ else vr - vl
        val = vl + s * step
        if r is not None:
            ml, mr = r[c, jl], r[c, jr]
            use = curved & np.isfinite(ml) & np.isfinite(mr)
            if np.any(use):
                # the quadratic through both readings whose slope changes by mr - ml over
                # the gap: the line plus the sag of the turn, -h^2 s (1 - s) a / 2 with
                # a = (mr - ml) / h.  Only the velocity *change* enters, so the readings'
                # own noise is weighted as by the line (exact for a constant acceleration;
                # a turn's arc to (v h theta)^2-small terms)
                sag = -0.5 * h * s * (1.0 - s) * (mr - ml)
                val = np.where(use, val + sag, val)
        if circ:
            val = wrap_pi(val)
        out[c] = np.where(ok, val, np.nan)
    return out, reason


def sample_unit(
    unit: UnitSeries, instants_ns: ArrayLike, max_gap_s: float, velocity_min_gap_s: float = 0.1
) -> SampledUnit:
    """Position and heading of one unit at the instants (NaN where not sampled), each
    interpolated to the instant (:func:`align_at`); positions follow the unit's own ground
    velocity between readings where it has one (VTG/RMC within ``max_gap_s``)."""
    pos_t = np.asarray(unit.pos_time_ns, np.int64)
    lat = np.asarray(unit.lat_rad, float)
    rates = None
    if len(unit.vel_time_ns) and len(pos_t):
        vel, _ = align_at(unit.vel_time_ns, np.vstack([unit.vn_mps, unit.ve_mps]), pos_t, max_gap_s)
        rates = np.vstack([vel[0] * k_phi(lat), vel[1] * k_lambda(lat)])  # rad/s (B18, B19)
    pos, pos_reason = align_at(
        pos_t,
        np.vstack([lat, unit.lon_rad]),
        instants_ns,
        max_gap_s,
        circular=(False, True),
        rates=rates,
        velocity_min_gap_s=velocity_min_gap_s,
    )
    hdg, hdg_reason = align_at(
        unit.hdg_time_ns,
        np.asarray(unit.heading_rad, float)[None, :],
        instants_ns,
        max_gap_s,
        circular=(True,),
    )
    return SampledUnit(
        lat_rad=pos[0],
        lon_rad=pos[1],
        heading_rad=wrap_2pi(hdg[0]),
        pos_reason=pos_reason,
        hdg_reason=hdg_reason,
    )


def unit_series_from_frames(
    position: pd.DataFrame | None,
    heading: pd.DataFrame | None,
    ground: pd.DataFrame | None = None,
) -> UnitSeries:
    """Readings of one unit from canonical ``position``, ``heading`` and ``ground`` frames
    (any None); ``ground`` (VTG/RMC course and speed over ground) gives the velocity.

    Positions with GGA fix quality 0 (invalid) are left out; headings only where the
    reference is true ('T': HDT, THS) — a magnetic heading is not an INS course.
    """
    kw: dict[str, Any] = {}
    if position is not None and len(position):
        pos = position[position["quality"] != 0]
        kw.update(
            pos_time_ns=pos["time_ns"].to_numpy(np.int64),
            lat_rad=pos["lat_rad"].to_numpy(float),
            lon_rad=pos["lon_rad"].to_numpy(float),
        )
    if heading is not None and len(heading):
        hdg = heading[heading["reference"] == "T"]
        kw.update(
            hdg_time_ns=hdg["time_ns"].to_numpy(np.int64),
            heading_rad=hdg["heading_rad"].to_numpy(float),
        )
    if ground is not None and len(ground):
        cog, sog = ground["cog_rad"].to_numpy(float), ground["sog_mps"].to_numpy(float)
        kw.update(
            vel_time_ns=ground["time_ns"].to_numpy(np.int64),
            vn_mps=sog * np.cos(cog),
            ve_mps=sog * np.sin(cog),
        )
    return UnitSeries(**kw)


def unit_series_from_voyage(voyage: Voyage, role: str) -> UnitSeries:
    """Readings of ``role`` from a :class:`dracc.frames.Voyage`
    (see :func:`unit_series_from_frames` for what is left out)."""
    return unit_series_from_frames(
        voyage.frame("position", role), voyage.frame("heading", role), voyage.frame("ground", role)
    )
