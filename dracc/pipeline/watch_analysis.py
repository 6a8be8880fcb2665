"""The rolling statistics of ``dracc watch``: the lines of the last ``window`` analysed
by the same library functions as ``dracc analyze`` and ``dracc audit``, and the hourly
INS deviations kept over the deviation window.

Nothing here is a second implementation.  :class:`LineWindow` keeps the recent lines as
they are recorded (TAG-block NMEA with their receive times), in chunks, bounded by the
window's span of data time and by ``max_bytes``.  Every ``every_s`` the window is written
to temporary files and :func:`analyse_window` reads them with
:func:`dracc.ingest.read_logs` and runs :func:`dracc.pipeline.analysis.analyse_voyage`
(integrity, faults, dead reckoning, deviation) on them: the roles of the sources, the DR
from the last fix with its 2M against GNSS, the integrity checks.

The INS deviation statistics need hourly samples (K: 1 h) over a day, longer than the
window: the readings of each INS unit and of the GNSS within ``max_interp_gap_s`` (plus a
minute) of a sampling instant are kept in a :class:`DeviationStore` (a few minutes an
hour, bounded by the deviation window), merged from every analysis, and the statistics
are :func:`dracc.math.deviation.analyse_deviations` over them -- the samples and
statistics ``analyze`` gives for the same readings.

:class:`LiveAnalyser` runs the analyses, in a worker process (``spawn``: the poll loop
keeps its core) or inline (``executor=None``, for tests), never two at a time, and says
what it is doing in :meth:`LiveAnalyser.summary`.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Executor, Future
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dracc.core.config import Config
from dracc.core.errors import DraccError, InsufficientDataError
from dracc.core.numbers import finite_or_none
from dracc.core.vocabulary import INS_ROLES
from dracc.ingest.live.record import form_suffix
from dracc.math.deviation import UnitSeries, analyse_deviations, unit_series_from_voyage
from dracc.math.integrity import IntegrityResult
from dracc.math.integrity.causes import failed_with_consequences
from dracc.pipeline.audit.facts import channel_rows

#: the roles whose readings the deviation store keeps
DEVIATION_ROLES = (*INS_ROLES, "gnss")
#: margin (s) kept beyond ``max_interp_gap_s`` on each side of a sampling instant
INSTANT_MARGIN_S = 60.0
#: evidence items of an integrity check carried into a finding, at most
MAX_EVIDENCE = 5


@dataclass
class LineWindow:
    """The lines of the last ``window_s`` of data time, bounded by ``max_bytes``: chunks of
    ``(first_ns, last_ns, form, bytes)`` (one per watch step and form, lines ending in
    LF).  ``trimmed_bytes`` counts what the byte bound dropped before its time."""

    window_s: float
    max_bytes: int
    chunks: deque[tuple[int, int, str, bytes]] = field(default_factory=deque)
    size: int = 0
    trimmed_bytes: int = 0
    newest_ns: int = 0

    def add(self, form: str, first_ns: int, last_ns: int, data: bytes) -> None:
        """Append a chunk and drop what fell out of the window (by time, then by size)."""
        if not data:
            return
        self.chunks.append((first_ns, last_ns, form, data))
        self.size += len(data)
        self.newest_ns = max(self.newest_ns, last_ns)
        oldest_ns = self.newest_ns - int(self.window_s * 1e9)
        while self.chunks and (self.chunks[0][1] < oldest_ns or self.size > self.max_bytes):
            dropped = self.chunks.popleft()
            self.size -= len(dropped[3])
            if dropped[1] >= oldest_ns:
                self.trimmed_bytes += len(dropped[3])

    def span_ns(self) -> tuple[int, int] | None:
        """(first, last) data time held, None when empty."""
        if not self.chunks:
            return None
        return min(c[0] for c in self.chunks), self.newest_ns

    def write(self, folder: Path, name: str) -> list[Path]:
        """The window as files ``folder/name<suffix>``, one per recording suffix (the
        forms of the NMEA 0183 recording in one ``.nmea``, each other form in its own)."""
        files: dict[str, Any] = {}  # by suffix: forms recorded together are read together
        try:
            for _, _, form, data in self.chunks:
                suffix = form_suffix(form)
                if suffix not in files:
                    files[suffix] = (folder / f"{name}{suffix}").open("wb")
                files[suffix].write(data)
        finally:
            for f in files.values():
                f.close()
        return [Path(f.name) for f in files.values()]


# ------------------------------------------------------------------ deviation store


def _near_instants(t_ns: np.ndarray, cfg: Config) -> np.ndarray:
    """Mask of the times within ``max_interp_gap_s`` + margin of a sampling instant
    (``offset + k * interval`` from 00:00 UTC, as :func:`sampling_instants`)."""
    step = int(round(cfg.deviation.interval_s * 1e9))
    off = int(round(cfg.deviation.offset_s * 1e9))
    half = int((cfg.deviation.max_interp_gap_s + INSTANT_MARGIN_S) * 1e9)
    phase = (t_ns.astype(np.int64) - off) % step  # midnight is a multiple of a day
    return (phase <= half) | (phase >= step - half)


def _merge(
    t_old: np.ndarray, v_old: tuple[np.ndarray, ...], t_new: np.ndarray, v_new: tuple, keep: Any
) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """Readings of old and new at their times (a time in both: the new reading), sorted,
    restricted to ``keep(t) -> mask``."""
    t = np.concatenate([t_new.astype(np.int64), t_old.astype(np.int64)])
    vals = [
        np.concatenate([np.asarray(a, float), np.asarray(b, float)])
        for a, b in zip(v_new, v_old, strict=True)
    ]
    _, first = np.unique(t, return_index=True)  # the first of equal times: the new one
    first = first[keep(t[first])]
    return t[first], tuple(v[first] for v in vals)


@dataclass(frozen=True)
class DeviationStore:
    """Per role (ins1..ins3, gnss) the readings near the sampling instants over the
    deviation window (picklable: it travels to the worker and back)."""

    units: dict[str, UnitSeries] = field(default_factory=dict)

    def merged(self, new: dict[str, UnitSeries], cfg: Config, now_ns: int) -> DeviationStore:
        """This store with ``new`` readings added and those older than the deviation
        window (``[deviation] window_s`` before ``now_ns``) dropped."""
        oldest = now_ns - int(cfg.deviation.window_s * 1e9)

        def keep(t: np.ndarray) -> np.ndarray:
            return (t >= oldest) & _near_instants(t, cfg)

        out: dict[str, UnitSeries] = {}
        for role in DEVIATION_ROLES:
            a = self.units.get(role, UnitSeries())
            b = new.get(role, UnitSeries())
            pt, (lat, lon) = _merge(
                a.pos_time_ns, (a.lat_rad, a.lon_rad), b.pos_time_ns, (b.lat_rad, b.lon_rad), keep
            )
            ht, (hdg,) = _merge(
                a.hdg_time_ns, (a.heading_rad,), b.hdg_time_ns, (b.heading_rad,), keep
            )
            vt, (vn, ve) = _merge(
                a.vel_time_ns, (a.vn_mps, a.ve_mps), b.vel_time_ns, (b.vn_mps, b.ve_mps), keep
            )
            if len(pt) or len(ht) or len(vt):
                out[role] = UnitSeries(pt, lat, lon, ht, hdg, vt, vn, ve)
        return DeviationStore(out)

    def readings(self) -> int:
        return sum(
            len(u.pos_time_ns) + len(u.hdg_time_ns) + len(u.vel_time_ns)
            for u in self.units.values()
        )


def deviation_summary(store: DeviationStore, cfg: Config) -> dict[str, Any] | None:
    """The INS deviation statistics over the store (``analyse_deviations``, as
    ``analyze``); None with fewer than two units."""
    units = {r: store.units[r] for r in INS_ROLES if r in store.units}
    if len(units) < 2:
        return None
    dev = analyse_deviations(units, cfg.deviation, store.units.get("gnss"))
    rows = channel_rows(dev)
    return {
        "units": sorted(units),
        "reference": "gnss" if "gnss" in store.units else None,
        "samples": int(max((r.n for r in rows), default=0)),
        "interval_s": cfg.deviation.interval_s,
        "window_s": cfg.deviation.window_s,
        "channels": [
            {
                "ins_unit": r.unit,
                "channel": r.channel,
                "n": r.n,
                "m_u": r.m_u,
                "m_y": r.m_y,
                "kurtosis": r.kurtosis,
                "limit_error": r.limit_error,
            }
            for r in rows
        ],
    }


# ------------------------------------------------------------------- the analysis


@dataclass(frozen=True)
class WindowResult:
    """What one analysis of the window gives the watch (JSON-ready dicts; picklable)."""

    span_utc_ns: tuple[int, int]
    lines: int
    seconds: float
    roles: dict[str, list[str]]  #: source key -> roles
    dead_reckoning: dict[str, Any] | None
    deviation: dict[str, Any] | None
    checks: list[dict[str, Any]]  #: every integrity check made (status pass/fail/not_checked)
    missing: list[str]
    store: DeviationStore


def _dr_summary(a: Any) -> dict[str, Any] | None:
    """The DR of the window: the last epoch (from the last fix: its 2M and, with a
    reference, the error and whether it is inside) and the window's consistency."""
    dr = a.dead_reckoning
    if dr is None or not len(dr.epochs.time_ns):
        return None
    e = dr.epochs
    i = len(e.time_ns) - 1
    err = finite_or_none(float(e.ref_error_m[i]))
    r2m = finite_or_none(float(e.radius_2m_m[i]))
    legs = dr.legs
    return {
        "epoch_utc_ns": int(e.time_ns[i]),
        "lat_deg": float(np.degrees(e.lat_rad[i])),
        "lon_deg": float(np.degrees(e.lon_rad[i])),
        "since_fix_s": finite_or_none(float(e.since_fix_s[i])),
        "fix_source": legs[-1].fix_source if legs else None,
        "radius_2m_m": r2m,
        "reference": dr.reference_role,
        "error_m": err,
        "inside_2m": None if err is None or r2m is None else bool(err <= r2m),
        "containment_2m": finite_or_none(dr.containment_2m),
        "n_scored": int(dr.n_scored),
        "expected_inside": finite_or_none(dr.expected_inside),
        "consistent": dr.consistent,
        "verdict": dr.verdict,
        "heading_source": dr.heading_source,
        "speed_source": dr.speed_source,
        "legs": len(legs),
    }


def _check_dict(c: Any, cause: Any = None, consequences: Sequence[Any] = ()) -> dict[str, Any]:
    """One check of the window as the watch raises it: a failed check another caused
    (``cause``: its check, name, source) is no alarm of its own; it is listed under its
    cause's ``consequences`` (:func:`dracc.math.integrity.causes.failed_with_consequences`)."""
    return {
        "check": c.check,
        "name": c.name,
        "source": c.source,
        "role": c.role,
        "status": c.status,
        "message": c.message,
        "evidence": {
            "statistic": c.statistic,
            "threshold": c.threshold,
            "items": list(c.evidence[:MAX_EVIDENCE]),
            "items_total": len(c.evidence),
        },
        "cause": None if cause is None else [cause.check, cause.name, cause.source],
        "consequences": [
            {"check": k.check, "name": k.name, "source": k.source, "message": k.message}
            for k in consequences
        ],
    }


def _check_dicts(ig: IntegrityResult) -> list[dict[str, Any]]:
    """Every check of the window, each failed one with its cause or its consequences."""
    grouped = failed_with_consequences(ig)
    under = {id(c): caused for c, caused in grouped}
    cause = {id(k): c for c, caused in grouped for k in caused}
    return [_check_dict(c, cause.get(id(c)), under.get(id(c), ())) for c in ig.checks]


def analyse_window(paths: list[str], cfg: Config, store: DeviationStore) -> WindowResult:
    """Read the window files and analyse them as ``dracc analyze`` does; merge the
    readings near the sampling instants into ``store`` and give the deviation
    statistics over it.  Raises what ``analyse`` raises (an empty window:
    :class:`~dracc.core.errors.InsufficientDataError`)."""
    from dracc.ingest import read_logs  # heavy; on use (in the worker)
    from dracc.pipeline.analysis import analyse_voyage

    t0 = time.perf_counter()
    voyage = read_logs([Path(p) for p in paths], cfg.ingest)
    a = analyse_voyage(voyage, cfg)
    if a.start_ns is None or a.end_ns is None:
        raise InsufficientDataError("the window holds no dated record yet")
    new = {r: unit_series_from_voyage(voyage, r) for r in DEVIATION_ROLES if voyage.role_sources(r)}
    store = store.merged(new, cfg, int(a.end_ns))
    roles = {str(s.key): [str(r) for r in s.roles] for s in a.sources}
    checks = [] if a.integrity is None else _check_dicts(a.integrity)
    return WindowResult(
        span_utc_ns=(int(a.start_ns), int(a.end_ns)),
        lines=int(a.lines),
        seconds=round(time.perf_counter() - t0, 3),
        roles=roles,
        dead_reckoning=_dr_summary(a),
        deviation=deviation_summary(store, cfg),
        checks=checks,
        missing=[str(m) for m in a.missing],
        store=store,
    )


class LiveAnalyser:
    """The window and the store, and the analyses over them every ``every_s``; in the
    ``executor`` (a one-process pool) or inline when it is None."""

    def __init__(
        self,
        cfg: Config,
        window_s: float,
        every_s: float,
        max_bytes: int,
        executor: Executor | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.cfg = cfg
        self.every_s = every_s
        self.window = LineWindow(window_s, max_bytes)
        self.store = DeviationStore()
        self.executor = executor
        self.clock = clock
        self.folder = Path(tempfile.mkdtemp(prefix="dracc-watch-"))
        self.job: Future[WindowResult] | None = None
        self.job_files: list[Path] = []
        self.next_at = clock() + every_s
        self.runs = 0
        self.last: WindowResult | None = None
        self.error: str | None = None  #: why the last analysis gave nothing
        self._pending: dict[str, list[bytes]] = {}
        self._pending_span: dict[str, list[int]] = {}

    def add(self, form: str, t_ns: int, line: bytes) -> None:
        """One recorded line (without its line end) at data time ``t_ns``."""
        lines = self._pending.get(form)
        if lines is None:
            lines = self._pending[form] = []
            self._pending_span[form] = [t_ns, t_ns]
        lines.append(line)
        span = self._pending_span[form]
        if t_ns < span[0]:
            span[0] = t_ns
        elif t_ns > span[1]:
            span[1] = t_ns

    def end_step(self) -> WindowResult | None:
        """Move the step's lines into the window; start an analysis when one is due and
        none is running; return the result of one that has finished (else None)."""
        for form, lines in self._pending.items():
            first, last = self._pending_span[form]
            self.window.add(form, first, last, b"\n".join(lines) + b"\n")
        self._pending.clear()
        self._pending_span.clear()
        done = self._collect()
        if self.job is None and self.clock() >= self.next_at and self.window.chunks:
            self._start()
            if self.executor is None:
                done = self._collect() or done
        return done

    def _start(self) -> None:
        self.runs += 1
        self.next_at = self.clock() + self.every_s
        self.job_files = self.window.write(self.folder, f"window-{self.runs}")
        paths = [str(p) for p in self.job_files]
        if self.executor is None:
            f: Future[WindowResult] = Future()
            try:
                f.set_result(analyse_window(paths, self.cfg, self.store))
            except Exception as e:  # noqa: BLE001 - said in the status, the watch goes on
                f.set_exception(e)
            self.job = f
        else:
            self.job = self.executor.submit(analyse_window, paths, self.cfg, self.store)

    def _collect(self) -> WindowResult | None:
        if self.job is None or not self.job.done():
            return None
        job, self.job = self.job, None
        for p in self.job_files:
            p.unlink(missing_ok=True)
        try:
            result = job.result()
        except DraccError as e:
            self.error = str(e)
            return None
        except Exception as e:  # noqa: BLE001 - a worker that died, a bug: said, not fatal
            self.error = f"the analysis failed: {type(e).__name__}: {e}"
            return None
        self.error = None
        self.store = result.store
        self.last = replace(result, store=DeviationStore())  # the store is kept once
        return result

    def summary(self) -> dict[str, Any]:
        """What the analyser holds and did, for the status document."""
        span = self.window.span_ns()
        last = self.last
        return {
            "window_s": self.window.window_s,
            "every_s": self.every_s,
            "window_bytes": self.window.size,
            "window_first_ns": span[0] if span else None,
            "window_last_ns": span[1] if span else None,
            "trimmed_bytes": self.window.trimmed_bytes,
            "runs": self.runs,
            "running": self.job is not None,
            "last_lines": last.lines if last else None,
            "last_seconds": last.seconds if last else None,
            "deviation_readings": self.store.readings(),
            "error": self.error,
        }

    def close(self) -> None:
        """Wait for a running analysis to end (it is not collected) and remove the files."""
        if self.job is not None:
            with contextlib.suppress(Exception):
                self.job.result(timeout=30)
        shutil.rmtree(self.folder, ignore_errors=True)


def _ignore_signals() -> None:
    """The worker leaves SIGINT/SIGTERM to the watch, which shuts the pool down."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def worker_pool() -> Executor:
    """One ``spawn`` worker process for the analyses (a fresh interpreter: nothing of the
    watch's sockets or recording is shared with it)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(
        1, mp_context=multiprocessing.get_context("spawn"), initializer=_ignore_signals
    )
