"""Seeded sensor faults for simulated voyages: what the nightly integrity audit must find.

Pure functions (numpy/pandas, no I/O).  A :class:`SimFault` names a kind, a source, a
window and a size; :func:`parse_fault` reads the CLI spec
``KIND[:SOURCE][@START][+DURATION][=SIZE]``, :func:`resolve_faults` fills in the defaults
(start and direction drawn from the seed) and checks the fault against the voyage, and
:func:`apply_error_faults` / :func:`apply_frame_faults` change the simulated true errors
and canonical frames.  Outside its window a fault changes nothing and other sources are
never touched (but a dropout closes up the line numbers of every later record).

Kinds (window ``[start, start + duration)`` in absolute voyage time; a window reaching
the end of the voyage includes its last sample):

``jump``     the source's positions displaced by ``size`` metres in a fixed direction
             (position frame and the true position error; velocities unchanged).
``freeze``   the source's latitude/longitude (a compass: its heading, and HDG's deviation)
             repeat bit-identically the last value before the start; records keep coming.
``dropout``  every record of the source removed (line numbers closed up).
``drift``    the position error gains ``size * (t - start)`` (m/s) in a fixed direction;
             back to normal after the window.
``latency``  records *received* in the window carry their time of fix ``size`` seconds
             earlier: ``recv_ns = time_ns + size``, values those of the time of fix (with
             a source latency, ``SimParams.latency_s``, on top of it).
``invalid``  the source's position records flagged invalid (``quality`` 0), values kept.
``leap``     (GNSS) the receiver's own time fields read ``size`` seconds ahead (GPS time
             without the UTC offset, default 18 s): ``time_ns`` (time of fix, ZDA too) +
             size for fixes in the window, ``recv_ns`` the true receive time; values kept.
``rollover`` (GNSS) the receiver's dates read 1024 weeks (7168 days) early (RMC and ZDA
             date fields; MCAP stamps): frames unchanged -- a parser places a time of fix
             on the day of its receive time -- the writers take :func:`date_shifts`.
``loop``     (source ``ALL``: the logger, or one source) at the start the log's records
             received in the previous ``size`` seconds (default 1320) are written again,
             same values and times, before the log goes on; lines renumbered in the
             written order.  No duration (it is resolved as 0).
``clockstep`` (``ALL`` or one source) the logger clock steps by ``size`` seconds (signed,
             default -1320) for the window: receive stamps shifted (``recv_ns``, and the
             ``time_ns`` of records without a time of fix); time-of-fix fields unchanged.

Jump and drift change the true errors (``errors`` holds measured - true) before the
frames are made, so frames and errors agree; freeze changes the errors in its window to
the frozen reading minus the truth.  Dropout, latency and invalid leave the errors alone
(the error process of the sensor goes on; the record's values are of its time of fix);
so do the four time faults.  Windows are on ``time_ns`` (a latency, clockstep and loop:
on the receive time, ``recv_ns`` where set).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
import pandas as pd

from dracc.core.errors import ConfigError
from dracc.core.geodesy import angdiff, offset_ne_m
from dracc.core.timefmt import iso_utc
from dracc.core.units import KN_MPS
from dracc.frames import MISSING_NS

FAULT_KINDS = ("jump", "freeze", "dropout", "drift", "latency", "invalid")  #: sensor faults
TIME_FAULT_KINDS = ("leap", "rollover", "loop", "clockstep")  #: a receiver's or logger's clock
ALL_FAULT_KINDS = FAULT_KINDS + TIME_FAULT_KINDS
#: every source key the simulator can write (as :data:`dracc.sim.readings.SOURCES`)
ALL_SOURCES = ("GYRO", "MAG", "LOG", "INS1", "INS2", "INS3", "GNSS")
LOGGER = "ALL"  #: the source of a loop or clockstep of the whole log
#: sentences with their own time of fix (``time_ns``); the others are timed on receipt
OWN_TIME_SENTENCES = ("GGA", "GLL", "RMC", "GNS", "ZDA")
ROLLOVER_DAYS = 1024 * 7  #: a GPS week-number rollover
POSITION_SOURCES = ("INS1", "INS2", "INS3", "GNSS")
COMPASS_SOURCES = ("GYRO", "MAG")
#: kind -> the sources it can hit
KIND_SOURCES = {
    "jump": POSITION_SOURCES,
    "freeze": POSITION_SOURCES + COMPASS_SOURCES,
    "dropout": ALL_SOURCES,
    "drift": POSITION_SOURCES,
    "latency": ALL_SOURCES,
    "invalid": POSITION_SOURCES,
    "leap": ("GNSS",),
    "rollover": ("GNSS",),
    "loop": (LOGGER, *ALL_SOURCES),
    "clockstep": (LOGGER, *ALL_SOURCES),
}
DEFAULT_SOURCE = {
    "jump": "GNSS",
    "freeze": "INS2",
    "dropout": "INS3",
    "drift": "INS1",
    "latency": "GNSS",
    "invalid": "GNSS",
    "leap": "GNSS",
    "rollover": "GNSS",
    "loop": LOGGER,
    "clockstep": LOGGER,
}
#: default window lengths in seconds (inf: to the end of the voyage)
DEFAULT_DURATION_S = {
    "jump": 600.0,
    "freeze": 2400.0,
    "dropout": 1500.0,
    "drift": math.inf,
    "latency": 3600.0,
    "invalid": 600.0,
    "leap": 3600.0,
    "rollover": math.inf,
    "loop": 0.0,  #: an instant: the replay is written at the start
    "clockstep": 3600.0,
}
#: default sizes in SI (jump m, drift m/s, latency s); kinds without a size are absent
DEFAULT_SIZE = {
    "jump": 670.0,
    "drift": 1.0 * KN_MPS,
    "latency": 3.0,
    "leap": 18.0,
    "loop": 1320.0,
    "clockstep": -1320.0,
}
SIZE_UNIT = {
    "jump": "m",
    "drift": "m/s",
    "latency": "s",
    "leap": "s",
    "loop": "s",
    "clockstep": "s",
}
SIGNED_SIZE = ("clockstep",)  #: kinds whose size may be negative
#: the default start is drawn uniformly in this fraction of the voyage
START_RANGE = (0.2, 0.5)
RNG_COMPONENT = 60  #: random stream of the fault draws (see dracc.sim.processes.component_rng)
SPEC_GRAMMAR = "KIND[:SOURCE][@START][+DURATION][=SIZE]"

_TIME_UNITS = {"": 1.0, "s": 1.0, "min": 60.0, "h": 3600.0}
_SIZE_UNITS = {
    "jump": {"": 1.0, "m": 1.0, "km": 1000.0},
    "drift": {"": KN_MPS, "kn": KN_MPS, "m/s": 1.0},
    "latency": {"": 1.0, "s": 1.0, "ms": 1e-3, "min": 60.0},
    **{k: {**_TIME_UNITS, "ms": 1e-3} for k in ("leap", "loop", "clockstep")},
}
_SIZE_EXAMPLE = {
    "jump": "=670m",
    "drift": "=1kn or =0.5m/s",
    "latency": "=3s",
    "leap": "=18s",
    "loop": "=22min",
    "clockstep": "=-22min",
}
_SPEC = re.compile(
    r"(?P<kind>[A-Za-z_]+)(?::(?P<source>[^@+=]*))?(?:@(?P<start>[^+=]*))?"
    r"(?:\+(?P<duration>[^=]*))?(?:=(?P<size>.*))?"
)
_NUM = re.compile(
    r"(?P<num>[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE]-?[0-9]+)?)\s*(?P<unit>[A-Za-z/]*)"
)


@dataclass(frozen=True)
class SimFault:
    """One seeded sensor fault.  ``None`` fields take the kind's default when resolved
    (:func:`resolve_faults`).

    ``start_s`` from the voyage start; ``duration_s`` (``inf``: to the end; 0 for a loop);
    ``size`` in SI: metres (jump), m/s (drift), seconds (latency, leap, loop, clockstep),
    ``None`` for freeze, dropout, invalid and rollover; ``direction_deg`` (true, towards)
    of a jump or drift.  ``source`` ``ALL``: every source (the logger; loop, clockstep).
    """

    kind: str
    source: str | None = None
    start_s: float | None = None
    duration_s: float | None = None
    size: float | None = None
    direction_deg: float | None = None

    def window_ns(self, voyage_start_ns: int) -> tuple[int, int | None]:
        """``[lo, hi)`` in UTC ns of a resolved fault (``hi`` None: to the end)."""
        assert self.start_s is not None and self.duration_s is not None  # resolved
        lo = int(voyage_start_ns) + int(round(self.start_s * 1e9))
        hi = None if math.isinf(self.duration_s) else lo + int(round(self.duration_s * 1e9))
        return lo, hi

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def describe(self) -> str:
        """The spec of a resolved fault, e.g. ``jump:GNSS@1234s+600s=670m``."""
        assert self.duration_s is not None  # resolved
        s = f"{self.kind}:{self.source}@{self.start_s:g}s"
        if self.kind != "loop":
            s += "+end" if math.isinf(self.duration_s) else f"+{self.duration_s:g}s"
        if self.size is not None:
            unit = "kn" if self.kind == "drift" else SIZE_UNIT[self.kind]
            s += f"={self.size / KN_MPS if self.kind == 'drift' else self.size:g}{unit}"
        return s


# --------------------------------------------------------------------------- parsing


def _number(text: str, units: dict[str, float], what: str, spec: str, example: str) -> float:
    m = _NUM.fullmatch(text.strip())
    if m is None or m.group("unit") not in units:
        names = ", ".join(u for u in units if u) or "none"
        raise ConfigError(
            f"--fault {spec!r}: {what} {text!r} is not a number with a unit "
            f"({names}; bare number: {next(u for u in units if u)}), e.g. "
            f"{example}"
        )
    v = float(m.group("num")) * units[m.group("unit")]
    if not math.isfinite(v):
        raise ConfigError(f"--fault {spec!r}: {what} {text!r} is not finite")
    return v


def parse_fault(spec: str) -> SimFault:
    """A ``--fault`` spec ``KIND[:SOURCE][@START][+DURATION][=SIZE]`` as an unresolved
    :class:`SimFault` (omitted parts None).  START and DURATION: a number with ``s``,
    ``min`` or ``h`` (bare: seconds); DURATION ``end``: to the end of the voyage (a loop
    takes none); SIZE: jump ``m``/``km`` (bare: m), drift ``kn``/``m/s`` (bare: kn),
    latency ``s``/``ms``/``min``, leap, loop and clockstep (signed) ``s``/``ms``/``min``/``h``
    (bare: s); freeze, dropout, invalid and rollover take none.  Kind and source (``ALL``:
    the logger) are case-insensitive.  Raises :class:`ConfigError`."""
    text = spec.strip()
    m = _SPEC.fullmatch(text)
    if m is None:
        raise ConfigError(f"--fault {spec!r}: expected {SPEC_GRAMMAR}, e.g. jump:GNSS@2h=670m")
    kind = m.group("kind").lower()
    if kind not in ALL_FAULT_KINDS:
        raise ConfigError(
            f"--fault {spec!r}: unknown kind {m.group('kind')!r}; expected one "
            f"of {', '.join(ALL_FAULT_KINDS)}"
        )
    source = m.group("source")
    if source is not None:
        source = source.strip().upper()
        if source not in (*ALL_SOURCES, LOGGER):
            raise ConfigError(
                f"--fault {spec!r}: unknown source {m.group('source')!r}; "
                f"expected one of {', '.join(KIND_SOURCES[kind])}"
            )
    start = dur = size = None
    if m.group("start") is not None:
        start = _number(m.group("start"), _TIME_UNITS, "START", spec, "@1.5h, @40min, @600")
    if m.group("duration") is not None and kind == "loop":
        raise ConfigError(
            f"--fault {spec!r}: loop takes no +DURATION; expected loop[:SOURCE][@START][=SIZE]"
        )
    if m.group("duration") is not None:
        dur = (
            math.inf
            if m.group("duration").strip().lower() == "end"
            else _number(m.group("duration"), _TIME_UNITS, "DURATION", spec, "+40min or +end")
        )
    if m.group("size") is not None:
        if kind not in _SIZE_UNITS:
            raise ConfigError(
                f"--fault {spec!r}: {kind} takes no =SIZE; expected "
                f"{kind}[:SOURCE][@START][+DURATION]"
            )
        size = _number(m.group("size"), _SIZE_UNITS[kind], "SIZE", spec, _SIZE_EXAMPLE[kind])
    return SimFault(kind, source, start, dur, size)


# --------------------------------------------------------------------------- resolution


def _fmt_s(x: float) -> str:
    return f"{x / 3600:g} h" if x >= 3600 else f"{x:g} s"


def resolve_faults(
    faults: Iterable[SimFault],
    voyage_s: float,
    seed: int,
    compass: str = "gyro",
    labels: Sequence[str] | None = None,
) -> tuple[SimFault, ...]:
    """Every fault with its defaults filled in and checked against the voyage.

    Source, duration and size default per kind (:data:`DEFAULT_SOURCE`,
    :data:`DEFAULT_DURATION_S`, :data:`DEFAULT_SIZE`).  The start (whole seconds, uniform
    in 20-50 % of ``voyage_s``) and the direction of a jump or drift (uniform 0-360 deg)
    come from a stream of their own per (kind, source, occurrence), so adding a fault
    changes neither the voyage's other draws nor another fault's.  A window reaching the
    end becomes ``duration_s = inf``.  Idempotent.  ``labels``: the specs as typed, for
    the messages.  Raises :class:`ConfigError`.
    """
    out = []
    seen: dict[tuple[str, str], int] = {}
    fitted = {*ALL_SOURCES, LOGGER}
    if compass == "gyro":
        fitted.discard("MAG")
    elif compass == "magnetic":
        fitted.discard("GYRO")
    for i, f in enumerate(faults):
        if not isinstance(f, SimFault):
            raise ConfigError(f"faults must be SimFault, got {type(f).__name__}")
        label = f"--fault {labels[i]!r}" if labels is not None else f"fault {f.kind}"
        if f.kind not in ALL_FAULT_KINDS:
            raise ConfigError(
                f"{label}: unknown kind {f.kind!r}; expected one of {', '.join(ALL_FAULT_KINDS)}"
            )
        src = f.source if f.source is not None else DEFAULT_SOURCE[f.kind]
        if src not in KIND_SOURCES[f.kind]:
            raise ConfigError(
                f"{label}: {f.kind} cannot hit source {src!r}; expected one of "
                f"{', '.join(KIND_SOURCES[f.kind])}"
            )
        if src not in fitted:
            raise ConfigError(
                f"{label}: the voyage has no source {src} (compass {compass!r}); "
                f"expected one of {', '.join(s for s in KIND_SOURCES[f.kind] if s in fitted)}"
            )
        occ = seen.get((f.kind, src), 0)
        seen[(f.kind, src)] = occ + 1
        rng = np.random.default_rng(
            [
                int(seed) & 0xFFFFFFFF,
                RNG_COMPONENT,
                ALL_FAULT_KINDS.index(f.kind),
                (*ALL_SOURCES, LOGGER).index(src),
                occ,
            ]
        )
        u_start, u_dir = rng.uniform(0.0, 1.0, 2)  # both always drawn: stable streams
        start = (
            f.start_s
            if f.start_s is not None
            else float(
                round((START_RANGE[0] + (START_RANGE[1] - START_RANGE[0]) * u_start) * voyage_s)
            )
        )
        if not (math.isfinite(start) and 0.0 <= start < voyage_s):
            raise ConfigError(
                f"{label}: start {_fmt_s(start)} is outside the voyage; expected "
                f"START in [0, {_fmt_s(voyage_s)})"
            )
        dur = f.duration_s if f.duration_s is not None else DEFAULT_DURATION_S[f.kind]
        if f.kind == "loop":
            if dur != 0:
                raise ConfigError(f"{label}: loop takes no duration, got {dur:g} s")
        elif math.isnan(dur) or dur <= 0:
            raise ConfigError(f"{label}: duration {dur:g} s; expected DURATION > 0")
        elif start + dur >= voyage_s:
            dur = math.inf
        size = f.size
        if f.kind in DEFAULT_SIZE:
            size = size if size is not None else DEFAULT_SIZE[f.kind]
            if not (math.isfinite(size) and (size >= 0 or f.kind in SIGNED_SIZE)):
                raise ConfigError(
                    f"{label}: size {size:g} {SIZE_UNIT[f.kind]}; expected a finite SIZE"
                    + ("" if f.kind in SIGNED_SIZE else " >= 0")
                )
        elif size is not None:
            raise ConfigError(f"{label}: {f.kind} takes no size, got {size!r}")
        direction = None
        if f.kind in ("jump", "drift"):
            direction = f.direction_deg if f.direction_deg is not None else 360.0 * float(u_dir)
            if not math.isfinite(direction):
                raise ConfigError(f"{label}: direction {direction!r} is not finite")
        elif f.direction_deg is not None:
            raise ConfigError(f"{label}: {f.kind} takes no direction")
        out.append(
            replace(
                f,
                source=src,
                start_s=float(start),
                duration_s=float(dur),
                size=None if size is None else float(size),
                direction_deg=direction,
            )
        )
    return tuple(out)


def date_shifts(
    faults: Iterable[SimFault], voyage_start_ns: int
) -> tuple[tuple[str, int, int | None, int], ...]:
    """``(source, lo_ns, hi_ns, days)`` per rollover: the writers date the source's records
    with ``time_ns`` in ``[lo, hi)`` (hi None: to the end) ``days`` early."""
    return tuple(
        (str(f.source), *f.window_ns(voyage_start_ns), ROLLOVER_DAYS)
        for f in faults
        if f.kind == "rollover"
    )


def fault_table(
    faults: Iterable[SimFault],
    voyage_start_ns: int,
    voyage_s: float,
    roles: Mapping[str, str] | None = None,
) -> list[dict[str, Any]]:
    """The resolved faults as JSON-ready dicts (params.json ``faults``): kind, source, role,
    start_utc, end_utc (ISO 8601, ns, as truth.csv's time_utc; a fault to the end ends at
    the voyage's end), start_s, duration_s (finite), size (SI), size_unit, direction_deg."""
    roles = roles or {}
    out = []
    for f in faults:
        lo, hi = f.window_ns(voyage_start_ns)
        # resolved faults (the docstring): a source, a start and a duration
        assert f.source is not None and f.start_s is not None and f.duration_s is not None
        end_ns = hi if hi is not None else int(voyage_start_ns) + int(round(voyage_s * 1e9))
        dur = f.duration_s if not math.isinf(f.duration_s) else voyage_s - f.start_s
        out.append(
            {
                "kind": f.kind,
                "source": f.source,
                "role": roles.get(f.source),
                "start_utc": iso_utc(unit="ns", time_ns=lo),
                "end_utc": iso_utc(unit="ns", time_ns=end_ns),
                "start_s": f.start_s,
                "duration_s": dur,
                "size": f.size,
                "size_unit": SIZE_UNIT.get(f.kind),
                "direction_deg": f.direction_deg,
            }
        )
    return out


# --------------------------------------------------------------------------- application


def _in(t: np.ndarray, lo: int, hi: int | None) -> np.ndarray:
    return (t >= lo) & (t < hi) if hi is not None else t >= lo


def error_columns(source: str) -> tuple[str, str]:
    """The north and east position error columns of a position source."""
    return (
        ("gnss_north_m", "gnss_east_m")
        if source == "GNSS"
        else (f"{source.lower()}_north_m", f"{source.lower()}_east_m")
    )


def apply_error_faults(
    faults: Iterable[SimFault],
    errors: dict[str, np.ndarray],
    time_ns: np.ndarray,
    t_s: np.ndarray,
    voyage_start_ns: int,
) -> dict[str, np.ndarray]:
    """The true errors with the jumps and drifts of ``faults`` added (a new dict; the
    arrays changed are new).  ``t_s``: seconds from the voyage start of each sample."""
    out = dict(errors)
    for f in faults:
        if f.kind not in ("jump", "drift"):
            continue
        lo, hi = f.window_ns(voyage_start_ns)
        w = _in(time_ns, lo, hi)
        if not w.any():
            continue
        # a resolved jump or drift has all of these
        assert f.source is not None and f.start_s is not None
        assert f.size is not None and f.direction_deg is not None
        mag = np.where(w, f.size if f.kind == "jump" else f.size * (t_s - f.start_s), 0.0)
        d = math.radians(f.direction_deg)
        cn, ce = error_columns(f.source)
        out[cn] = out[cn] + mag * math.cos(d)
        out[ce] = out[ce] + mag * math.sin(d)
    return out


def _frozen_columns(source: str | None) -> tuple[str, tuple[str, ...]]:
    if source in POSITION_SOURCES:
        return "position", ("lat_rad", "lon_rad")
    return "heading", ("heading_rad", "deviation_rad") if source == "MAG" else ("heading_rad",)


def apply_frame_faults(
    faults: Iterable[SimFault],
    frames: dict[str, pd.DataFrame],
    zda: pd.DataFrame,
    errors: pd.DataFrame,
    truth: pd.DataFrame,
    voyage_start_ns: int,
    state_in: dict[str, Any] | None = None,
) -> tuple[dict[str, pd.DataFrame], pd.DataFrame, pd.DataFrame, dict[str, Any]]:
    """Apply the freezes, dropouts, latencies, invalid flags and time faults (leap,
    clockstep, loop) of ``faults`` (in their order) to the canonical frames of one
    simulated segment (a rollover changes only the written dates: :func:`date_shifts`).

    ``errors`` and ``truth`` share the segment's time base (a freeze sets the errors in
    its window to the frozen reading minus the truth).  ``state_in``: what the previous
    segment left (a freeze's held value).  Returns ``(frames, zda, errors, state_out)``,
    new objects where anything changed; line numbers are closed up after a dropout.
    """
    state_in = state_in or {}
    state_out: dict[str, Any] = {}
    frames = dict(frames)
    dropped = False
    for i, f in enumerate(faults):
        if f.kind in ("jump", "drift"):
            continue
        lo, hi = f.window_ns(voyage_start_ns)
        if f.kind == "freeze":
            kind, cols = _frozen_columns(f.source)
            df = frames[kind]
            t = df["time_ns"].to_numpy(np.int64)
            sm = (df["source"] == f.source).to_numpy(bool)
            win = sm & _in(t, lo, hi)
            before = np.flatnonzero(sm & (t < lo))
            key = f"fault{i}_held"
            if len(before):
                r = before[np.argmax(t[before])]
                held = tuple(float(df[c].to_numpy(float)[r]) for c in cols)
            elif key in state_in:
                held = tuple(state_in[key])
            elif win.any():  # nothing before the start: the first reading in the window
                r = np.flatnonzero(win)[np.argmin(t[win])]
                held = tuple(float(df[c].to_numpy(float)[r]) for c in cols)
            else:
                held = None
            if held is None:
                continue
            state_out[key] = list(held)
            if win.any():
                df = df.copy()
                for c, v in zip(cols, held, strict=True):
                    a = df[c].to_numpy(float).copy()
                    a[win] = v
                    df[c] = a
                frames[kind] = df
            errors = _frozen_errors(f, held, errors, truth, lo, hi)
        elif f.kind == "dropout":
            for kind, df in list(frames.items()):
                if not len(df):
                    continue
                t = df["time_ns"].to_numpy(np.int64)
                gone = (df["source"] == f.source).to_numpy(bool) & _in(t, lo, hi)
                if gone.any():
                    frames[kind] = df[~gone].reset_index(drop=True)
                    dropped = True
            if len(zda):
                gone = (zda["source"].to_numpy(object) == f.source) & _in(
                    zda["time_ns"].to_numpy(np.int64), lo, hi
                )
                if gone.any():
                    zda = zda[~gone].reset_index(drop=True)
                    dropped = True
        elif f.kind == "invalid":
            df = frames["position"]
            t = df["time_ns"].to_numpy(np.int64)
            win = (df["source"] == f.source).to_numpy(bool) & _in(t, lo, hi)
            if win.any():
                df = df.copy()
                q = df["quality"].to_numpy(np.int8).copy()
                q[win] = 0
                df["quality"] = q
                frames["position"] = df
        elif f.kind in ("leap", "clockstep"):
            assert f.size is not None  # resolved: a size
            shift = int(round(f.size * 1e9))
            if f.kind == "leap":
                frames, zda = _leap(frames, zda, shift, lo, hi)
            else:
                frames = {k: _clockstep(df, f.source, shift, lo, hi) for k, df in frames.items()}
        elif f.kind == "loop":
            assert f.size is not None  # resolved: a size
            frames, zda = _loop(frames, zda, f.source, lo, int(round(f.size * 1e9)))
        elif f.kind == "latency":
            assert f.size is not None  # a resolved latency has a size
            lag = int(round(f.size * 1e9))
            for kind, df in list(frames.items()):
                if not len(df):
                    continue
                t = received_ns(df)  # the time of fix, or a source's own latency on it
                win = (df["source"] == f.source).to_numpy(bool) & _in(t + lag, lo, hi)
                if win.any():
                    df = df.copy()
                    r = df["recv_ns"].to_numpy(np.int64).copy()
                    r[win] = t[win] + lag
                    df["recv_ns"] = r
                    frames[kind] = df
    if dropped:
        frames, zda = renumber_lines(frames, zda)
    return frames, zda, errors, state_out


def _frozen_errors(
    f: SimFault,
    held: tuple[float, ...],
    errors: pd.DataFrame,
    truth: pd.DataFrame,
    lo: int,
    hi: int | None,
) -> pd.DataFrame:
    """Errors in the freeze window: the held reading minus the truth at every sample."""
    w = _in(errors["time_ns"].to_numpy(np.int64), lo, hi)
    if not w.any():
        return errors
    errors = errors.copy()
    if f.source in POSITION_SOURCES:
        lat = truth["lat_rad"].to_numpy(float)[w]
        lon = truth["lon_rad"].to_numpy(float)[w]
        n, e = offset_ne_m(held[0], held[1], lat, lon)
        for c, v in zip(error_columns(f.source), (n, e), strict=True):
            a = errors[c].to_numpy(float).copy()
            a[w] = v
            errors[c] = a
    else:
        col, true = (
            ("gyro_err_rad", "heading_rad")
            if f.source == "GYRO"
            else ("mag_err_rad", "compass_course_rad")
        )
        a = errors[col].to_numpy(float).copy()
        a[w] = angdiff(held[0], truth[true].to_numpy(float)[w])
        errors[col] = a
    return errors


def received_ns(df: pd.DataFrame) -> np.ndarray:
    """The receive (logger) time of each record: ``recv_ns`` where set, else ``time_ns``."""
    t = df["time_ns"].to_numpy(np.int64)
    r = df["recv_ns"].to_numpy(np.int64)
    out: np.ndarray = np.where(r != MISSING_NS, r, t)
    return out


def _of(df: pd.DataFrame, source: str | None) -> np.ndarray:
    """Rows of ``source`` (every row for the logger, ``ALL``)."""
    if source == LOGGER:
        return np.ones(len(df), bool)
    out: np.ndarray = (df["source"] == source).to_numpy(bool)
    return out


def _own_time(df: pd.DataFrame) -> np.ndarray:
    out: np.ndarray = df["sentence"].astype(str).isin(OWN_TIME_SENTENCES).to_numpy(bool)
    return out


def _leap(
    frames: dict[str, pd.DataFrame], zda: pd.DataFrame, shift: int, lo: int, hi: int | None
) -> tuple[dict[str, pd.DataFrame], pd.DataFrame]:
    """The GNSS's times of fix in the window ``shift`` ns ahead; its receive times kept."""
    out = dict(frames)
    for kind, df in frames.items():
        if not len(df):
            continue
        t = df["time_ns"].to_numpy(np.int64)
        win = _of(df, "GNSS") & _own_time(df) & _in(t, lo, hi)
        if win.any():
            df = df.copy()
            df["recv_ns"] = np.where(win, received_ns(df), df["recv_ns"].to_numpy(np.int64))
            df["time_ns"] = np.where(win, t + shift, t)
            out[kind] = df
    if len(zda):
        t = zda["time_ns"].to_numpy(np.int64)
        win = (zda["source"].to_numpy(object) == "GNSS") & _in(t, lo, hi)
        zda = zda.assign(time_ns=np.where(win, t + shift, t))
    return out, zda


def _clockstep(
    df: pd.DataFrame, source: str | None, step: int, lo: int, hi: int | None
) -> pd.DataFrame:
    """Receive stamps of records received in the window shifted by ``step`` ns: ``recv_ns``
    (set where the record has a time of fix) and the ``time_ns`` of records without."""
    if not len(df):
        return df
    rcv = received_ns(df)
    win = _of(df, source) & _in(rcv, lo, hi)
    if not win.any():
        return df
    own, r = _own_time(df), df["recv_ns"].to_numpy(np.int64)
    t = df["time_ns"].to_numpy(np.int64)
    df = df.copy()
    df["recv_ns"] = np.where(win & (own | (r != MISSING_NS)), rcv + step, r)
    df["time_ns"] = np.where(win & ~own, t + step, t)
    return df


def _loop(
    frames: dict[str, pd.DataFrame],
    zda: pd.DataFrame,
    source: str | None,
    lo: int,
    size: int,
) -> tuple[dict[str, pd.DataFrame], pd.DataFrame]:
    """The records received in ``[lo - size, lo)`` (of ``source``, or all) written again
    before the first line received at ``lo`` or later; lines renumbered in written order."""
    live = [df for df in frames.values() if len(df)]
    if not live:
        return frames, zda
    lines = np.concatenate([df["line"].to_numpy(np.int64) for df in live])
    late = np.concatenate([received_ns(df) >= lo for df in live])
    at = int(lines[late].min()) if late.any() else int(lines.max()) + 1
    pick = {
        k: _of(df, source)
        & (df["line"].to_numpy(np.int64) < at)
        & _in(received_ns(df), lo - size, lo)
        for k, df in frames.items()
        if len(df)
    }
    copied = np.unique(
        np.concatenate([frames[k]["line"].to_numpy(np.int64)[m] for k, m in pick.items()])
    )
    zl = zda["line"].to_numpy(np.int64) if len(zda) else np.zeros(0, np.int64)
    zpick = np.isin(zl - 1, copied) & (zl < at)  # a ZDA follows its RMC: copied with it
    copied = np.union1d(copied, zl[zpick])
    if not len(copied):
        return frames, zda
    # order keys: the originals at line * K, the copies just before line ``at``
    big = len(copied) + 2

    def keyed(df: pd.DataFrame, m: np.ndarray) -> pd.DataFrame:
        ln = df["line"].to_numpy(np.int64)
        copy = df[m].assign(line=(at - 1) * big + 1 + np.searchsorted(copied, ln[m]))
        both = pd.concat([df.assign(line=ln * big), copy], ignore_index=True)
        return both.iloc[np.argsort(both["line"].to_numpy(np.int64), kind="stable")]

    out = {k: keyed(df, pick[k]) if k in pick else df for k, df in frames.items()}
    return renumber_lines(out, keyed(zda, zpick) if len(zda) else zda)


def renumber_lines(
    frames: dict[str, pd.DataFrame], zda: pd.DataFrame
) -> tuple[dict[str, pd.DataFrame], pd.DataFrame]:
    """Close up the line numbers (1..n in the old order) after records were removed: the
    lines a reader of the written log numbers.  A line shared by two frames (RMC: position
    and ground) keeps one number."""
    parts = [df["line"].to_numpy(np.int64) for df in frames.values() if len(df)]
    if len(zda):
        parts.append(zda["line"].to_numpy(np.int64))
    if not parts:
        return frames, zda
    u = np.unique(np.concatenate(parts))

    def new(df: pd.DataFrame) -> pd.DataFrame:
        if not len(df):
            return df
        df = df.copy()
        df["line"] = np.searchsorted(u, df["line"].to_numpy(np.int64)).astype(np.int64) + 1
        return df

    return {k: new(df) for k, df in frames.items()}, new(zda)
