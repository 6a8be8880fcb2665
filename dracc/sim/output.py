"""``dracc simulate``'s files: a simulated voyage written to a folder as its log (in one of
:data:`FORMATS`), truth.csv, errors.csv and params.json, from the command's options.

:func:`simulate_to_folder` checks the options, builds the :class:`SimParams` (the seeded
faults resolved, the sources' clocks), simulates (NMEA in segments, so memory does not grow
with the hours), writes every file atomically and returns what the command reports.
params.json holds the clock truth per source (``clocks``, :func:`merge_clocks`).
"""

from __future__ import annotations

import json
import math
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import pandas as pd

from dracc import __version__
from dracc.core.atomic import atomic_path, write_text
from dracc.core.errors import ConfigError, DraccError
from dracc.sim.faults import SimFault, fault_table, parse_fault, resolve_faults
from dracc.sim.model import SimVoyage, simulate, simulate_segments
from dracc.sim.params import SimParams, random_clocks
from dracc.sim.truth import generated_legs, start_ns

FORMATS = ("nmea", "csv-long", "csv-wide", "mcap-json", "mcap-ros2", "mcap-protobuf", "mcap-nmea")
EXT = {
    "nmea": "nmea",
    "csv-long": "csv",
    "csv-wide": "csv",
    "mcap-json": "mcap",
    "mcap-ros2": "mcap",
    "mcap-protobuf": "mcap",
    "mcap-nmea": "mcap",
}


def write_log(
    voyage: SimVoyage, path: Path, fmt: str, form: str = "tag", tag_time: str = "s"
) -> None:
    """Write the voyage's log in ``fmt`` (one of :data:`FORMATS`) to ``path``."""
    if fmt == "nmea":
        from dracc.sim.nmea_out import write_nmea

        write_nmea(voyage, path, form=form, tag_time=tag_time)
    elif fmt.startswith("csv-"):
        try:
            from dracc.sim.csv_out import write_csv
        except ImportError as e:
            raise DraccError(f"CSV output is not available in this build ({e})") from e
        write_csv(voyage.frames, path, form=fmt[4:], date_shifts=voyage.date_shifts)
    elif fmt.startswith("mcap-"):
        try:
            from dracc.sim.mcap_out import write_mcap
        except ImportError as e:
            raise DraccError(f"MCAP output is not available in this build ({e})") from e
        # a loop or a clock step is written as the logger wrote it, back in log time
        stepped = any(f.kind in ("loop", "clockstep") for f in voyage.params.faults)
        write_mcap(
            voyage.frames,
            voyage.roles,
            path,
            encoding=fmt[5:],
            order="line" if stepped else "time",
            date_shifts=voyage.date_shifts,
        )
    else:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")


def write_table(df: pd.DataFrame, fh: TextIO, header: bool = True) -> None:
    """A truth or error table as CSV into an open text file: time_utc (ISO, ns) first,
    floats to 12 significant digits."""
    out = df.copy()
    out.insert(
        0,
        "time_utc",
        np.char.add(
            np.datetime_as_string(df["time_ns"].to_numpy().astype("datetime64[ns]"), unit="ns"), "Z"
        ),
    )
    out.to_csv(fh, index=False, header=header, float_format="%.12g", lineterminator="\n")


def decimate(df: pd.DataFrame, truth_hz: float, base_hz: float, start_ns: int) -> pd.DataFrame:
    """Rows at ``start + k / truth_hz`` (all rows for ``truth_hz <= 0`` or faster than the data)."""
    if truth_hz <= 0 or truth_hz >= base_hz:
        return df
    step = base_hz / truth_hz
    if abs(step - round(step)) > 1e-9:
        raise ConfigError(f"--truth-hz {truth_hz} does not divide the truth rate {base_hz} Hz")
    step_ns = int(round(1e9 / truth_hz))
    return df[(df["time_ns"].to_numpy() - start_ns) % step_ns == 0]


@dataclass(frozen=True)
class SimulationWritten:
    """What :func:`simulate_to_folder` wrote: the log, the seconds spent simulating and
    writing the log and tables, and the seeded faults as resolved."""

    log_path: Path
    seconds: float
    faults: tuple[SimFault, ...]
    #: source -> its clock truth over the whole voyage (params.json ``clocks``)
    clocks: dict[str, dict[str, float]] = field(default_factory=dict)


def _unit_scales(text: str) -> tuple[float, float, float]:
    """``--ins-unit-scales``: three positive factors 'A,B,C' for INS1..INS3."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        k = tuple(float(p) for p in parts)
    except ValueError:
        k = ()
    if len(k) != 3 or not all(math.isfinite(x) and x >= 0 for x in k):
        raise ConfigError(
            f"--ins-unit-scales must be three factors >= 0 such as 1,3,1, got {text!r}"
        )
    return (k[0], k[1], k[2])


def _clock_pairs(items: list[str], option: str) -> tuple[tuple[str, float], ...]:
    """``--phase``/``--latency`` values ``SRC=S`` as (SRC, seconds) pairs."""
    out = []
    for item in items:
        src, sep, value = str(item).partition("=")
        try:
            sec = float(value)
        except ValueError:
            sep = ""
        if not sep or not src.strip():
            raise ConfigError(f"{option} {item!r}: expected SRC=SECONDS, e.g. INS2=0.3")
        out.append((src.strip().upper(), sec))
    return tuple(out)


def with_clocks(
    params: SimParams,
    clocks: str = "none",
    latency_max: float = 2.0,
    phase: list[str] | None = None,
    latency: list[str] | None = None,
) -> SimParams:
    """``params`` with the sources' clocks of ``dracc simulate``'s options: ``clocks``
    'random' (:func:`random_clocks` from the voyage's seed) or 'none'; then each
    ``--phase``/``--latency SRC=S`` replaces its source's value."""
    if clocks not in ("none", "random"):
        raise ConfigError(f"--clocks must be none or random, got {clocks!r}")
    if clocks == "random":
        params = random_clocks(params, params.seed, latency_max)
    phases = _clock_pairs(phase or [], "--phase")
    lags = _clock_pairs(latency or [], "--latency")

    def over(old: tuple[tuple[str, float], ...], new: tuple[tuple[str, float], ...]) -> Any:
        named = {s for s, _ in new}
        return tuple((s, v) for s, v in old if s not in named) + new

    params = replace(
        params, phases_s=over(params.phases_s, phases), latency_s=over(params.latency_s, lags)
    )
    params.clock_steps()  # a source the voyage lacks, a phase beyond the period: now
    return params


def merge_clocks(
    total: dict[str, dict[str, float]], part: dict[str, dict[str, float]]
) -> dict[str, dict[str, float]]:
    """The clock truth of two stretches of a voyage: the offsets' means weighted by records."""
    out = {k: dict(v) for k, v in total.items()}
    for src, c in part.items():
        if src not in out:
            out[src] = dict(c)
            continue
        n0, n1 = out[src]["records"], c["records"]
        for key in ("offset_s", "offset_whole_s_stamps"):
            if n1:
                a = out[src][key] if n0 else 0.0
                out[src][key] = round((a * n0 + c[key] * n1) / (n0 + n1), 9)  # to the ns
        out[src]["records"] = n0 + n1
    return out


def _json_clocks(clocks: dict[str, dict[str, float]]) -> dict[str, dict[str, Any]]:
    """NaN as null, records as an integer."""
    return {
        src: {k: (int(v) if k == "records" else None if math.isnan(v) else v) for k, v in c.items()}
        for src, c in clocks.items()
    }


def simulate_to_folder(
    *,
    out_dir: Path,
    hours: float,
    seed: int,
    start: str,
    fmt: str,
    form: str,
    tag_time: str,
    compass: str,
    compass_hz: float,
    log_hz: float,
    ins_hz: float,
    gnss_hz: float,
    aux_hz: float,
    lat_deg: float,
    lon_deg: float,
    speed_kn: float,
    legs: str,
    ins_talkers: str,
    ins_error_scale: float,
    ins_unit_scales: str,
    gyro_error_deg: float,
    log_scale_pct: float,
    log_bias_kn: float,
    current_kn: float,
    current_set_deg: float,
    variation_deg: float,
    noiseless: bool,
    truth_hz: float,
    name: str,
    segment_hours: float,
    fault: list[str],
    clocks: str = "none",
    latency_max: float = 2.0,
    phase: list[str] | None = None,
    latency: list[str] | None = None,
) -> SimulationWritten:
    """Simulate a voyage and write it to ``out_dir``: ``<name>.<ext>`` (the log in ``fmt``),
    truth.csv, errors.csv and params.json.  The arguments are ``dracc simulate``'s options
    by name (``legs`` as for :func:`parse_legs`, ``fault`` as for
    :func:`dracc.sim.faults.parse_fault`, the clocks as for :func:`with_clocks`); a value
    it cannot use is a ConfigError naming the option."""
    if fmt not in FORMATS:
        raise ConfigError(f"--format must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if not (hours > 0 and math.isfinite(hours)):
        raise ConfigError(f"--hours must be positive, got {hours}")
    common: dict[str, Any] = {
        "legs": parse_legs(legs),
        "ins_talkers": tuple(ins_talkers.split(",")),
        "duration_s": hours * 3600.0,
        "seed": seed,
        "start_utc": start,
        "start_lat_deg": lat_deg,
        "start_lon_deg": lon_deg,
        "speed_kn": speed_kn,
        "compass": compass,
        "compass_hz": compass_hz,
        "log_hz": log_hz,
        "ins_hz": ins_hz,
        "gnss_hz": gnss_hz,
        "aux_hz": aux_hz,
        "variation_deg": variation_deg,
        "current_set_deg": current_set_deg,
    }
    if noiseless:
        params = SimParams.noiseless(**common)
    else:
        params = SimParams(
            **common,
            gyro_offset_deg=gyro_error_deg,
            log_scale=log_scale_pct / 100.0,
            log_bias_kn=log_bias_kn,
            current_drift_kn=current_kn,
        ).with_ins_error_scale(ins_error_scale)
        params = params.with_ins_unit_scales(_unit_scales(ins_unit_scales))
    if not segment_hours > 0:
        raise ConfigError(f"--segment-hours must be positive, got {segment_hours}")
    if form not in ("tag", "prefix", "bare") or tag_time not in ("s", "ms", "auto"):
        raise ConfigError(
            f"--form must be tag, prefix or bare and --tag-time s, ms or auto, "
            f"got {form!r}, {tag_time!r}"
        )
    if tag_time == "auto":
        # whole seconds would give every sub-second sentence its neighbour's time
        tag_time = "ms" if max(compass_hz, log_hz, ins_hz, gnss_hz, aux_hz) > 1.0 else "s"
    params = with_clocks(
        replace(params, legs=generated_legs(params)), clocks, latency_max, phase, latency
    )
    specs = list(fault or [])
    params = replace(
        params,
        faults=resolve_faults(
            [parse_fault(f) for f in specs],
            params.duration_s,
            params.seed,
            params.compass,
            labels=specs,
        ),
    )
    return write_voyage(
        params,
        out_dir,
        fmt=fmt,
        form=form,
        tag_time=tag_time,
        name=name,
        truth_hz=truth_hz,
        segment_hours=segment_hours,
    )


def write_voyage(
    params: SimParams,
    out_dir: Path,
    *,
    fmt: str,
    form: str,
    tag_time: str,
    name: str,
    truth_hz: float,
    segment_hours: float,
) -> SimulationWritten:
    """Simulate ``params`` and write the log ``out_dir/<name>.<ext>`` (NMEA in segments of
    ``segment_hours``), truth.csv and errors.csv at ``truth_hz`` and params.json."""
    p = params
    base_hz = max(p.compass_hz, p.log_hz, p.ins_hz, p.gnss_hz, p.aux_hz)
    t0_ns = start_ns(params.start_utc)
    log_path = out_dir / f"{name}.{EXT[fmt]}"
    t0 = time.perf_counter()
    records: Counter[str] = Counter()
    sq = {u: {"lat_m": 0.0, "lon_m": 0.0, "course_deg": 0.0} for u in ("ins1", "ins2", "ins3")}
    count = dict.fromkeys(sq, 0)
    roles: dict[str, str] = {}
    clocks: dict[str, dict[str, float]] = {}
    with (
        atomic_path(out_dir / "truth.csv") as tt,
        atomic_path(out_dir / "errors.csv") as te,
        open(tt, "w", encoding="utf-8") as ft,
        open(te, "w", encoding="utf-8") as fe,
    ):
        if fmt == "nmea":
            from dracc.sim.nmea_out import iter_blocks

            with atomic_path(log_path) as tl, open(tl, "wb") as fl:
                log = _ReceivedOrder(fl, hold=bool(params.latency_s))
                for i, v in enumerate(simulate_segments(params, segment_hours * 3600.0)):
                    blocks = iter_blocks(
                        v.frames, v.roles, form, tag_time, order="line", date_shifts=v.date_shifts
                    )
                    log.segment(blocks, int(v.truth["time_ns"].iloc[-1]))
                    _tables_and_tallies(v, i, ft, fe, truth_hz, base_hz, t0_ns, records, sq, count)
                    roles = v.roles
                    clocks = merge_clocks(clocks, v.clocks)
                log.close()
        else:
            v = simulate(params)
            write_log(v, log_path, fmt)
            _tables_and_tallies(v, 0, ft, fe, truth_hz, base_hz, t0_ns, records, sq, count)
            roles, clocks = v.roles, v.clocks
    t1 = time.perf_counter()
    unit_rms = {
        u: {ch: math.sqrt(s / count[u]) if count[u] else float("nan") for ch, s in sq[u].items()}
        for u in sq
    }
    info = {
        "dracc_version": __version__,
        "format": fmt,
        "form": form if fmt == "nmea" else None,
        "tag_time": tag_time if fmt == "nmea" and form == "tag" else None,
        "files": {"log": log_path.name, "truth": "truth.csv", "errors": "errors.csv"},
        "roles": roles,
        "unit_rms": unit_rms,
        "records": dict(records),
        "faults": fault_table(params.faults, t0_ns, params.duration_s, roles),
        "clocks": _json_clocks(clocks),
        "params": params.to_dict(),
    }
    write_text(out_dir / "params.json", json.dumps(info, indent=2) + "\n")
    return SimulationWritten(log_path, t1 - t0, tuple(params.faults), clocks)


class _ReceivedOrder:
    """Writes the segments' lines to ``fh`` in the order they are received: with ``hold``
    (the sources have latencies) lines of a segment received after its last sample are
    held back and merged by receive time into the next segment's first lines."""

    def __init__(self, fh: Any, hold: bool, newline: bytes = b"\r\n") -> None:
        self.fh, self.nl, self.hold = fh, newline, hold
        self.held_t = np.zeros(0, np.int64)
        self.held: list[bytes] = []

    def segment(self, blocks: Any, end_ns: int) -> None:
        if not self.hold:
            for _, _, blob in blocks:
                self.fh.write(blob)
            return
        last = None
        for t, _, blob in blocks:
            if last is not None:
                self._write(*last)
            last = (t, blob)
        if last is None:
            return
        t, blob = last
        early = np.flatnonzero(t <= end_ns)
        k = int(early[-1]) + 1 if len(early) else 0
        lines = blob.split(self.nl)[:-1]
        if k < len(t):  # received after the segment's end: held for the next one
            self._write(t[:k], b"".join(ln + self.nl for ln in lines[:k]))
            self.held_t, self.held = t[k:], lines[k:]
        else:
            self._write(t, blob)

    def _write(self, t: np.ndarray, blob: bytes) -> None:
        if not len(self.held):
            self.fh.write(blob)
            return
        lines = blob.split(self.nl)[:-1]
        k = int(np.searchsorted(t, self.held_t[-1], side="right"))
        both = self.held + lines[:k]
        o = np.argsort(np.concatenate([self.held_t, t[:k]]), kind="stable")
        self.fh.write(b"".join(both[i] + self.nl for i in o))
        self.fh.write(b"".join(ln + self.nl for ln in lines[k:]))
        self.held_t, self.held = np.zeros(0, np.int64), []

    def close(self) -> None:
        self.fh.write(b"".join(ln + self.nl for ln in self.held))
        self.held_t, self.held = np.zeros(0, np.int64), []


def _tables_and_tallies(
    v: SimVoyage,
    i: int,
    ft: TextIO,
    fe: TextIO,
    truth_hz: float,
    base_hz: float,
    t0_ns: int,
    records: Counter[str],
    sq: dict[str, dict[str, float]],
    count: dict[str, int],
) -> None:
    """Append one segment's truth and errors; add up its records and INS squared errors."""
    write_table(decimate(v.truth, truth_hz, base_hz, t0_ns), ft, header=i == 0)
    write_table(decimate(v.errors, truth_hz, base_hz, t0_ns), fe, header=i == 0)
    for kind, f in v.frames.items():
        records[kind] += len(f)
    pos = v.frames["position"]
    for u in sq:
        n = int((pos["source"] == u.upper()).sum())
        if n == 0:  # a short last segment may hold no INS sample
            continue
        count[u] += n
        for ch, rms in v.unit_rms[u].items():
            sq[u][ch] += n * rms**2


def parse_legs(text: str) -> tuple[tuple[float, float], ...] | None:
    """``'0:60,3600:150'`` -> ((0.0, 60.0), (3600.0, 150.0)); '' -> None (generated)."""
    if not text.strip():
        return None
    legs = []
    for item in text.split(","):
        try:
            t_s, deg = (float(x) for x in item.split(":"))
        except ValueError as e:
            raise ConfigError(f"--legs: {item!r} is not T_S:DEG (e.g. 3600:150)") from e
        if not (math.isfinite(t_s) and math.isfinite(deg)):
            raise ConfigError(f"--legs: {item!r} is not finite")
        legs.append((t_s, deg))
    return tuple(legs)
