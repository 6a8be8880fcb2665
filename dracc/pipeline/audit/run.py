"""Running the nightly audit: analyse, check, record the night and the a priori chain.

:func:`run_audit` is the whole ``dracc audit`` run; :func:`audit_night` checks one
night's facts and records them in the state (:mod:`dracc.pipeline.state`) in one
transaction, recomputing the vessel's a priori chain (:mod:`dracc.pipeline.audit.rule`)
over every stored night, so a night audited late or re-audited keeps the chain exact.
The :class:`AuditOutcome` carries the typed analysis up to the reports.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import os
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

from dracc.core.config import Config, DeviationConfig
from dracc.core.errors import ConfigError, ExitCode, NoLogsError, StateError
from dracc.core.numbers import jsonable
from dracc.core.vocabulary import CHANNEL_KEYS
from dracc.pipeline.audit.accuracy import accuracy_findings, period_hours
from dracc.pipeline.audit.facts import NightFacts, facts_from_analysis, night_of
from dracc.pipeline.audit.findings import (
    DR_FALSE_ALARM,
    Finding,
    evaluate,
    make_finding,
    not_checked,
)
from dracc.pipeline.audit.limits import (
    AuditConfig,
    apriori_seeds,
    audit_config,
    settings_sha256,
    vessel_name,
)
from dracc.pipeline.audit.logs import (
    choose_logs,
    content_sha256,
    parse_night,
    yesterday_utc,
)
from dracc.pipeline.audit.rule import apriori_chain
from dracc.pipeline.audit.sensor_checks import sensor_checks_made
from dracc.pipeline.state import AprioriEvent, NightRecord, StateStore

if TYPE_CHECKING:
    from dracc.pipeline.results import Analysis

#: test hook: seconds to sleep inside the recording transaction (simulates a slow or killed run)
TEST_SLEEP_ENV = "DRACC_AUDIT_TEST_SLEEP_S"


@dataclass(frozen=True)
class AuditOutcome:
    """The result of auditing one night."""

    record: NightRecord  #: as stored (with the a priori verdicts of this night)
    findings: tuple[Finding, ...]
    not_checked: tuple[dict, ...]  #: {check, name, source, role, why}
    status: str  #: 'recorded' (new night), 'unchanged' (same content: nothing written), 'replaced'
    apriori_events: tuple[AprioriEvent, ...]  #: established or raised on this night
    accuracy: Mapping = field(default_factory=dict)  #: the accuracy window (JSON-ready)
    false_alarm_per_night: float | None = None  #: bound for the statistical checks made
    no_data: bool = False  #: no logs for the night: recorded as a night without data
    ignored: Mapping[str, int] = field(default_factory=dict)  #: valid unused input, by type
    #: the analysis the night's checks rest on (for the reports); None without logs
    analysis: Analysis | None = field(default=None, compare=False, repr=False)

    @property
    def verdict(self) -> str:
        """'no data', 'findings' or 'ok'."""
        return "no data" if self.no_data else ("findings" if self.findings else "ok")

    @property
    def exit_code(self) -> ExitCode:
        if self.no_data:
            return ExitCode.INPUT
        return ExitCode.FINDINGS if self.findings else ExitCode.OK


def audit_night(
    facts: NightFacts,
    *,
    store: StateStore,
    acfg: AuditConfig,
    seeds: Mapping[tuple[str, str], float],
    vessel: str,
    night: str | None,
    content_hash: str,
    settings_hash: str,
    now: Callable[[], dt.datetime] | None = None,
    dev_cfg: DeviationConfig | None = None,
) -> AuditOutcome:
    """Audit one night given the facts of its analysis, and record it in ``store``.

    Idempotent on (vessel, night, content hash, settings hash): the same night with the
    same content is recorded once (``status='unchanged'``, nothing written); a night
    whose content changed replaces the stored one in the same transaction
    (``'replaced'``).  The a priori chain of the vessel is recomputed in that transaction.
    """
    dev_cfg = dev_cfg or DeviationConfig()
    night = night or night_of(facts)
    findings, skipped = evaluate(facts, acfg)
    clock = now or (lambda: dt.datetime.now(dt.timezone.utc))
    # the hours tonight adds to the accuracy window: as a stored night is counted (its
    # period), from the period where the analysis gives no duration
    hours = (
        facts.duration_s / 3600.0
        if facts.duration_s is not None
        else period_hours(facts.period_start_utc, facts.period_end_utc)
    )
    with store.transaction():
        acc_found, acc_skipped, acc_doc = accuracy_findings(
            store, vessel, night, acfg, dev_cfg, tonight=(hours, facts.channels)
        )
        findings += acc_found
        skipped += acc_skipped
        record = _record(vessel, night, content_hash, settings_hash, clock, facts, findings)
        status = _store_night(store, record, seeds)
        stored = store.night(vessel, night)
        events = tuple(e for e in store.apriori_events(vessel) if e.night == night)
    assert stored is not None
    extra = []
    if acfg.apriori_raise_is_finding:
        for e in events:
            if e.reason == "raised":
                measure = CHANNEL_KEYS[e.channel].rsplit("_", 1)[1]
                extra.append(
                    make_finding(
                        "accuracy",
                        "apriori_raised",
                        f"{e.unit} {e.channel}",
                        e.value,
                        e.previous,
                        measure,
                        f"{e.unit} {e.channel}: a priori RMS raised "
                        f"from {e.previous:.4g} to {e.value:.4g} {measure}",
                        role=e.unit,
                        rule="[audit] apriori_raise_is_finding",
                    )
                )
    fa = [f for f in (facts.integrity_false_alarm,) if f is not None]
    if facts.dr_verdict in ("consistent", "conservative", "inconsistent"):
        fa.append(DR_FALSE_ALARM)
    fa += [acfg.false_alarm] * sensor_checks_made(facts, acfg)  # compass, log (issue 29)
    return AuditOutcome(
        stored,
        findings + tuple(extra),
        skipped,
        status,
        events,
        acc_doc,
        min(1.0, sum(fa)) if fa else None,
        ignored=dict(facts.ignored),
    )


def _record(
    vessel, night, content_hash, settings_hash, clock, facts: NightFacts, findings
) -> NightRecord:
    return NightRecord(
        vessel=vessel,
        night=night,
        content_sha256=content_hash,
        settings_sha256=settings_hash,
        audited_utc=clock().strftime("%Y-%m-%dT%H:%M:%SZ"),
        period_start_utc=facts.period_start_utc,
        period_end_utc=facts.period_end_utc,
        inputs=facts.inputs,
        sources=facts.sources,
        lines=facts.lines,
        rejected=facts.rejected,
        rejected_rate=facts.rejected_rate,
        dr_containment_2m=facts.dr_containment_2m,
        dr_n_scored=facts.dr_n_scored,
        compass_error_deg=facts.compass_error_deg,
        compass_error_sigma_deg=facts.compass_error_sigma_deg,
        log_scale=facts.log_scale,
        log_scale_sigma=facts.log_scale_sigma,
        findings=tuple(_finding_dict(f) for f in findings),
        missing=facts.missing,
        channels=facts.channels,
        dr_verdict=facts.dr_verdict,
        dr_verdict_text=facts.dr_verdict_text,
        dr_consistent=facts.dr_consistent,
        dr_nees=facts.dr_nees,
        measures=dict(facts.measures) if facts.measures else None,
    )


def _finding_dict(f: Finding) -> dict:
    return jsonable(asdict(f))


def _store_night(store: StateStore, record: NightRecord, seeds) -> str:
    """Insert or replace ``record`` (inside the caller's transaction): its status word."""
    old = store.night(record.vessel, record.night)
    if (
        old is not None
        and old.content_sha256 == record.content_sha256
        and old.settings_sha256 == record.settings_sha256
    ):
        return "unchanged"
    store.delete_night(record.vessel, record.night)
    store.insert_night(record)
    _recompute_chain(store, record.vessel, seeds)
    sleep_s = os.environ.get(TEST_SLEEP_ENV)
    if sleep_s:  # test hook: a run killed here must leave no partial night
        print(
            f"dracc audit: test hook: sleeping {sleep_s} s inside the transaction",
            file=sys.stderr,
            flush=True,
        )
        time.sleep(float(sleep_s))
    return "replaced" if old is not None else "recorded"


#: the content hash of a night recorded without logs
NO_DATA_SHA256 = hashlib.sha256(b"dracc: no logs for this night").hexdigest()


def record_no_data(
    store: StateStore,
    *,
    vessel: str,
    night: str,
    why: str,
    settings_hash: str,
    seeds: Mapping[tuple[str, str], float],
    now: Callable[[], dt.datetime] | None = None,
) -> AuditOutcome:
    """Record ``night`` as a night without data (no logs were found): its one finding is
    the absence, so ``audit history`` shows the gap.  A night already audited with logs
    is left as it is (its logs may have been moved away since)."""
    clock = now or (lambda: dt.datetime.now(dt.timezone.utc))
    f = make_finding(
        "availability",
        "no_logs",
        "logs",
        None,
        None,
        "",
        why,
        rule="logs for the night in the folder, matching the pattern",
        false_alarm=0.0,
    )
    with store.transaction():
        old = store.night(vessel, night)
        if old is not None and old.content_sha256 != NO_DATA_SHA256:
            record, status = old, "unchanged"
        else:
            record = NightRecord(
                vessel=vessel,
                night=night,
                content_sha256=NO_DATA_SHA256,
                settings_sha256=settings_hash,
                audited_utc=clock().strftime("%Y-%m-%dT%H:%M:%SZ"),
                period_start_utc=None,
                period_end_utc=None,
                inputs=(),
                sources={},
                lines=0,
                rejected=0,
                rejected_rate=None,
                dr_containment_2m=None,
                dr_n_scored=None,
                compass_error_deg=None,
                compass_error_sigma_deg=None,
                log_scale=None,
                log_scale_sigma=None,
                findings=(_finding_dict(f),),
                missing=(why,),
                channels=(),
            )
            status = _store_night(store, record, seeds)
            record = store.night(vessel, night) or record
    return AuditOutcome(record, (f,), (), status, (), no_data=True)


def _recompute_chain(
    store: StateStore, vessel: str, seeds: Mapping[tuple[str, str], float]
) -> None:
    """Re-apply the monitoring rule over every stored night of ``vessel`` (in the transaction)."""
    series: dict[tuple[str, str], list[tuple[str, float | None]]] = {}
    for rec in store.nights(vessel):
        for c in rec.channels:
            series.setdefault((c.unit, c.channel), []).append((rec.night, c.m_y))
    events = []
    for (unit, channel), nights in sorted(series.items()):
        rec_by_night = dict(nights)
        for step in apriori_chain(seeds.get((unit, channel)), nights):
            store.set_channel_apriori(
                vessel, step.night, unit, channel, step.before, step.after, step.verdict
            )
            if step.verdict in ("established", "raised"):
                stored = store.night(vessel, step.night)
                assert stored is not None  # the chain runs over stored nights
                row = next(c for c in stored.channels if c.unit == unit and c.channel == channel)
                events.append(
                    AprioriEvent(
                        vessel,
                        unit,
                        channel,
                        step.night,
                        float(step.after),  # type: ignore[arg-type]  # established/raised set it
                        step.before,
                        step.verdict,
                        {
                            "night": step.night,
                            "m_y": rec_by_night[step.night],
                            "m_u": row.m_u,
                            "n": row.n,
                            "kurtosis": row.kurtosis,
                            "limit": row.limit_error,
                            "previous": step.before,
                            "seed": "config" if (unit, channel) in seeds else None,
                        },
                    )
                )
    store.replace_apriori_events(vessel, events)


def open_state(cfg: Config, db: str | Path | None = None) -> StateStore:
    """The existing audit database (``db``, else ``[audit] db``) to read: ConfigError
    without a path, StateError where no audit has written one yet."""
    acfg = audit_config(cfg)
    path = db or (Path(acfg.db) if acfg.db else None)
    if path is None:
        raise ConfigError('no audit database: give --db PATH or [audit] db = "PATH"')
    if not Path(path).is_file():
        raise StateError(f"{path}: no audit database here (run 'dracc audit' first)")
    return StateStore(path, busy_timeout_s=acfg.busy_timeout_s)


def analyse_voyage(
    paths: Sequence[Path], cfg: Config, progress: Callable[[str, float], None] | None = None
) -> Analysis:
    """Run the pipeline (:func:`dracc.pipeline.analysis.analyse`) over one voyage's logs."""
    from dracc.pipeline import analysis as pipeline

    return pipeline.analyse([Path(p) for p in paths], cfg, progress=progress)


def run_audit(
    inputs: Sequence[Path],
    cfg: Config,
    *,
    db: str | Path | None = None,
    vessel: str | None = None,
    night: str | None = None,
    pattern: str | None = None,
    progress: Callable[[str, float], None] | None = None,
    now: dt.datetime | None = None,
) -> AuditOutcome:
    """The whole nightly audit: choose the logs, analyse them, check, record.

    The outcome carries the analysis for the reports (``outcome.analysis``; None for a
    night without logs: a folder holding no log for the night is recorded as a night
    without data, ``outcome.no_data``, exit 3).  Raises IngestError/InsufficientDataError (exit 3)
    for given files that hold no usable logs and ConfigError (exit 4) for a bad ``[audit]``
    section or no database path.  Without ``night`` and with a folder among the inputs,
    the night is yesterday (UTC): cron runs the audit after midnight.
    """
    acfg = audit_config(cfg)
    seeds = apriori_seeds(cfg)
    db_path = db or acfg.db
    if not db_path:
        raise ConfigError('no audit database: give --db PATH or [audit] db = "PATH"')
    has_dir = any(Path(p).is_dir() for p in inputs)
    if night is not None:
        night = parse_night(night)
    elif has_dir:
        night = yesterday_utc(now)
    name = vessel_name(cfg, acfg, vessel)
    try:
        choice = choose_logs(inputs, night, pattern or acfg.pattern)
    except NoLogsError as e:
        if night is None:
            raise
        with StateStore(db_path, busy_timeout_s=acfg.busy_timeout_s) as store:
            outcome = record_no_data(
                store,
                vessel=name,
                night=night,
                why=str(e),
                settings_hash=settings_sha256(cfg),
                seeds=seeds,
            )
        return outcome
    paths = list(choice.paths)
    content_hash = content_sha256(paths)
    analysis = analyse_voyage(paths, cfg, progress=progress)
    with StateStore(db_path, busy_timeout_s=acfg.busy_timeout_s) as store:
        outcome = audit_night(
            facts_from_analysis(analysis),
            store=store,
            acfg=acfg,
            seeds=seeds,
            vessel=name,
            night=night,
            content_hash=content_hash,
            settings_hash=settings_sha256(cfg),
            dev_cfg=cfg.deviation,
        )
    # files of the folder not read: said in the summary and the JSON
    skipped = tuple(not_checked("logs", str(f), why) for f, why in choice.skipped)
    return replace(outcome, not_checked=outcome.not_checked + skipped, analysis=analysis)
