"""Batch fleet reports: many vessels' logs analysed in parallel, resumable.

Each log file is one task.  Workers run :func:`analyse_log` (the pipeline plus the JSON
serialiser) and send back a small summary of the analysis document (no samples, no DR
epochs).  The parent caches every summary under ``OUT/cache/`` keyed by the SHA-256 of
the log's bytes and of the analysis settings (written atomically; entries written by
another dracc version are analysed again), so a re-run skips what was done unless
``force``; a failing log becomes a row with ``status='failed'`` and
an entry in ``failures``, never the end of the batch.

Engines: a local :class:`concurrent.futures.ProcessPoolExecutor` (``workers``), or an
existing Dask distributed scheduler (``scheduler='tcp://host:port'``, through
:class:`distributed.Client`).  The workers must see the log paths (a shared disk).

The fleet table has one row per log, unit and channel (a log without INS statistics has
one row with empty unit and channel).  The a priori verdict applies the monitoring rule
(:func:`dracc.pipeline.audit.apriori_chain`) per vessel, unit and channel in time order, seeded
with ``[deviation.apriori]``.  The per-day trend pools the RMS of the day's logs::

    m_y,day = sqrt( sum_i n_i m_y,i^2 / sum_i n_i )        (pooled RMS, weights n_i)

Hostile inputs (issue 15): an input that is not a regular readable file (a FIFO, socket
or device, a dangling link, an unreadable file, a folder where ``--pattern`` names
files) and, inside a vessel folder, a symbolic link leading out of it, is a failed log
with why; it is never opened (a FIFO's open blocks) and makes the exit code 3.  The
outputs (tables, trends, per-vessel CSV, ``fleet.json``, ``fleet.html``) are written to a
staging folder and published together by one rename (:func:`dracc.core.atomic.file_set`);
CSV cells that a spreadsheet would read as a formula get a leading single quote.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import sys
import time
import unicodedata
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import asdict, dataclass
from pathlib import Path, PurePath

import numpy as np
import pandas as pd

from dracc import __version__
from dracc.core import atomic
from dracc.core.config import Config
from dracc.core.errors import ConfigError, DraccError, FleetError, IngestError
from dracc.core.vocabulary import CHANNELS
from dracc.core.workers import detach_worker
from dracc.pipeline.audit import (
    apriori_chain,
    apriori_seeds,
    facts_from_analysis,
    file_sha256,
    input_problem,
    outside_link,
    settings_sha256,
)

#: /2: the summary's "dr" carries the verdict word and the NEES statistic (a /1 entry is
#: analysed again)
CACHE_SCHEMA = "dracc.fleet.cache/2"

#: columns of the fleet table, in order (units in the names or in ``measure``)
TABLE_COLUMNS = (
    "vessel",
    "log",
    "sha256",
    "status",
    "error",
    "period_start_utc",
    "period_end_utc",
    "day",
    "unit",
    "channel",
    "measure",
    "n",
    "m_u",
    "m_y",
    "kurtosis",
    "limit",
    "apriori_before",
    "apriori_after",
    "apriori_verdict",
    "dr_containment_2m",
    "dr_n_scored",
    "dr_consistent",
    "dr_verdict",
    "dr_nees",
    "compass_error_deg",
    "compass_error_sigma_deg",
    "log_scale_pct",
    "log_scale_sigma_pct",
    "rejected_rate_pct",
    "lines",
)
TREND_COLUMNS = (
    "vessel",
    "day",
    "unit",
    "channel",
    "measure",
    "logs",
    "n",
    "m_y",
    "apriori_after",
    "dr_containment_2m",
)


# ------------------------------------------------------------------------ config


@dataclass(frozen=True)
class FleetConfig:
    """The ``[fleet]`` table."""

    workers: int | None = None  #: local processes (default: the machine's CPU count)
    pattern: str = "**/*"  #: glob for log files inside a vessel folder (hidden files skipped)
    out: str | None = None  #: output folder (default "fleet-report")
    scheduler: str | None = None  #: Dask scheduler address, e.g. "tcp://10.0.0.5:8786"
    connect_timeout_s: float = 30.0  #: how long to wait for the Dask scheduler


def fleet_config(cfg: Config) -> FleetConfig:
    """Validate ``cfg.extra['fleet']`` into a :class:`FleetConfig`."""
    table = cfg.extra.get("fleet", {})
    if not isinstance(table, dict):
        raise ConfigError(f"[fleet] must be a table, got {type(table).__name__}")
    known = list(asdict(FleetConfig()))
    unknown = set(table) - set(known)
    if unknown:
        raise ConfigError(
            f"[fleet] unknown key(s): {', '.join(sorted(unknown))}; "
            f"known: {', '.join(sorted(known))}"
        )
    kw: dict = {}
    if "workers" in table:
        w = table["workers"]
        if isinstance(w, bool) or not isinstance(w, int) or w < 1:
            raise ConfigError(f"[fleet] workers must be a positive integer, got {w!r}")
        kw["workers"] = w
    for key in ("pattern", "out", "scheduler"):
        if key in table:
            if not isinstance(table[key], str) or not table[key].strip():
                raise ConfigError(f"[fleet] {key} must be a non-empty string, got {table[key]!r}")
            kw[key] = table[key]
    if "connect_timeout_s" in table:
        v = table["connect_timeout_s"]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise ConfigError(f"[fleet] connect_timeout_s must be a positive number, got {v!r}")
        kw["connect_timeout_s"] = float(v)
    return FleetConfig(**kw)


# ------------------------------------------------------------------ names and paths


_UNSAFE = set('/\\:*?"<>|')
_RESERVED = (
    {"CON", "PRN", "AUX", "NUL"}
    | {f"COM{i}" for i in range(1, 10)}
    | {f"LPT{i}" for i in range(1, 10)}
)


def safe_name(name: str, max_len: int = 100) -> str:
    """A single path component for ``name``: separators and control characters become
    ``_``, leading/trailing dots and spaces go, Unicode letters stay (NFC).  When the
    result differs from ``name``, a short hash of ``name`` is appended so that two
    different names never share a folder."""
    nfc = unicodedata.normalize("NFC", name)
    s = "".join(
        "_" if (c in _UNSAFE or unicodedata.category(c).startswith("C")) else c for c in nfc
    )
    s = s.strip(" .")[:max_len]
    if not s or s.split(".")[0].upper() in _RESERVED:
        s = "_" + s
    if s != name:
        s = f"{s}-{hashlib.sha256(name.encode('utf-8', 'surrogatepass')).hexdigest()[:8]}"
    return s


def inside(root: Path, *parts: str) -> Path:
    """``root/part/...`` after :func:`safe_name` on each part, checked to stay inside ``root``."""
    base = root.resolve()
    p = base.joinpath(*(safe_name(x) for x in parts)).resolve()
    if p != base and base not in p.parents:
        raise FleetError(f"output path {p} would escape {base}")
    return p


# --------------------------------------------------------------------- the tasks


@dataclass(frozen=True)
class LogTask:
    """One log file of one vessel (or an input that cannot be read: ``error`` says why)."""

    vessel: str
    path: str  #: absolute
    log: str  #: as shown in tables: path relative to the vessel folder (or the file name)
    sha256: str | None  #: of the bytes; None for an input that cannot be read
    #: why the input cannot be read (a FIFO, socket or device, a dangling link, a folder
    #: where a file is expected, unreadable, a link out of its vessel folder); listed as
    #: failed without being opened or analysed
    error: str | None = None


_GLOB_CHARS = set("*?[")


def _expand(item: str) -> list[Path]:
    p = Path(item)
    if os.path.lexists(item):  # a dangling link too: listed as failed, not "no such file"
        return [p]
    if _GLOB_CHARS & set(item):
        return [Path(x) for x in sorted(glob.glob(item, recursive=True))]
    raise IngestError(f"{item}: no such file or folder")


def _names_files(pattern: str) -> bool:
    """True when the last part of ``pattern`` names files by their extension
    (``*.nmea``, ``2026-*.txt``): a folder it matches is a folder where a log was
    expected.  ``*`` and ``**`` match folders as well as files."""
    return "." in PurePath(pattern).name.strip("*")


def _task(vessel: str, path: Path, log: str) -> LogTask:
    """The task for one input: its hash, or why it cannot be read (never blocking:
    :func:`dracc.pipeline.audit.input_problem` opens nothing but a regular file)."""
    absolute = os.path.abspath(path)
    problem = input_problem(path)
    if problem is None:
        try:
            return LogTask(vessel, str(Path(path).resolve()), log, file_sha256(path))
        except IngestError as err:
            return LogTask(vessel, absolute, log, None, str(err))
    return LogTask(vessel, absolute, log, None, f"{path}: {problem}")


def discover(inputs: Iterable[str | Path], pattern: str = "**/*") -> list[LogTask]:
    """The tasks for ``inputs``: a folder is one vessel (its name), holding log files
    matching ``pattern``; a file (or a glob's files) belongs to the vessel named by its
    parent folder.  Hidden files and folders are skipped; a file listed twice counts once.

    An input that is not a regular readable file is a task with ``error`` set (listed as
    failed, never opened): a FIFO, socket or device, a dangling link, an unreadable file,
    a folder matching a pattern that names files (``*.nmea``), and, inside a vessel
    folder, a symbolic link whose target lies outside that folder (not followed)."""
    tasks: dict[str, LogTask] = {}

    def add(t: LogTask) -> None:
        tasks.setdefault(t.path, t)

    for item in inputs:
        matches = _expand(str(item))
        if not matches:
            raise IngestError(f"{item}: the pattern matches nothing")
        for m in matches:
            if m.is_dir():
                vessel = m.resolve().name
                for f in sorted(m.glob(pattern)):
                    rel = f.relative_to(m)
                    if any(x.startswith(".") for x in rel.parts):
                        continue
                    target = outside_link(f, m)
                    if target is not None:
                        add(
                            LogTask(
                                vessel,
                                os.path.abspath(f),
                                rel.as_posix(),
                                None,
                                f"{f}: symbolic link to {target}, outside the vessel folder "
                                f"{m}: not followed",
                            )
                        )
                    elif f.is_dir():
                        if _names_files(pattern):
                            add(
                                LogTask(
                                    vessel,
                                    os.path.abspath(f),
                                    rel.as_posix(),
                                    None,
                                    f"{f}: is a directory, not a log file",
                                )
                            )
                    else:
                        add(_task(vessel, f, rel.as_posix()))
            else:  # a file, or something in a file's place (FIFO, device, dangling link)
                parent = m.resolve().parent if m.exists() else Path(os.path.abspath(m)).parent
                add(_task(parent.name, m, m.name))
    if not tasks:
        raise IngestError("no log files found in the inputs")
    return sorted(tasks.values(), key=lambda t: (t.vessel, t.log, t.path))


# ------------------------------------------------------------------- the workers


def summarise(doc: Mapping) -> dict:
    """The part of an analysis document the fleet keeps (small: no samples, no epochs)."""
    facts = facts_from_analysis(doc)
    return {
        "schema": doc.get("schema"),
        "period": {"start_utc": facts.period_start_utc, "end_utc": facts.period_end_utc},
        "lines": facts.lines,
        "rejected": facts.rejected,
        "sources": facts.sources,
        "channels": [asdict(c) for c in facts.channels],
        "dr": {
            "containment_2m": facts.dr_containment_2m,
            "n_scored": facts.dr_n_scored,
            "consistent": facts.dr_consistent,
            "verdict": facts.dr_verdict,
            "nees": facts.dr_nees,
        },
        "calibration": {
            "compass_error_deg": facts.compass_error_deg,
            "compass_error_sigma_deg": facts.compass_error_sigma_deg,
            "log_scale": facts.log_scale,
            "log_scale_sigma": facts.log_scale_sigma,
        },
        "missing": list(facts.missing),
    }


def analyse_log(path: str, cfg: Config) -> dict:
    """Worker: analyse one log; ``{"ok": True, "summary": …}`` or ``{"ok": False, "error": …}``.

    Never raises for a bad log: the batch goes on.
    """
    from dracc.pipeline.audit import analysis_document

    try:
        return {"ok": True, "summary": summarise(analysis_document([Path(path)], cfg))}
    except DraccError as err:
        return {"ok": False, "error": str(err)}
    except Exception as err:  # a dracc bug on one log must not stop the fleet
        return {"ok": False, "error": f"internal error ({type(err).__name__}: {err})"}


# ------------------------------------------------------------------- the batch


@dataclass(frozen=True)
class FleetResult:
    """The fleet table, the per-day trends, and what happened to each log."""

    table: pd.DataFrame
    trends: pd.DataFrame
    failures: tuple[dict, ...]  #: {"vessel", "log", "path", "error"}
    analysed: int  #: logs analysed in this run
    cached: int  #: logs taken from the cache


def cache_path(out: Path, task: LogTask, settings: str) -> Path:
    return out / "cache" / task.sha256[:2] / f"{task.sha256}-{settings[:16]}.json"


def _read_cache(p: Path) -> dict | None:
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None  # absent or unreadable: analysed again (and rewritten)
    if doc.get("schema") != CACHE_SCHEMA or not isinstance(doc.get("summary"), dict):
        return None
    if doc.get("dracc_version") != __version__:  # another dracc may analyse differently
        return None
    return doc["summary"]


def run_fleet(
    tasks: Sequence[LogTask],
    cfg: Config,
    out: Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    connect_timeout_s: float = 30.0,
    progress: Callable[[int], None] | None = None,
    analyser: Callable[[str, Config], dict] = analyse_log,
) -> FleetResult:
    """Analyse every task (or take it from the cache) and build the fleet tables.

    ``analyser`` must be a picklable module-level function (tests replace it).
    """
    out = Path(out)
    settings = settings_sha256(cfg)
    seeds = apriori_seeds(cfg)
    summaries: dict[str, dict] = {}
    failures: dict[str, str] = {}
    todo: list[LogTask] = []
    for t in tasks:
        if t.error is not None:  # not a readable file: listed as failed, never opened
            failures[t.path] = t.error
            if progress:
                progress(1)
            continue
        s = None if force else _read_cache(cache_path(out, t, settings))
        if s is None:
            todo.append(t)
        else:
            summaries[t.path] = s
            if progress:
                progress(1)
    cached = len(summaries)

    def done(task: LogTask, result: dict) -> None:
        if result.get("ok"):
            summaries[task.path] = result["summary"]
            atomic.write_text(
                cache_path(out, task, settings),
                json.dumps(
                    {
                        "schema": CACHE_SCHEMA,
                        "dracc_version": __version__,
                        "sha256": task.sha256,
                        "settings_sha256": settings,
                        "vessel": task.vessel,
                        "log": task.log,
                        "summary": result["summary"],
                    },
                    ensure_ascii=False,
                    allow_nan=False,
                ),
            )
        else:
            failures[task.path] = str(result.get("error"))
        if progress:
            progress(1)

    if todo:
        # largest first: the last tasks to finish are short ones (less idle time at the end)
        todo.sort(key=lambda t: _size(t.path), reverse=True)
        if scheduler:
            _run_dask(todo, cfg, scheduler, connect_timeout_s, analyser, done)
        else:
            _run_local(todo, cfg, workers or os.cpu_count() or 1, analyser, done)
    table = fleet_table(tasks, summaries, failures, seeds)
    failed = tuple(
        {"vessel": t.vessel, "log": t.log, "path": t.path, "error": failures[t.path]}
        for t in tasks
        if t.path in failures
    )
    return FleetResult(table, fleet_trends(table), failed, len(todo), cached)


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0


def _preload() -> None:
    """Import the pipeline in the parent so that forked workers start with it loaded."""
    import importlib

    for name in ("dracc.pipeline.analysis", "dracc.ingest", "dracc.report.json_report"):
        try:
            importlib.import_module(name)
        except ImportError:  # pragma: no cover - the worker reports it per log
            pass


def _run_local(todo, cfg, workers, analyser, done) -> None:
    if analyser is analyse_log:
        _preload()
    with ProcessPoolExecutor(
        max_workers=max(1, min(workers, len(todo))),
        initializer=detach_worker,
        initargs=(os.getpid(),),
    ) as pool:
        pending = {pool.submit(analyser, t.path, cfg): t for t in todo}
        try:
            while pending:
                finished, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in finished:
                    task = pending.pop(fut)
                    try:
                        result = fut.result()
                    except BrokenProcessPool as err:
                        result = {"ok": False, "error": f"worker process died ({err})"}
                    done(task, result)
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def _run_dask(todo, cfg, scheduler, timeout_s, analyser, done) -> None:
    try:
        from distributed import Client, as_completed
    except ImportError as err:
        raise FleetError("--scheduler needs Dask distributed: pip install 'dracc[dask]'") from err
    try:
        client = Client(scheduler, timeout=timeout_s, set_as_default=False)
    except (OSError, TimeoutError) as err:
        raise FleetError(f"cannot reach the Dask scheduler at {scheduler}: {err}") from err
    try:
        try:
            client.wait_for_workers(1, timeout=timeout_s)
        except TimeoutError as err:
            raise FleetError(
                f"the Dask scheduler at {scheduler} has no workers (waited {timeout_s:g} s)"
            ) from err
        futures = client.map(analyser, [t.path for t in todo], cfg=cfg, pure=False)
        by_key = {f.key: t for f, t in zip(futures, todo, strict=True)}
        for fut in as_completed(futures, loop=client.loop):
            task = by_key[fut.key]
            try:
                result = fut.result()
            except Exception as err:  # a worker lost or killed: that log failed, the batch goes on
                result = {"ok": False, "error": f"dask task failed ({type(err).__name__}: {err})"}
            done(task, result)
    finally:
        client.close()


# ------------------------------------------------------------------- the tables


def _day(start: str | None, end: str | None) -> str | None:
    if not start or not end:
        return None
    t0 = pd.Timestamp(start)
    t1 = pd.Timestamp(end)
    return (t0 + (t1 - t0) / 2).date().isoformat()


def _pct(x):
    return None if x is None else 100.0 * x


def fleet_table(
    tasks: Sequence[LogTask],
    summaries: Mapping[str, dict],
    failures: Mapping[str, str],
    seeds: Mapping[tuple[str, str], float],
) -> pd.DataFrame:
    """One row per log, unit and channel, sorted by vessel, time, log, unit, channel."""
    rows: list[dict] = []
    for t in tasks:
        base = {"vessel": t.vessel, "log": t.log, "sha256": t.sha256}
        if t.path in failures:
            rows.append({**base, "status": "failed", "error": failures[t.path]})
            continue
        s = summaries.get(t.path)
        if s is None:
            continue
        per = s["period"]
        cal = s["calibration"]
        rate = (s["rejected"] / s["lines"]) if s.get("lines") else None
        common = {
            **base,
            "status": "ok",
            "error": None,
            "period_start_utc": per["start_utc"],
            "period_end_utc": per["end_utc"],
            "day": _day(per["start_utc"], per["end_utc"]),
            "dr_containment_2m": s["dr"]["containment_2m"],
            "dr_n_scored": s["dr"]["n_scored"],
            "dr_consistent": s["dr"]["consistent"],
            "dr_verdict": s["dr"].get("verdict"),
            "dr_nees": s["dr"].get("nees"),
            "compass_error_deg": cal["compass_error_deg"],
            "compass_error_sigma_deg": cal["compass_error_sigma_deg"],
            "log_scale_pct": _pct(cal["log_scale"]),
            "log_scale_sigma_pct": _pct(cal["log_scale_sigma"]),
            "rejected_rate_pct": _pct(rate),
            "lines": s.get("lines"),
        }
        if not s["channels"]:
            rows.append(common)
        for c in s["channels"]:
            rows.append(
                {
                    **common,
                    "unit": c["unit"],
                    "channel": c["channel"],
                    "measure": {"lat": "m", "lon": "m", "course": "deg"}.get(c["channel"]),
                    "n": c["n"],
                    "m_u": c["m_u"],
                    "m_y": c["m_y"],
                    "kurtosis": c["kurtosis"],
                    "limit": c["limit_error"],
                }
            )
    df = pd.DataFrame(rows, columns=list(TABLE_COLUMNS))
    df = _typed(df)
    df = df.sort_values(
        ["vessel", "period_start_utc", "log", "unit", "channel"],
        na_position="last",
        kind="mergesort",
    ).reset_index(drop=True)
    _apply_rule(df, seeds)
    return df


def _typed(df: pd.DataFrame) -> pd.DataFrame:
    floats = [
        "m_u",
        "m_y",
        "kurtosis",
        "limit",
        "apriori_before",
        "apriori_after",
        "dr_containment_2m",
        "dr_nees",
        "compass_error_deg",
        "compass_error_sigma_deg",
        "log_scale_pct",
        "log_scale_sigma_pct",
        "rejected_rate_pct",
    ]
    ints = ["n", "dr_n_scored", "lines"]
    strings = [c for c in TABLE_COLUMNS if c not in floats + ints + ["dr_consistent"]]
    for c in floats:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("float64")
    for c in ints:
        df[c] = pd.to_numeric(df[c], errors="coerce").astype("Int64")
    for c in strings:
        df[c] = df[c].astype("string")
    df["dr_consistent"] = df["dr_consistent"].astype("boolean")
    return df


def _apply_rule(df: pd.DataFrame, seeds: Mapping[tuple[str, str], float]) -> None:
    """The monitoring rule per vessel, unit and channel, log after log in time order
    (:func:`dracc.pipeline.audit.apriori_chain` on each series; one assignment per column)."""
    ok_pos = np.flatnonzero(((df["status"] == "ok") & df["unit"].notna()).to_numpy(dtype=bool))
    before = np.full(len(df), np.nan)
    after = np.full(len(df), np.nan)
    verdict = np.full(len(df), None, dtype=object)
    logs = df["log"].to_numpy(dtype=object)
    m_y = df["m_y"].to_numpy(dtype="float64")
    keys = df.iloc[ok_pos][["vessel", "unit", "channel"]]
    for (_vessel, unit, channel), pos in keys.groupby(
        ["vessel", "unit", "channel"], sort=False
    ).indices.items():
        rows = ok_pos[pos]  # in table order: time order within the vessel
        steps = apriori_chain(
            seeds.get((unit, channel)),
            [(str(logs[r]), None if np.isnan(m_y[r]) else float(m_y[r])) for r in rows],
        )
        before[rows] = [np.nan if st.before is None else st.before for st in steps]
        after[rows] = [np.nan if st.after is None else st.after for st in steps]
        verdict[rows] = [st.verdict for st in steps]
    df["apriori_before"] = before
    df["apriori_after"] = after
    df["apriori_verdict"] = pd.array(verdict, dtype="string")


def fleet_trends(table: pd.DataFrame) -> pd.DataFrame:
    """Per vessel, day, unit and channel: pooled RMS m_y (weights n), the a priori at the
    day's end, and the DR containment of the vessel's logs that day pooled over their
    scored epochs (weights ``dr_n_scored``)."""
    ok = table[(table["status"] == "ok") & table["unit"].notna() & table["day"].notna()]
    key = ["vessel", "day", "unit", "channel"]
    n = ok["n"].astype("float64")
    m_y = ok["m_y"].astype("float64")
    good = m_y.notna() & (n > 0)
    parts = ok[key + ["measure", "log", "apriori_after"]].assign(
        _n=n.where(good, 0.0), _nm2=(n * m_y**2).where(good, 0.0)
    )
    agg = (
        parts.groupby(key, sort=True)
        .agg(
            measure=("measure", "first"),
            logs=("log", "nunique"),
            n=("_n", "sum"),
            nm2=("_nm2", "sum"),
            apriori_after=("apriori_after", "last"),
        )
        .reset_index()
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        agg["m_y"] = np.where(agg["n"] > 0, np.sqrt(agg["nm2"] / agg["n"]), np.nan)  # pooled RMS
    per_log = ok.drop_duplicates(["vessel", "log", "sha256"])
    w = per_log["dr_n_scored"].astype("float64")
    c = per_log["dr_containment_2m"].astype("float64")
    okc = c.notna() & w.notna() & (w > 0)
    dr = per_log[["vessel", "day"]].assign(_w=w.where(okc, 0.0), _wc=(w * c).where(okc, 0.0))
    dr = (
        dr.groupby(["vessel", "day"], sort=True)
        .agg(w=("_w", "sum"), wc=("_wc", "sum"))
        .reset_index()
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        dr["dr_containment_2m"] = np.where(dr["w"] > 0, dr["wc"] / dr["w"], np.nan)
    df = agg.merge(dr[["vessel", "day", "dr_containment_2m"]], on=["vessel", "day"], how="left")
    df = df[list(TREND_COLUMNS)].copy()
    for col in ("vessel", "day", "unit", "channel", "measure"):
        df[col] = df[col].astype("string")
    for col in ("logs", "n"):
        df[col] = df[col].round().astype("Int64")
    for col in ("m_y", "apriori_after", "dr_containment_2m"):
        df[col] = df[col].astype("float64")
    return df.reset_index(drop=True)


def count_logs(table: pd.DataFrame) -> int:
    """The number of logs in a fleet table (a log has one row per unit and channel)."""
    return len(table.drop_duplicates(["vessel", "log", "sha256"]))


#: test hook: seconds to sleep half-way through writing the outputs (interruption tests)
TEST_SLEEP_ENV = "DRACC_FLEET_TEST_SLEEP_S"


def csv_text(df: pd.DataFrame) -> str:
    """``df`` as CSV for a spreadsheet: a text cell starting with ``=``, ``+``, ``-``,
    ``@``, a tab or a CR (a vessel or file name, an error message) gets a leading single
    quote, so that no cell is read as a formula (:func:`dracc.core.safetext.csv_cell`).
    Numbers are left alone (-0.5 stays a number); Parquet keeps the raw text."""
    from dracc.core.safetext import csv_cell

    safe = df.copy()
    for col in safe.columns:
        if not (pd.api.types.is_string_dtype(safe[col]) or safe[col].dtype == object):
            continue
        safe[col] = safe[col].map(csv_cell, na_action="ignore")
    return safe.to_csv(index=False)


def write_tables(
    result: FleetResult,
    out: Path,
    extra: Mapping[str, str] | None = None,
    published: list | None = None,
) -> list[Path]:
    """fleet.parquet/.csv, trends.parquet/.csv, failures in fleet.json, per vessel
    ``vessels/<safe name>/fleet.csv`` and ``trends.csv``, and the ``extra`` files
    (name -> text, e.g. ``fleet.html``), published together (:func:`dracc.core.atomic.file_set`):
    a reader, an interrupt or a kill at any moment finds the previous complete set in
    ``out`` or the new complete set, never a mix (``published``: see
    :func:`~dracc.core.atomic.file_set`).  Returns the paths of the outputs."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rels: list[Path] = []
    sleep_s = os.environ.get(TEST_SLEEP_ENV)
    with atomic.file_set(out, published) as stage:

        def put(rel: Path, data: str | pd.DataFrame) -> None:
            path = inside(stage, *rel.parts)
            path.parent.mkdir(parents=True, exist_ok=True)
            if isinstance(data, str):
                path.write_text(data, encoding="utf-8")
            elif path.suffix == ".parquet":
                data.to_parquet(path, index=False)
            else:
                path.write_text(csv_text(data), encoding="utf-8")
            rels.append(path.relative_to(stage.resolve()))

        for name, df in (("fleet", result.table), ("trends", result.trends)):
            put(Path(f"{name}.parquet"), df)
            put(Path(f"{name}.csv"), df)
        if sleep_s:  # test hook: a run interrupted here must leave the old set whole
            print(
                f"dracc fleet: test hook: sleeping {sleep_s} s while writing the outputs",
                file=sys.stderr,
                flush=True,
            )
            time.sleep(float(sleep_s))
        for vessel in sorted(result.table["vessel"].dropna().unique()):
            put(
                Path("vessels", vessel, "fleet.csv"), result.table[result.table["vessel"] == vessel]
            )
            put(
                Path("vessels", vessel, "trends.csv"),
                result.trends[result.trends["vessel"] == vessel],
            )
        summary = {
            "schema": "dracc.fleet/1",
            "dracc_version": __version__,
            "logs": count_logs(result.table),
            "vessels": sorted(result.table["vessel"].dropna().unique().tolist()),
            "analysed": result.analysed,
            "cached": result.cached,
            "failures": list(result.failures),
        }
        put(Path("fleet.json"), json.dumps(summary, indent=1, ensure_ascii=False) + "\n")
        for name, text in (extra or {}).items():
            put(Path(name), text)
    root = out.resolve()
    return [root / r for r in rels]


__all__ = [
    "CHANNELS",
    "FleetConfig",
    "FleetError",
    "FleetResult",
    "LogTask",
    "analyse_log",
    "count_logs",
    "discover",
    "fleet_config",
    "fleet_table",
    "fleet_trends",
    "inside",
    "run_fleet",
    "safe_name",
    "summarise",
    "write_tables",
    "csv_text",
]
