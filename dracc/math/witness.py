"""Witnesses: what the *other* sources of a voyage say about the ship's motion over a
stretch of time, and the resolution of a source's readings learned from its values.

No source is the truth; every source is a witness.  A repeated reading (a position that
does not move, a heading that does not turn) is a fault only where another source shows
the ship moving or turning by more than the repeating sensor could have resolved.  This
module measures both sides; :mod:`dracc.math.faults` judges.

Resolution (:func:`quantum`)
    the largest step ``q`` of a fixed list of the steps logs are written with (whole,
    half, tenths ... of a degree or of a minute of arc; 1e-4 rad of NMEA 2000 ...) of
    which at least 98 % of a source's distinct values are whole multiples: an AIS
    heading in whole degrees has ``q = 1 deg``, a gyro's HDT with one decimal
    ``0.1 deg``; values on no such grid (simulated, or computed) give ``q = 0``.
Motion over the ground (:func:`ground_witness`)
    the median SOG of the other sources' ground records; without any, the net
    displacement of each other position source over the stretch divided by its length
    (the median over those sources); without either, the log, whose speed through the
    water proves motion over the ground only beyond the current a ship can lie in at a
    berth (:data:`BERTH_CURRENT_KN`).  An INS's own drift (a knot an hour) is why its
    velocity, not its position, witnesses first.
Turning (:func:`turn_witness`)
    per other heading source, the spread ``max - min`` of its readings about their
    circular mean over the stretch, less what its own noise and resolution could make of
    a steady heading: ``spread - 2 sqrt(2 ln N) sigma - q_w`` (the expected range of
    ``N`` normal samples; ``sigma^2 = max(0, -mean(d_k d_{k+1}))`` from successive first
    differences ``d``, which white noise makes anticorrelated and a real turn or yaw
    does not).  The smallest such turn over the witnesses covering the stretch is what
    they prove (every one must show it).  Only where
    no other source gives a heading, the COG of any source (also one under the
    heading's own key: another instrument) while it shows the ship moving, and then its
    net change (the first third's circular mean against the last's): a course swings
    with the current, the leeway and the yaw by degrees while the heading holds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from dracc.core.arrays import FloatArray
from dracc.core.geodesy import angdiff, circmean, distance_m
from dracc.core.units import DEG_RAD, KN_MPS, NS_PER_S

__all__ = [
    "BERTH_CURRENT_KN",
    "GroundWitness",
    "TurnWitness",
    "ground_witness",
    "turn_witness",
]

#: a log alone proves the ship moved over the ground only beyond this speed through the
#: water: the tidal stream a moored ship's log can read at a berth
BERTH_CURRENT_KN = 2.0


def _window(
    df: pd.DataFrame | None, exclude: str, a_ns: int, b_ns: int, only: str | None = None
) -> pd.DataFrame | None:
    """Rows of the other sources (or of source ``only``) of a time-sorted frame within
    [a, b]."""
    if df is None or df.empty:
        return None
    t = df["time_ns"].to_numpy(np.int64)
    i, j = np.searchsorted(t, a_ns, "left"), np.searchsorted(t, b_ns, "right")
    w = df.iloc[i:j]
    src = w["source"].to_numpy()
    w = w[(src == only) if only is not None else (src != exclude)]
    return w if len(w) else None


@dataclass(frozen=True)
class GroundWitness:
    """What the other sources say about motion over the ground over [a, b]."""

    speed_mps: float  #: NaN without a witness
    how: str  #: 'SOG', 'positions', 'log' or '' (none)
    sources: tuple[str, ...]  #: the witnesses' keys

    @property
    def found(self) -> bool:
        return math.isfinite(self.speed_mps)

    def moving(self, moving_mps: float) -> bool:
        """True where the witness shows the ship moving at ``moving_mps`` or more (a log
        alone only beyond the current it may read at a berth)."""
        floor = moving_mps + (BERTH_CURRENT_KN * KN_MPS if self.how == "log" else 0.0)
        return self.found and self.speed_mps >= floor

    def words(self) -> str:
        if not self.found:
            return "no other source of speed"
        via = {"SOG": "SOG", "positions": "speed of the fixes", "log": "log speed"}[self.how]
        return f"{via} {self.speed_mps / KN_MPS:.1f} kn ({', '.join(self.sources)})"


def ground_witness(
    frames: Mapping[str, pd.DataFrame],
    exclude: str,
    a_ns: int,
    b_ns: int,
    only: str | None = None,
) -> GroundWitness:
    """The other sources' evidence of motion over the ground over [a, b] (module
    docstring): SOG, else the net motion of other position sources, else the log.
    With ``only``, what that one source says of itself (shown, never a witness)."""
    w = _window(frames.get("ground"), exclude, a_ns, b_ns, only)
    if w is not None:
        v = np.abs(w["sog_mps"].to_numpy(float))
        ok = np.isfinite(v)
        if ok.any():
            sog = tuple(sorted({str(s) for s in w["source"].to_numpy()[ok]}))
            return GroundWitness(float(np.median(v[ok])), "SOG", sog)
    w = _window(frames.get("position"), exclude, a_ns, b_ns, only)
    if w is not None and b_ns > a_ns and only is None:
        speeds: list[float] = []
        keys: list[str] = []
        for key, g in w.groupby("source", observed=True):
            q = g["quality"].to_numpy() if "quality" in g else np.ones(len(g))
            la, lo = g["lat_rad"].to_numpy(float), g["lon_rad"].to_numpy(float)
            ok = np.isfinite(la) & np.isfinite(lo) & (q != 0)
            t = g["time_ns"].to_numpy(np.int64)[ok]
            if ok.sum() < 2 or (t[-1] - t[0]) < 0.5 * (b_ns - a_ns):
                continue
            la, lo = la[ok], lo[ok]
            d = float(distance_m(la[0], lo[0], la[-1], lo[-1]))
            speeds.append(d / ((t[-1] - t[0]) / NS_PER_S))
            keys.append(str(key))
        if speeds:
            return GroundWitness(float(np.median(speeds)), "positions", tuple(sorted(keys)))
    # the log is another instrument even where it talks under the position's own key (an
    # instrument bus, NMEA 0183 'II', relays the GNSS, the compass and the log alike)
    w = _window(frames.get("water"), "" if only is None else exclude, a_ns, b_ns, only)
    if w is not None:
        v = np.abs(w["stw_mps"].to_numpy(float))
        ok = np.isfinite(v)
        if ok.any():
            logs = tuple(sorted({str(s) for s in w["source"].to_numpy()[ok]}))
            return GroundWitness(float(np.median(v[ok])), "log", logs)
    return GroundWitness(math.nan, "", ())


@dataclass(frozen=True)
class TurnWitness:
    """What the other sources say about turning over [a, b]: the largest spread of a
    witness's headings (or COG) and the largest turn beyond its own noise and resolution."""

    spread_rad: float  #: NaN without a witness
    turn_rad: float  #: spread less noise and resolution (NaN without a witness)
    sources: tuple[str, ...]

    @property
    def found(self) -> bool:
        return math.isfinite(self.turn_rad)


def _spread_and_turn(h: FloatArray, q_w: float) -> tuple[float, float]:
    """(spread about the circular mean, spread less noise range and resolution)."""
    d = angdiff(h, circmean(h))
    spread = float(np.max(d) - np.min(d))
    dd = np.diff(d)
    var = -float(np.mean(dd[1:] * dd[:-1])) if dd.size >= 3 else 0.0
    noise = 2.0 * math.sqrt(2.0 * math.log(max(h.size, 2))) * math.sqrt(max(var, 0.0))
    return spread, spread - noise - q_w


def turn_witness(
    frames: Mapping[str, pd.DataFrame],
    exclude: str,
    a_ns: int,
    b_ns: int,
    moving_mps: float,
    quanta: Mapping[str, float],
) -> TurnWitness:
    """The other heading sources (and COG while moving) over [a, b] (module docstring);
    ``quanta``: source key -> resolution of its headings (0 where unknown).  A witness
    must cover half the stretch with at least 6 readings; the turn proven is the
    smallest over the witnesses (every one must show it: one wandering compass among
    steady gyros proves nothing), the spread shown the largest."""
    spreads, turns, keys = [], [], []
    w = _window(frames.get("heading"), exclude, a_ns, b_ns)
    if w is not None:
        for key, g in w.groupby("source", observed=True):
            h = g["heading_rad"].to_numpy(float)
            ok = np.isfinite(h)
            if _covers(g["time_ns"].to_numpy(np.int64)[ok], a_ns, b_ns):
                s, t = _spread_and_turn(h[ok], quanta.get(str(key), 0.0))
                spreads.append(s)
                turns.append(t)
                keys.append(str(key))
    # no other heading: the course of any GNSS, also one under the heading's own key (an
    # instrument bus relays compass and GNSS alike), while moving, net of its swing
    w = _window(frames.get("ground"), "", a_ns, b_ns) if not keys else None
    if w is not None:
        for key, g in w.groupby("source", observed=True):
            c = g["cog_rad"].to_numpy(float)
            ok = np.isfinite(c) & (g["sog_mps"].to_numpy(float) >= moving_mps)
            if _covers(g["time_ns"].to_numpy(np.int64)[ok], a_ns, b_ns):
                c = c[ok]
                third = c.size // 3
                spreads.append(_spread_and_turn(c, 0.0)[0])
                turns.append(abs(float(angdiff(circmean(c[-third:]), circmean(c[:third])))))
                keys.append(f"{key} COG")
    if not keys:
        return TurnWitness(math.nan, math.nan, ())
    return TurnWitness(max(spreads), max(min(turns), 0.0), tuple(sorted(set(keys))))


def _covers(t: np.ndarray, a_ns: int, b_ns: int) -> bool:
    """At least 6 readings spanning half of [a, b]."""
    return t.size >= 6 and (t[-1] - t[0]) >= 0.5 * (b_ns - a_ns)


def heading_spread_deg(
    frames: Mapping[str, pd.DataFrame], exclude: str, a_ns: int, b_ns: int
) -> float:
    """The largest spread of the other heading sources over [a, b] in degrees (NaN
    without one): the 'heading spread' a report of a ship at rest states."""
    w = _window(frames.get("heading"), exclude, a_ns, b_ns)
    spreads = []
    if w is not None:
        for _, g in w.groupby("source", observed=True):
            h = g["heading_rad"].to_numpy(float)
            h = h[np.isfinite(h)]
            if h.size >= 2:
                d = angdiff(h, circmean(h))
                spreads.append(float(np.max(d) - np.min(d)) / DEG_RAD)
    return max(spreads) if spreads else math.nan
