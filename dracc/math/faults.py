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
    ``frozen_min_s`` and ``min_records`` records while another source shows the ship
    moving (:func:`dracc.math.witness.ground_witness`: another source's SOG, else the
    net motion of another position source, else the log beyond a berth's current, at
    ``moving_min_kn`` or more) and farther over the run than three steps of the
    source's own resolution (learned from its values, :func:`~dracc.core.resolution.quantum`).
    No witness, no fault: a GNSS that holds its fix at rest (SOG 0.0) is a ship at rest
    (:class:`RepeatRun` ``at_rest``) or unwitnessed (``no_witness``), not frozen.
``stuck_heading``
    a heading source repeating a bit-identical heading for at least ``stuck_min_s``
    and ``min_records`` records while another heading source (or another source's COG
    while moving) turned by more than three steps of the source's resolution learned
    from its values (an AIS heading in whole degrees: 3 deg; never less than
    :data:`MIN_TURN_DEG`, and ``turn_min_deg`` always suffices), beyond the witness's
    own noise and resolution (:func:`~dracc.math.witness.turn_witness`).  Moving on a
    steady heading proves nothing: a heading repeats within its resolution.  At rest (a
    witness below ``moving_min_kn``) only a swing of ``turn_min_deg`` proves it: at a
    berth a compass wanders with the steel about it and a gyro settles.
``out_of_range``
    values no sensor can produce but that a reader passed through: latitude beyond
    +-90 deg, longitude beyond +-180 deg, heading or course outside [0, 360) deg,
    speed over ground negative, any speed beyond ``max_speed_kn`` in magnitude, rate
    of turn beyond ``max_rot_deg_per_min``.  Consecutive records of one source and
    quantity form one fault.

:func:`faults_and_repeats` also returns every run of repeats judged, with the witnesses'
verdict (``fault``, ``at_rest``, ``steady``, ``no_witness``) and its evidence in words.

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
from dracc.core.geodesy import A_M, distance_m, offset_ne_m
from dracc.core.resolution import HEADING_QUANTA_RAD, POSITION_QUANTA_RAD, quantum
from dracc.core.timefmt import iso_utc
from dracc.core.units import DEG_RAD, KN_MPS, NMI_M, NS_PER_S
from dracc.frames import Voyage
from dracc.math.witness import (
    GroundWitness,
    TurnWitness,
    ground_witness,
    heading_spread_deg,
    turn_witness,
)

__all__ = [
    "FAULT_KINDS",
    "RepeatRun",
    "SensorFault",
    "check_config",
    "detect_faults",
    "exclude_faults",
    "faults_and_repeats",
]

FAULT_KINDS = ("jump", "frozen", "stuck_heading", "out_of_range")
#: the smallest turn of the witnesses that proves a heading stuck (the finest step headings
#: are logged with in NMEA 0183, two decimals, is 0.01 deg: five of them)
MIN_TURN_DEG = 0.05


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


@dataclass(frozen=True)
class RepeatRun:
    """A run of bit-identical readings long enough to be judged, and the verdict of the
    other sources on it (:mod:`dracc.math.witness`).

    ``verdict``: ``fault`` (a witness shows the ship moving or turning beyond the
    sensor's resolution: ``fault`` holds the :class:`SensorFault`), ``at_rest`` (the
    witnesses show the ship still), ``steady`` (moving on a heading that did not turn
    beyond the resolution), ``no_witness`` (no other source to tell).  ``evidence`` says
    it in words ("at rest: SOG 0.0 kn, heading spread 0.4 deg")."""

    source: str
    role: str | None
    kind: str  #: 'frozen' or 'stuck_heading'
    start_ns: int
    end_ns: int
    n_records: int
    verdict: str
    evidence: str
    values: tuple[tuple[str, float], ...]
    fault: SensorFault | None = None

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS_PER_S


def _position_quantum_m(g: pd.DataFrame) -> float:
    """The resolution of a source's positions in metres (the coarser axis; 0 unknown)."""
    la, lo = g["lat_rad"].to_numpy(float), g["lon_rad"].to_numpy(float)
    q_lat = quantum(la, POSITION_QUANTA_RAD)
    q_lon = quantum(lo, POSITION_QUANTA_RAD)
    coslat = math.cos(float(np.nanmedian(la))) if np.isfinite(la).any() else 1.0
    return max(q_lat, q_lon * abs(coslat)) * A_M


def _frozen(
    key: str,
    role: str | None,
    g: pd.DataFrame,
    frames: Mapping[str, pd.DataFrame],
    cfg: FaultsConfig,
) -> list[RepeatRun]:
    ok = np.isfinite(g["lat_rad"].to_numpy(float)) & np.isfinite(g["lon_rad"].to_numpy(float))
    g = g[ok]
    if len(g) < cfg.min_records:
        return []
    t = g["time_ns"].to_numpy(np.int64)
    lat = g["lat_rad"].to_numpy(float)
    lon = g["lon_rad"].to_numpy(float)
    line = g["line"].to_numpy(np.int64)
    found = _long_equal_runs(t, cfg.min_records, cfg.frozen_min_s, lat, lon)
    q_m = _position_quantum_m(g) if found else 0.0
    out = []
    for a, b in found:
        ta, tb = int(t[a]), int(t[b - 1])
        dur_s = (tb - ta) / NS_PER_S
        wit = ground_witness(frames, key, ta, tb)
        # the ship moved, by a witness, and farther than the source resolves
        moved = wit.moving(cfg.moving_min_kn * KN_MPS) and wit.speed_mps * dur_s > 3.0 * q_m
        spread = heading_spread_deg(frames, key, ta, tb)
        values = (
            ("lat_deg", float(lat[a] / DEG_RAD)),
            ("lon_deg", float(lon[a] / DEG_RAD)),
            ("duration_s", float(dur_s)),
            ("other_speed_kn", float(wit.speed_mps / KN_MPS)),
            ("resolution_m", float(q_m)),
            ("heading_spread_deg", spread),
        )
        if not moved:
            own = ground_witness(frames, "", ta, tb, only=key) if not wit.found else wit
            verdict, words = _rest_words(wit, spread, own, cfg.moving_min_kn * KN_MPS)
            out.append(RepeatRun(key, role, "frozen", ta, tb, b - a, verdict, words, values))
            continue
        msg = (
            f"{key}: position frozen at {lat[a] / DEG_RAD:.6f}, {lon[a] / DEG_RAD:.6f} deg for "
            f"{b - a} records, {_span(ta, tb)}, while {wit.words()} (the ship moved about "
            f"{wit.speed_mps * dur_s:,.0f} m; the source resolves {q_m:.2g} m)"
        )
        fault = SensorFault(
            key, role, "frozen", "position", ta, tb, b - a, int(line[a]), values, msg
        )
        out.append(RepeatRun(key, role, "frozen", ta, tb, b - a, "fault", msg, values, fault))
    return out


def _rest_words(
    wit: GroundWitness, spread_deg: float, own: GroundWitness, moving_mps: float
) -> tuple[str, str]:
    """(verdict, evidence) of a repeat no witness shows moving (``own``: what the source
    itself says, shown, never a witness of itself)."""
    if not wit.found:
        said = f"its own SOG {own.speed_mps / KN_MPS:.1f} kn; " if own.how == "SOG" else ""
        return "no_witness", f"{said}no other source tells whether the ship moved"
    if wit.how == "log" and wit.speed_mps >= moving_mps:  # moving, or a current past a berth
        return "no_witness", (
            f"{wit.words()}, which a current past a moored ship reads as well; no other "
            "source tells whether the ship moved over the ground"
        )
    head = f", heading spread {spread_deg:.1f} deg" if math.isfinite(spread_deg) else ""
    return "at_rest", f"at rest: {wit.words()}{head}"


def _turn_words(
    turn: TurnWitness, wit: GroundWitness, still: bool, gate: float, q: float
) -> tuple[str, str]:
    """(verdict, evidence) of a repeated heading no witness shows turning beyond ``gate``
    (``still``: a witness shows the ship below the moving speed)."""
    if not turn.found:  # at rest or not, nobody saw the heading: it cannot be judged
        rest = f"at rest ({wit.words()}), but " if still else ""
        return "no_witness", f"{rest}no other heading source tells whether the ship turned"
    state = "at rest" if still else "steady"
    why = (
        f"at rest only a swing that large proves a heading dead; the source resolves "
        f"{q / DEG_RAD:.2g} deg"
        if still
        else f"three steps of the {q / DEG_RAD:.2g} deg the source resolves"
    )
    return state.replace(" ", "_"), (
        f"{state}: {wit.words()}, heading spread {turn.spread_rad / DEG_RAD:.1f} deg "
        f"({', '.join(turn.sources)}), within {gate / DEG_RAD:.2g} deg ({why})"
    )


def _stuck(
    key: str,
    role: str | None,
    g: pd.DataFrame,
    frames: Mapping[str, pd.DataFrame],
    cfg: FaultsConfig,
    quanta: Mapping[str, float],
) -> list[RepeatRun]:
    h = g["heading_rad"].to_numpy(float)
    g = g[np.isfinite(h)]
    if len(g) < cfg.min_records:
        return []
    t = g["time_ns"].to_numpy(np.int64)
    h = g["heading_rad"].to_numpy(float)
    line = g["line"].to_numpy(np.int64)
    q = quanta.get(key, 0.0)
    # a turn proves the sensor dead when it is well beyond the sensor's resolution (three
    # steps), never less than MIN_TURN_DEG; turn_min_deg always proves it
    gate = min(cfg.turn_min_deg * DEG_RAD, max(3.0 * q, MIN_TURN_DEG * DEG_RAD))
    out = []
    for a, b in _long_equal_runs(t, cfg.min_records, cfg.stuck_min_s, h):
        ta, tb = int(t[a]), int(t[b - 1])
        dur_s = (tb - ta) / NS_PER_S
        turn = turn_witness(frames, key, ta, tb, cfg.moving_min_kn * KN_MPS, quanta)
        wit = ground_witness(frames, key, ta, tb)
        values = (
            ("heading_deg", float(h[a] / DEG_RAD)),
            ("duration_s", float(dur_s)),
            ("other_turn_deg", float(turn.spread_rad / DEG_RAD)),
            ("turn_beyond_noise_deg", float(turn.turn_rad / DEG_RAD)),
            ("resolution_deg", float(q / DEG_RAD)),
            ("other_speed_kn", float(wit.speed_mps / KN_MPS)),
        )
        # at rest (a witness says so), a compass wanders with the steel and cranes of a
        # berth and a gyro settles: only a swing of turn_min_deg proves the heading dead
        still = wit.found and wit.speed_mps < cfg.moving_min_kn * KN_MPS
        run_gate = max(gate, cfg.turn_min_deg * DEG_RAD) if still else gate
        if not (turn.found and turn.turn_rad > run_gate):
            verdict, words = _turn_words(turn, wit, still, run_gate, q)
            out.append(RepeatRun(key, role, "stuck_heading", ta, tb, b - a, verdict, words, values))
            continue
        msg = (
            f"{key}: heading stuck at {h[a] / DEG_RAD:.2f} deg for {b - a} records, "
            f"{_span(ta, tb)}, while other headings span {turn.spread_rad / DEG_RAD:.1f} deg "
            f"({', '.join(turn.sources)}; each turned {turn.turn_rad / DEG_RAD:.1f} deg or "
            f"more beyond its noise, against the {q / DEG_RAD:.2g} deg the source resolves)"
        )
        fault = SensorFault(
            key, role, "stuck_heading", "heading", ta, tb, b - a, int(line[a]), values, msg
        )
        out.append(
            RepeatRun(key, role, "stuck_heading", ta, tb, b - a, "fault", msg, values, fault)
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


def faults_and_repeats(
    voyage_or_frames: Voyage | Mapping[str, pd.DataFrame], cfg: FaultsConfig | None = None
) -> tuple[list[SensorFault], list[RepeatRun]]:
    """Every sensor fault (as :func:`detect_faults`) and every run of repeated positions
    or headings long enough to judge, with the witnesses' verdict on it."""
    cfg = check_config(cfg or FaultsConfig())
    frames: Mapping[str, pd.DataFrame]
    interleaved: set[str] = set()  # several units behind one key: steps are no jumps
    if isinstance(voyage_or_frames, Voyage):
        frames = voyage_or_frames.frames
        roles = {k: s.role for k, s in voyage_or_frames.sources.items()}
        interleaved = {k for k, s in voyage_or_frames.sources.items() if s.interleaved}
    else:
        frames = voyage_or_frames
        roles = {}
    faults: list[SensorFault] = []
    repeats: list[RepeatRun] = []
    split = {kind: list(_by_source(frames.get(kind))) for kind in ("position", "heading")}
    for key, g in split["position"]:
        frozen = _frozen(key, roles.get(key), g, frames, cfg)
        repeats += frozen
        # the step out of a held fix is the unit catching up, not a jump (at rest too)
        caught_up = {r.end_ns for r in frozen}
        faults += [r.fault for r in frozen if r.fault is not None]
        if key not in interleaved:
            faults += _jumps(key, roles.get(key), g, cfg, caught_up)
    # the resolution of every heading source, learned from its values over the voyage
    quanta = {
        key: quantum(g["heading_rad"].to_numpy(float), HEADING_QUANTA_RAD)
        for key, g in split["heading"]
    }
    for key, g in split["heading"]:
        stuck = _stuck(key, roles.get(key), g, frames, cfg, quanta)
        repeats += stuck
        faults += [r.fault for r in stuck if r.fault is not None]
    faults += _out_of_range(frames, roles, cfg, split)
    faults.sort(key=lambda f: (f.start_ns, f.source, f.kind))
    repeats.sort(key=lambda r: (r.start_ns, r.source, r.kind))
    return faults, repeats


def detect_faults(
    voyage_or_frames: Voyage | Mapping[str, pd.DataFrame], cfg: FaultsConfig | None = None
) -> list[SensorFault]:
    """Every sensor fault in a voyage (or a mapping kind -> canonical frame), by start time.

    Roles come from ``Voyage.sources`` (None for a bare mapping of frames).  ``cfg``
    defaults to :class:`FaultsConfig` (); invalid thresholds raise ConfigError.
    """
    return faults_and_repeats(voyage_or_frames, cfg)[0]


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
