"""Sensor faults: physically impossible or dead readings found in the canonical frames.

Pure functions over the frames of :mod:`dracc.frames` (no I/O).  Each fault is
one :class:`SensorFault` naming the source key, its role, the kind, the first and last
record concerned and the raw values, so a report can show exactly what was seen.

Kinds and the rule that finds each (thresholds in :class:`dracc.core.config.FaultsConfig`):

``jump``
    consecutive valid fixes of one position source a distance ``d`` apart in ``dt``
    with ``d > jump_min_m`` and ``d / dt > max_speed_kn`` (``dt = 0`` counts as
    infinite speed).  The fault covers the displaced records: from the first record
    after the jump to the record before the next jump of that source (the jump back),
    or to its last record when it never comes back.  The step out of a frozen run
    (the unit catching up) belongs to the ``frozen`` fault, not to a jump.
``frozen``
    a position source repeating bit-identical latitude and longitude for at least
    ``frozen_min_s`` and ``min_records`` records, unless the other sources show the
    ship stationary then (median speed below ``moving_min_kn``).  A moored ship's
    receiver still jitters in its last digit; a dead unit does not.
``stuck_heading``
    a heading source repeating a bit-identical heading for at least ``stuck_min_s``
    and ``min_records`` records, unless the other sources show the ship neither
    turning (other headings, or COG above ``moving_min_kn``, spanning less than
    ``turn_min_deg``) nor moving.
``out_of_range``
    values no sensor can produce but that a reader passed through: latitude beyond
    +-90 deg, longitude beyond +-180 deg, heading or course outside [0, 360) deg,
    speed over ground negative, any speed beyond ``max_speed_kn`` in magnitude, rate
    of turn beyond ``max_rot_deg_per_min``.  Consecutive records of one source and
    quantity form one fault.

Distances use :func:`dracc.core.geodesy.distance_m`; angles are compared with
:func:`dracc.core.geodesy.angdiff`.  Times are int64 UTC nanoseconds; degrees, knots and
nautical miles appear only in the messages and the ``values`` shown to a reader.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, cast

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from dracc.core.arrays import BoolArray, FloatArray, IntArray
from dracc.core.config import FaultsConfig
from dracc.core.errors import ConfigError
from dracc.core.geodesy import angdiff, circmean, distance_m, offset_ne_m
from dracc.core.timefmt import iso_utc
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M, NS_PER_S
from dracc.frames import Voyage

__all__ = ["FAULT_KINDS", "SensorFault", "check_config", "detect_faults", "exclude_faults"]

FAULT_KINDS = ("jump", "frozen", "stuck_heading", "out_of_range")


@dataclass(frozen=True)
class SensorFault:
    """One sensor fault of one source.

    ``frame`` is the frame kind of the records concerned (``position``, ``heading``,
    ``ground``, ``water``, ``rot``); ``start_ns``/``end_ns`` the times of the first and
    last of them (inclusive), ``first_line`` the input line of the first;
    ``values`` the raw figures as (name, value) pairs with the unit in the name.
    """

    source: str
    role: str | None
    kind: str
    frame: str
    start_ns: int
    end_ns: int
    n_records: int
    first_line: int
    values: tuple[tuple[str, float], ...]
    message: str

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS_PER_S

    def to_dict(self) -> dict[str, Any]:
        """JSON form (times as ISO 8601 UTC and as integer nanoseconds)."""
        return {
            "source": self.source,
            "role": self.role,
            "kind": self.kind,
            "frame": self.frame,
            "start": iso_utc(unit="us", time_ns=self.start_ns),
            "end": iso_utc(unit="us", time_ns=self.end_ns),
            "start_ns": int(self.start_ns),
            "end_ns": int(self.end_ns),
            "duration_s": self.duration_s,
            "n_records": int(self.n_records),
            "first_line": int(self.first_line),
            "values": {k: (None if not math.isfinite(v) else float(v)) for k, v in self.values},
            "message": self.message,
        }


def check_config(cfg: FaultsConfig) -> FaultsConfig:
    """Raise ConfigError naming the key for a threshold that is not a positive number."""
    for f in fields(FaultsConfig):
        v = getattr(cfg, f.name)
        if f.name == "exclude":
            if not isinstance(v, bool):
                raise ConfigError(f"[faults] exclude must be true or false, got {v!r}")
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ConfigError(f"[faults] {f.name} must be a positive number, got {v!r}")
    return cfg


# ---------------------------------------------------------------------- helpers


def _runs(mask: NDArray[Any]) -> list[tuple[int, int]]:
    """[start, stop) index pairs of the runs of True in ``mask``."""
    m = np.concatenate(([False], np.asarray(mask, dtype=bool), [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def _equal_runs(*cols: NDArray[Any]) -> list[tuple[int, int]]:
    """[start, stop) of the runs of consecutive rows where every column repeats exactly."""
    same = np.ones(len(cols[0]) - 1, dtype=bool) if len(cols[0]) > 1 else np.zeros(0, bool)
    for c in cols:
        same &= c[1:] == c[:-1]
    # a run of k repeats in ``same`` at [a, b) covers rows [a, b + 1)
    return [(a, b + 1) for a, b in _runs(same)]


def _long_equal_runs(
    t: IntArray, min_records: int, min_s: float, *cols: NDArray[Any]
) -> list[tuple[int, int]]:
    """The runs of :func:`_equal_runs` with at least ``min_records`` rows spanning at
    least ``min_s`` seconds, filtered with numpy (a 1 Hz receiver giving GGA and RMC
    repeats each position once: tens of thousands of runs of two)."""
    same = np.ones(len(cols[0]) - 1, dtype=bool) if len(cols[0]) > 1 else np.zeros(0, bool)
    for c in cols:
        same &= c[1:] == c[:-1]
    m = np.concatenate(([False], same, [False]))
    edges = np.flatnonzero(m[1:] != m[:-1])
    a, b = edges[::2], edges[1::2] + 1
    keep = (b - a >= min_records) & ((t[b - 1] - t[a]) / NS_PER_S >= min_s)
    return list(zip(a[keep].tolist(), b[keep].tolist(), strict=True))


def _by_source(df: pd.DataFrame | None) -> Iterator[tuple[str, pd.DataFrame]]:
    """(source key, its rows sorted by time) for each source, sorted by key.

    The rows carry the numeric columns only (the checks read nothing else): taking the
    string columns row by row costs more than all the checks.
    """
    if df is None or df.empty:
        return
    codes, keys = pd.factorize(df["source"], sort=True)
    # stable: time order kept within a source; int16 keys make numpy's stable sort a radix sort
    order = np.argsort(codes.astype(np.int16) if len(keys) < 1 << 15 else codes, kind="stable")
    bounds = np.searchsorted(codes[order], np.arange(len(keys) + 1))
    numeric = {
        c: df[c].to_numpy() for c in df.columns if pd.api.types.is_numeric_dtype(df[c].dtype)
    }
    for i, key in enumerate(keys):
        rows = order[bounds[i] : bounds[i + 1]]
        g = pd.DataFrame({c: v[rows] for c, v in numeric.items()}, copy=False)
        t = g["time_ns"].to_numpy()
        if (t[1:] < t[:-1]).any():  # canonical frames are sorted: then nothing to do
            g = g.sort_values("time_ns", kind="stable")
        yield str(key), g


def _window(df: pd.DataFrame | None, exclude: str, a_ns: int, b_ns: int) -> pd.DataFrame | None:
    if df is None or df.empty:
        return None
    t = df["time_ns"].to_numpy(np.int64)
    i, j = np.searchsorted(t, a_ns, "left"), np.searchsorted(t, b_ns, "right")
    w = df.iloc[i:j]
    w = w[(w["source"] != exclude).to_numpy()]
    return w if len(w) else None


def _other_speed_mps(
    frames: Mapping[str, pd.DataFrame], exclude: str, a_ns: int, b_ns: int
) -> float:
    """Median speed shown by the other sources over [a, b]: SOG, else the log, else NaN."""
    for kind, col in (("ground", "sog_mps"), ("water", "stw_mps")):
        w = _window(frames.get(kind), exclude, a_ns, b_ns)
        if w is not None:
            v = np.abs(w[col].to_numpy(float))
            v = v[np.isfinite(v)]
            if v.size:
                return float(np.median(v))
    return math.nan


def _other_turn_rad(
    frames: Mapping[str, pd.DataFrame], exclude: str, a_ns: int, b_ns: int, moving_mps: float
) -> float:
    """Largest spread (max - min about the circular mean) of another heading source or of
    the COG while moving, over [a, b]; NaN without such evidence."""
    spreads = []
    w = _window(frames.get("heading"), exclude, a_ns, b_ns)
    if w is not None:
        for _, g in w.groupby("source", observed=True):
            h = g["heading_rad"].to_numpy(float)
            h = h[np.isfinite(h)]
            if h.size >= 2:
                d = angdiff(h, circmean(h))
                spreads.append(float(np.max(d) - np.min(d)))
    w = _window(frames.get("ground"), exclude, a_ns, b_ns)
    if w is not None:
        c = w["cog_rad"].to_numpy(float)
        s = w["sog_mps"].to_numpy(float)
        c = c[np.isfinite(c) & (s >= moving_mps)]
        if c.size >= 2:
            d = angdiff(c, circmean(c))
            spreads.append(float(np.max(d) - np.min(d)))
    return max(spreads) if spreads else math.nan


def _fmt_t(t_ns: int) -> str:
    return cast(str, pd.Timestamp(int(t_ns), unit="ns", tz="UTC").strftime("%Y-%m-%d %H:%M:%S"))


def _span(a_ns: int, b_ns: int) -> str:
    return f"{_fmt_t(a_ns)} to {_fmt_t(b_ns)} UTC ({(b_ns - a_ns) / NS_PER_S / 60:.1f} min)"


# ---------------------------------------------------------------------- detectors


def _jumps(
    key: str, role: str | None, g: pd.DataFrame, cfg: FaultsConfig, catch_up_from_ns: set[int]
) -> list[SensorFault]:
    la, lo = g["lat_rad"].to_numpy(float), g["lon_rad"].to_numpy(float)
    with np.errstate(invalid="ignore"):  # out-of-range positions are their own fault
        ok = (np.abs(la) <= math.pi / 2) & (np.abs(lo) <= math.pi) & (g["quality"].to_numpy() != 0)
    g = g[ok]
    if len(g) < 2:
        return []
    t = g["time_ns"].to_numpy(np.int64)
    lat = g["lat_rad"].to_numpy(float)
    lon = g["lon_rad"].to_numpy(float)
    line = g["line"].to_numpy(np.int64)
    d_m = distance_m(lat[:-1], lon[:-1], lat[1:], lon[1:])
    dt_s = np.diff(t) / NS_PER_S
    with np.errstate(divide="ignore", invalid="ignore"):
        v_mps = np.where(dt_s > 0, d_m / np.where(dt_s > 0, dt_s, 1.0), np.inf)
    jump = (d_m > cfg.jump_min_m) & (v_mps > cfg.max_speed_kn * KN_MPS)
    # the step out of a frozen run is the unit catching up, part of the frozen fault
    jump &= ~np.isin(t[:-1], np.fromiter(catch_up_from_ns, np.int64, len(catch_up_from_ns)))
    idx = np.flatnonzero(jump)  # jump between rows i and i+1
    out = []
    n = 0
    while n < idx.size:
        i = idx[n]
        a = i + 1  # first displaced row
        nxt = int(idx[n + 1]) if n + 1 < idx.size else None
        b = nxt if nxt is not None else len(t) - 1  # last displaced row
        # the jump back undoes the jump: the two steps as vectors nearly cancel (the ship
        # moved on meanwhile, so the positions before and after need not be close)
        back = False
        if nxt is not None:
            out_n, out_e = offset_ne_m(lat[a], lon[a], lat[i], lon[i])
            ret_n, ret_e = offset_ne_m(lat[nxt + 1], lon[nxt + 1], lat[nxt], lon[nxt])
            back = bool(math.hypot(out_n + ret_n, out_e + ret_e) < d_m[i] / 2)
        tail = (
            # back is True only when nxt is an index
            f"back at {_fmt_t(t[nxt + 1])} UTC after {b - a + 1} record(s)"  # type: ignore[operator]
            if back
            else (
                f"jumped again at {_fmt_t(t[nxt + 1])} UTC"
                if nxt is not None
                else "did not come back before its last record"
            )
        )
        speed = "instantaneous" if not math.isfinite(v_mps[i]) else f"{v_mps[i] / KN_MPS:,.0f} kn"
        msg = (
            f"{key}: position jumped {d_m[i] / NMI_M:.2f} nmi in {dt_s[i]:g} s "
            f"(implied {speed}) at {_fmt_t(t[a])} UTC; {tail}"
        )
        out.append(
            SensorFault(
                source=key,
                role=role,
                kind="jump",
                frame="position",
                start_ns=int(t[a]),
                end_ns=int(t[b]),
                n_records=int(b - a + 1),
                first_line=int(line[a]),
                values=(
                    ("jump_nmi", float(d_m[i] / NMI_M)),
                    ("dt_s", float(dt_s[i])),
                    ("implied_speed_kn", float(v_mps[i] / KN_MPS)),
                    ("lat_before_deg", float(lat[i] / DEG_RAD)),
                    ("lon_before_deg", float(lon[i] / DEG_RAD)),
                    ("lat_after_deg", float(lat[a] / DEG_RAD)),
                    ("lon_after_deg", float(lon[a] / DEG_RAD)),
                ),
                message=msg,
            )
        )
        n += 2 if back else 1  # the jump back belongs to this fault
    return out


def _frozen(
    key: str,
    role: str | None,
    g: pd.DataFrame,
    frames: Mapping[str, pd.DataFrame],
    cfg: FaultsConfig,
) -> list[SensorFault]:
    ok = np.isfinite(g["lat_rad"].to_numpy(float)) & np.isfinite(g["lon_rad"].to_numpy(float))
    g = g[ok]
    if len(g) < cfg.min_records:
        return []
    t = g["time_ns"].to_numpy(np.int64)
    lat = g["lat_rad"].to_numpy(float)
    lon = g["lon_rad"].to_numpy(float)
    line = g["line"].to_numpy(np.int64)
    out = []
    for a, b in _long_equal_runs(t, cfg.min_records, cfg.frozen_min_s, lat, lon):
        dur_s = (t[b - 1] - t[a]) / NS_PER_S
        if b - a < cfg.min_records or dur_s < cfg.frozen_min_s:
            continue
        v = _other_speed_mps(frames, key, int(t[a]), int(t[b - 1]))
        if math.isfinite(v) and v < cfg.moving_min_kn * KN_MPS:
            continue  # the ship lay still: a repeated position proves nothing
        why = (
            f"while other sources show {v / KN_MPS:.1f} kn"
            if math.isfinite(v)
            else "(no other source tells whether the ship moved)"
        )
        msg = (
            f"{key}: position frozen at {lat[a] / DEG_RAD:.6f}, {lon[a] / DEG_RAD:.6f} deg for "
            f"{b - a} records, {_span(int(t[a]), int(t[b - 1]))}, {why}"
        )
        out.append(
            SensorFault(
                source=key,
                role=role,
                kind="frozen",
                frame="position",
                start_ns=int(t[a]),
                end_ns=int(t[b - 1]),
                n_records=int(b - a),
                first_line=int(line[a]),
                values=(
                    ("lat_deg", float(lat[a] / DEG_RAD)),
                    ("lon_deg", float(lon[a] / DEG_RAD)),
                    ("duration_s", float(dur_s)),
                    ("other_speed_kn", float(v / KN_MPS)),
                ),
                message=msg,
            )
        )
    return out


def _stuck(
    key: str,
    role: str | None,
    g: pd.DataFrame,
    frames: Mapping[str, pd.DataFrame],
    cfg: FaultsConfig,
) -> list[SensorFault]:
    h = g["heading_rad"].to_numpy(float)
    g = g[np.isfinite(h)]
    if len(g) < cfg.min_records:
        return []
    t = g["time_ns"].to_numpy(np.int64)
    h = g["heading_rad"].to_numpy(float)
    line = g["line"].to_numpy(np.int64)
    out = []
    for a, b in _long_equal_runs(t, cfg.min_records, cfg.stuck_min_s, h):
        dur_s = (t[b - 1] - t[a]) / NS_PER_S
        if b - a < cfg.min_records or dur_s < cfg.stuck_min_s:
            continue
        ta, tb = int(t[a]), int(t[b - 1])
        turn = _other_turn_rad(frames, key, ta, tb, cfg.moving_min_kn * KN_MPS)
        v = _other_speed_mps(frames, key, ta, tb)
        turned = math.isfinite(turn) and turn >= cfg.turn_min_deg * DEG_RAD
        moved = math.isfinite(v) and v >= cfg.moving_min_kn * KN_MPS
        evidence = math.isfinite(turn) or math.isfinite(v)
        if evidence and not (turned or moved):
            continue  # a still ship on a steady heading: a repeated heading proves nothing
        parts = []
        if math.isfinite(turn):
            parts.append(f"other headings span {turn / DEG_RAD:.1f} deg")
        if math.isfinite(v):
            parts.append(f"other sources show {v / KN_MPS:.1f} kn")
        why = ("while " + " and ".join(parts)) if parts else "(no other source to compare with)"
        msg = (
            f"{key}: heading stuck at {h[a] / DEG_RAD:.2f} deg for {b - a} records, "
            f"{_span(ta, tb)}, {why}"
        )
        out.append(
            SensorFault(
                source=key,
                role=role,
                kind="stuck_heading",
                frame="heading",
                start_ns=ta,
                end_ns=tb,
                n_records=int(b - a),
                first_line=int(line[a]),
                values=(
                    ("heading_deg", float(h[a] / DEG_RAD)),
                    ("duration_s", float(dur_s)),
                    ("other_turn_deg", float(turn / DEG_RAD)),
                    ("other_speed_kn", float(v / KN_MPS)),
                ),
                message=msg,
            )
        )
    return out


#: a predicate of bad values: True where a reading is out of range
_BadValue = Callable[[FloatArray], BoolArray]


def _limits(cfg: FaultsConfig) -> dict[str, list[tuple[str, float, str, _BadValue]]]:
    """frame -> [(column, scale to the shown unit, shown name, predicate of a bad value)]."""
    vmax = cfg.max_speed_kn * KN_MPS
    rot_max = cfg.max_rot_deg_per_min * DEG_RAD / 60.0

    def speed(v: FloatArray) -> BoolArray:
        return np.abs(v) > vmax

    return {
        "position": [
            ("lat_rad", 1 / DEG_RAD, "lat_deg", lambda v: np.abs(v) > math.pi / 2),
            ("lon_rad", 1 / DEG_RAD, "lon_deg", lambda v: np.abs(v) > math.pi),
        ],
        "heading": [
            ("heading_rad", 1 / DEG_RAD, "heading_deg", lambda v: (v < 0) | (v >= 2 * math.pi))
        ],
        "ground": [
            ("cog_rad", 1 / DEG_RAD, "cog_deg", lambda v: (v < 0) | (v >= 2 * math.pi)),
            ("sog_mps", 1 / KN_MPS, "sog_kn", lambda v: (v < 0) | (v > vmax)),
        ],
        "water": [
            (c, 1 / KN_MPS, c.replace("_mps", "_kn"), speed)
            for c in ("stw_mps", "stw_transverse_mps", "sog_long_mps", "sog_transverse_mps")
        ],
        "rot": [("rot_radps", 60 / DEG_RAD, "rot_deg_per_min", lambda v: np.abs(v) > rot_max)],
    }


def _out_of_range(
    frames: Mapping[str, pd.DataFrame],
    roles: Mapping[str, str | None],
    cfg: FaultsConfig,
    split: dict[str, list[tuple[str, pd.DataFrame]]] | None = None,
) -> list[SensorFault]:
    """``split``: kind -> [(source, rows)] already made by the caller (else made here)."""
    out = []
    split = {} if split is None else split
    for kind, checks in _limits(cfg).items():
        if kind not in split:
            split[kind] = list(_by_source(frames.get(kind)))
        for key, g in split[kind]:
            t = g["time_ns"].to_numpy(np.int64)
            line = g["line"].to_numpy(np.int64)
            for col, scale, shown, bad_of in checks:
                v = g[col].to_numpy(float)
                with np.errstate(invalid="ignore"):
                    bad = np.isfinite(v) & bad_of(np.where(np.isfinite(v), v, 0.0))
                for a, b in _runs(bad):
                    lo, hi = float(np.min(v[a:b]) * scale), float(np.max(v[a:b]) * scale)
                    shown_v = f"{lo:g}" if lo == hi else f"{lo:g} to {hi:g}"
                    msg = (
                        f"{key}: {shown.rsplit('_', 1)[0]} {shown_v} "
                        f"{shown.rsplit('_', 1)[1].replace('per', '/')} out of range in {b - a} "
                        f"record(s) from {_fmt_t(t[a])} to {_fmt_t(t[b - 1])} UTC (line {line[a]})"
                    )
                    out.append(
                        SensorFault(
                            source=key,
                            role=roles.get(key),
                            kind="out_of_range",
                            frame=kind,
                            start_ns=int(t[a]),
                            end_ns=int(t[b - 1]),
                            n_records=int(b - a),
                            first_line=int(line[a]),
                            values=((f"min_{shown}", lo), (f"max_{shown}", hi)),
                            message=msg,
                        )
                    )
    return out


# ---------------------------------------------------------------------- public API


def detect_faults(
    voyage_or_frames: Voyage | Mapping[str, pd.DataFrame], cfg: FaultsConfig | None = None
) -> list[SensorFault]:
    """Every sensor fault in a voyage (or a mapping kind -> canonical frame), by start time.

    Roles come from ``Voyage.sources`` (None for a bare mapping of frames).  ``cfg``
    defaults to :class:`FaultsConfig` (); invalid thresholds raise ConfigError.
    """
    cfg = check_config(cfg or FaultsConfig())
    frames: Mapping[str, pd.DataFrame]
    if isinstance(voyage_or_frames, Voyage):
        frames = voyage_or_frames.frames
        roles = {k: s.role for k, s in voyage_or_frames.sources.items()}
    else:
        frames = voyage_or_frames
        roles = {}
    faults: list[SensorFault] = []
    split = {kind: list(_by_source(frames.get(kind))) for kind in ("position", "heading")}
    for key, g in split["position"]:
        frozen = _frozen(key, roles.get(key), g, frames, cfg)
        faults += frozen + _jumps(key, roles.get(key), g, cfg, {f.end_ns for f in frozen})
    for key, g in split["heading"]:
        faults += _stuck(key, roles.get(key), g, frames, cfg)
    faults += _out_of_range(frames, roles, cfg, split)
    faults.sort(key=lambda f: (f.start_ns, f.source, f.kind))
    return faults


def exclude_faults(voyage: Voyage, faults: list[SensorFault]) -> tuple[Voyage, dict[str, int]]:
    """A copy of ``voyage`` without the records the faults cover; (voyage, frame -> n removed).

    A record is removed when its source, frame kind and time match a fault
    (``start_ns <= time_ns <= end_ns``).  The input voyage is not changed.
    """
    frames = dict(voyage.frames)
    removed: dict[str, int] = {}
    for kind in {f.frame for f in faults}:
        df = frames.get(kind)
        if df is None or df.empty:
            continue
        t = df["time_ns"].to_numpy(np.int64)
        src = df["source"].astype(str).to_numpy()
        drop = np.zeros(len(df), dtype=bool)
        for f in faults:
            if f.frame == kind:
                drop |= (src == f.source) & (t >= f.start_ns) & (t <= f.end_ns)
        if drop.any():
            frames[kind] = df[~drop].reset_index(drop=True)
            removed[kind] = int(drop.sum())
    return replace(voyage, frames=frames), removed
