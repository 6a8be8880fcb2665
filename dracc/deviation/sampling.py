"""Sampling each unit's position and heading at the instants of the method.

The paper reads the INS every 1 h (or 2 h).  dracc samples at
``offset + k * interval`` from 00:00 UTC of the first reading's day, interpolating each
unit from its own time-tagged readings:

- both neighbouring readings within ``max_gap_s`` of the instant: linear interpolation
  (latitude linear, longitude and heading on the circle through :func:`angdiff`);
- only one within ``max_gap_s`` (a log that starts or ends there, or a one-sided
  dropout): that reading;
- none within ``max_gap_s``: NaN, the unit is missing at that instant (never filled).

The course channel is each unit's *heading* output (HDT/THS), not its course over
ground.  No I/O; :func:`unit_series_from_voyage` only selects columns from the
canonical frames.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..geodesy import angdiff, wrap_2pi, wrap_pi

DAY_NS = 86_400 * 1_000_000_000


@dataclass(frozen=True, eq=False)  # holds arrays: identity, not elementwise ==
class UnitSeries:
    """One unit's time-tagged readings (an INS, or the reference).

    Positions: ``pos_time_ns`` (int64 UTC ns), ``lat_rad``, ``lon_rad``;
    headings: ``hdg_time_ns``, ``heading_rad`` (true heading, [0, 2 pi)).
    Either part may be empty.  Readings need not be sorted; NaN readings are ignored.
    """

    pos_time_ns: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    lat_rad: np.ndarray = field(default_factory=lambda: np.empty(0))
    lon_rad: np.ndarray = field(default_factory=lambda: np.empty(0))
    hdg_time_ns: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    heading_rad: np.ndarray = field(default_factory=lambda: np.empty(0))

    def __post_init__(self) -> None:
        if not (len(self.pos_time_ns) == len(self.lat_rad) == len(self.lon_rad)):
            raise ValueError("UnitSeries: pos_time_ns, lat_rad, lon_rad differ in length")
        if len(self.hdg_time_ns) != len(self.heading_rad):
            raise ValueError("UnitSeries: hdg_time_ns and heading_rad differ in length")

    def span_ns(self) -> tuple[int, int] | None:
        """(first, last) reading time over positions and headings, None if no readings."""
        t = np.concatenate([np.asarray(self.pos_time_ns, np.int64),
                            np.asarray(self.hdg_time_ns, np.int64)])
        return (int(t.min()), int(t.max())) if len(t) else None


@dataclass(frozen=True, eq=False)  # holds arrays: identity, not elementwise ==
class SampledUnit:
    """One unit at the sampling instants; NaN where missing."""

    lat_rad: np.ndarray
    lon_rad: np.ndarray
    heading_rad: np.ndarray


def sampling_instants(first_ns: int, last_ns: int, interval_s: float, offset_s: float = 0.0):
    """Instants ``t_k = midnight(first) + offset + k * interval`` lying in [first, last].

    ``midnight(first)`` is 00:00 UTC of the day of ``first_ns``.  int64 ns, sorted.
    """
    if interval_s <= 0:
        raise ValueError(f"interval_s must be positive, got {interval_s}")
    step = int(round(interval_s * 1e9))
    off = int(round(offset_s * 1e9))
    origin = first_ns - first_ns % DAY_NS + off
    k0 = -((origin - first_ns) // step)  # ceil((first - origin) / step)
    k1 = (last_ns - origin) // step
    if k1 < k0:
        return np.empty(0, np.int64)
    return origin + np.arange(k0, k1 + 1, dtype=np.int64) * step


def _clean(t_ns, values):
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


def interpolate_at(t_ns, values, instants_ns, max_gap_s: float, circular=(False,)):
    """Interpolate readings to ``instants_ns`` (rules in the module docstring).

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


def sample_unit(unit: UnitSeries, instants_ns, max_gap_s: float) -> SampledUnit:
    """Position and heading of one unit at the instants (NaN where missing)."""
    pos = interpolate_at(unit.pos_time_ns, np.vstack([unit.lat_rad, unit.lon_rad]),
                         instants_ns, max_gap_s, circular=(False, True))
    hdg = interpolate_at(unit.hdg_time_ns, np.asarray(unit.heading_rad, float)[None, :],
                         instants_ns, max_gap_s, circular=(True,))[0]
    return SampledUnit(lat_rad=pos[0], lon_rad=pos[1], heading_rad=wrap_2pi(hdg))


def unit_series_from_frames(position, heading) -> UnitSeries:
    """Readings of one unit from canonical ``position`` and ``heading`` frames (either None).

    Positions with GGA fix quality 0 (invalid) are left out; headings only where the
    reference is true ('T': HDT, THS) — a magnetic heading is not an INS course.
    """
    kw: dict = {}
    if position is not None and len(position):
        pos = position[position["quality"] != 0]
        kw.update(pos_time_ns=pos["time_ns"].to_numpy(np.int64),
                  lat_rad=pos["lat_rad"].to_numpy(float), lon_rad=pos["lon_rad"].to_numpy(float))
    if heading is not None and len(heading):
        hdg = heading[heading["reference"] == "T"]
        kw.update(hdg_time_ns=hdg["time_ns"].to_numpy(np.int64),
                  heading_rad=hdg["heading_rad"].to_numpy(float))
    return UnitSeries(**kw)


def unit_series_from_voyage(voyage, role: str) -> UnitSeries:
    """Readings of ``role`` from a :class:`dracc.ingest.frames.Voyage`
    (see :func:`unit_series_from_frames` for what is left out)."""
    return unit_series_from_frames(voyage.frame("position", role), voyage.frame("heading", role))
