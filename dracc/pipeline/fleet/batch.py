"""Running the fleet batch: every log analysed on a local pool or on Dask, cached.

Workers run :func:`analyse_log` (the pipeline) on each log file and send back
:func:`summarise`: a small JSON-ready summary of the analysis (no samples, no DR
epochs), with the night's findings and integrity counts
(:mod:`dracc.pipeline.fleet.findings`).  The parent caches every summary under
``OUT/cache/`` keyed by the SHA-256 of the log's bytes and of the settings
(:func:`fleet_settings_sha256`; ``dracc.fleet.cache/4``, written atomically; entries
written by another dracc version are analysed again), so a re-run
skips what was done unless ``force``; a failing log becomes a row with
``status='failed'`` and an entry in ``failures``, never the end of the batch.  A file
that is no log at all (:func:`dracc.ingest.not_a_log`: a README, a photo, an archive)
is not analysed: it is listed in ``skipped`` with what it is, and counted apart, so
that ``analysed + cached + documents + failed = logs``.

Engines: a local :class:`concurrent.futures.ProcessPoolExecutor` (``workers``), or an
existing Dask distributed scheduler (``scheduler='tcp://host:port'``, through
:class:`distributed.Client`), both in :mod:`dracc.pipeline.fleet.engines` (small logs of
one folder several to a task).  The workers must see the log paths (a shared disk).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING

from dracc import __version__
from dracc.core import atomic
from dracc.core.config import Config
from dracc.core.errors import DraccError
from dracc.core.numbers import jsonable
from dracc.ingest import not_a_log
from dracc.pipeline.audit.facts import facts_from_analysis
from dracc.pipeline.audit.findings import evaluate
from dracc.pipeline.audit.limits import AuditConfig, apriori_seeds, audit_config, settings_sha256
from dracc.pipeline.audit.run import analyse_voyage
from dracc.pipeline.fleet.documents import expand_documents
from dracc.pipeline.fleet.engines import run_dask as _run_dask
from dracc.pipeline.fleet.engines import run_local as _run_local
from dracc.pipeline.fleet.findings import (
    findings_table,
    integrity_counts,
    integrity_table,
    night_findings,
)
from dracc.pipeline.fleet.ranking import measures_frame, rank_fleet, ranking_config
from dracc.pipeline.fleet.tables import (
    FleetResult,
    drop_duplicate_nights,
    fleet_table,
    fleet_trends,
    night_of_summary,
)
from dracc.pipeline.fleet.tasks import LogTask

if TYPE_CHECKING:
    from dracc.pipeline.results import Analysis

#: /2: the summary's "dr" carries the verdict word and the NEES statistic; /3: the
#: ranking's "measures"; /4: the night's "findings" and "integrity" counts (an older
#: entry is analysed again)
CACHE_SCHEMA = "dracc.fleet.cache/4"


def summarise(analysis: Analysis, acfg: AuditConfig | None = None) -> dict:
    """The part of an analysis the fleet keeps and caches (small: no samples, no epochs),
    with the night's findings as the audit would make them under ``acfg`` (``[audit]``;
    default: its defaults) and the counts of the analysis' integrity checks
    (:mod:`dracc.pipeline.fleet.findings`)."""
    facts = facts_from_analysis(analysis)
    found, not_checked = evaluate(facts, acfg or AuditConfig())
    return {
        "schema": analysis.schema,
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
        "measures": dict(facts.measures),
        "findings": night_findings([jsonable(asdict(f)) for f in found], not_checked),
        "integrity": None if analysis.integrity is None else integrity_counts(analysis.integrity),
    }


def analyse_log(path: str, cfg: Config) -> dict:
    """Worker: analyse one log; ``{"ok": True, "summary": …}``, ``{"ok": False, "error": …}``,
    or ``{"ok": False, "skipped": what it is}`` for a file that is no log at all
    (:func:`dracc.ingest.not_a_log`: a README, a photo), which is not analysed.

    Never raises for a bad log: the batch goes on.
    """
    try:
        what = not_a_log(path)
        if what is not None:
            return {"ok": False, "skipped": what}
        acfg = audit_config(cfg)  # before the analysis: a bad [audit] fails at once
        return {"ok": True, "summary": summarise(analyse_voyage([Path(path)], cfg), acfg)}
    except DraccError as err:
        return {"ok": False, "error": str(err)}
    except Exception as err:  # a dracc bug on one log must not stop the fleet
        return {"ok": False, "error": f"internal error ({type(err).__name__}: {err})"}


def fleet_settings_sha256(cfg: Config) -> str:
    """SHA-256 of the settings a cached summary depends on: those of the analysis
    (:func:`dracc.pipeline.audit.settings_sha256`), the integrity checks and the sensor
    faults, and the ``[audit]`` limits its findings are judged by (ConfigError for a bad
    ``[audit]``: the run stops before any log)."""
    doc = {
        "analysis": settings_sha256(cfg),
        "integrity": asdict(cfg.integrity),
        "faults": asdict(cfg.faults),
        "audit": asdict(audit_config(cfg)),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def cache_path(out: Path, task: LogTask, settings: str) -> Path:
    """Where the summary of ``task`` under ``settings`` (their SHA-256) is cached."""
    sha = str(task.sha256)  # only readable logs (hashed) are analysed and cached
    return out / "cache" / sha[:2] / f"{sha}-{settings[:16]}.json"


def check_own_folders(out: Path) -> None:
    """``OUT/cache`` (and its folders) and ``OUT/.runs`` are dracc's own: a symbolic link
    planted there would have summaries read from and written to elsewhere, or old sets
    removed there; it is an OutputError before any log is read, never followed (issue 33).
    Those not made yet are made by their first write."""
    for name in ("cache", atomic.RUNS):
        if os.path.lexists(out / name):
            atomic.own_folder(out / name)
    if os.path.isdir(out / "cache"):
        for entry in os.scandir(out / "cache"):
            if entry.is_symlink():
                atomic.own_folder(entry.path)  # says what it is and where it leads


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
    check_own_folders(out)
    settings = fleet_settings_sha256(cfg)
    seeds = apriori_seeds(cfg)
    rc = ranking_config(cfg)
    # audit documents and databases: their nights are read, not analysed
    n_inputs = len(tasks)
    tasks, summaries, failures = expand_documents(tasks)
    documents = frozenset(summaries)  # the nights read from documents
    n_documents = n_inputs - sum(1 for t in tasks if t.path not in summaries)
    if progress and n_documents:
        progress(n_documents)
    todo: list[LogTask] = []
    skipped: dict[str, str] = {}  # path -> what the file is: no log, not analysed, listed
    from_cache: set[str] = set()
    for t in tasks:
        if t.path in summaries:
            continue
        if t.path in failures:  # a document that cannot be read
            if progress:
                progress(1)
            continue
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
            from_cache.add(t.path)
            if progress:
                progress(1)

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
        elif result.get("skipped"):  # no log at all: listed apart, not failed
            skipped[task.path] = str(result["skipped"])
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
    # a night given twice (its log and its document, a document twice) is shown once
    tasks, duplicates = drop_duplicate_nights(tasks, summaries, documents)
    kept = {t.path for t in tasks if t.path in summaries}
    from_documents = len(kept & documents)
    cached = len(kept & from_cache)
    analysed = len(kept) - from_documents - cached  # this run's, that succeeded
    table = fleet_table(tasks, summaries, failures, seeds)
    ranking = rank_fleet(
        measures_frame(
            [
                (t.vessel, night, summaries[t.path].get("measures") or {})
                for t in tasks
                if t.path in summaries and (night := night_of_summary(summaries[t.path]))
            ]
        ),
        rc,
    )
    failed = tuple(
        {"vessel": t.vessel, "log": t.log, "path": t.path, "error": failures[t.path]}
        for t in tasks
        if t.path in failures
    )
    passed = tuple(
        {"vessel": t.vessel, "log": t.log, "path": t.path, "why": skipped[t.path]}
        for t in tasks
        if t.path in skipped
    )
    return FleetResult(
        table,
        fleet_trends(table),
        failed,
        analysed,
        cached,
        ranking,
        skipped=passed,
        documents=from_documents,
        duplicates=duplicates,
        findings=findings_table(tasks, summaries),
        integrity=integrity_table(tasks, summaries),
    )


def _size(path: str) -> int:
    try:
        return os.path.getsize(path)
    except OSError:
        return 0
