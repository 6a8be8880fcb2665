"""The nightly shipboard audit: thresholds, the a priori rule, findings.

``dracc audit`` runs after midnight over the last day's logs, analyses them with
:func:`dracc.pipeline.analysis.analyse`, checks the results against the limits in the
``[audit]`` section of the configuration and keeps the state between nights in SQLite
(:mod:`dracc.pipeline.state`).

The monitoring rule (INS-deviation paper, conclusions)
------------------------------------------------------
"Monitor systematically the RMS values of coordinates and the course using the
deviations of the NP from the average values and compare them with the a priori values
of the RMS.  As a result, the larger value becomes a new a priori one.  In the absence
of a priori values of the RMS, their definition by deviation becomes mandatory."
Night after night, per unit and channel::

    a_0     = a priori from the configuration ([deviation.apriori]), or none
    a_{k+1} = max(a_k, m_y,k)        m_y,k = k_ch * m_u,k   (K3b), (K5b)
    a_1     = m_y,0                  when there is no a_0 ("established")

The chain is recomputed over all stored nights of the vessel inside the transaction
that records a night, so a night audited late or re-audited keeps the chain exact.

Analysis documents
------------------
Audit and fleet consume the analysis as its JSON-ready dict (schema
``dracc.analysis/1``, keys fixed by issue 5): small, picklable, what fleet workers send
back.  :func:`facts_from_analysis` is the one place that reads it.
"""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import math
import os
import stat
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from dracc.core.config import Config
from dracc.core.errors import ConfigError, ExitCode, IngestError, InsufficientDataError, NoLogsError
from dracc.core.numbers import finite_or_none, jsonable
from dracc.core.timefmt import parse_utc
from dracc.core.vocabulary import CHANNEL_KEYS, CHANNELS, INS_ROLES, ROLES
from dracc.pipeline.state import AprioriEvent, ChannelRow, NightRecord, StateStore

UNITS = INS_ROLES
KEY_CHANNELS = {v: k for k, v in CHANNEL_KEYS.items()}

#: test hook: seconds to sleep inside the recording transaction (simulates a slow or killed run)
TEST_SLEEP_ENV = "DRACC_AUDIT_TEST_SLEEP_S"


# ------------------------------------------------------------------------ config


@dataclass(frozen=True)
class AuditConfig:
    """The ``[audit]`` table.  Percentages carry ``_pct``; limits use the channel's unit."""

    db: str | None = None  #: SQLite state file; required (here or --db)
    vessel: str | None = None  #: vessel name in the state (else [vessel] name, else "default")
    pattern: str = "*"  #: glob for the log files inside a folder (e.g. "**/*.nmea")
    busy_timeout_s: float = 60.0  #: how long to wait for another audit holding the database
    #: limiting error (K8) per unit and channel; "all" applies to every unit
    limits: Mapping[str, Mapping[str, float]] = field(
        default_factory=lambda: {"all": {"lat_m": 1852.0, "lon_m": 1852.0, "course_deg": 0.75}}
    )
    dr_containment_min: float = 0.90  #: fraction of DR epochs with the reference inside 2M
    compass_error_max_deg: float = 1.0  #: |compass error| estimated against the reference
    log_scale_max_pct: float = 2.0  #: |log scale error|, % of speed (IMO: 2 %)
    rejected_rate_max_pct: float = 1.0  #: rejected lines, % of all lines
    required_sources: tuple[str, ...] = UNITS  #: roles that must be present in the logs
    apriori_raise_is_finding: bool = False  #: a raised a priori value is a finding (exit 1)
    #: the limiting errors are judged over the nights of at least this many hours (seed 001
    #: asks 72 h for a kurtosis that means something): a short night cannot raise a limit
    accuracy_window_h: float = 72.0

    def limit_for(self, unit: str, channel: str) -> float | None:
        key = CHANNEL_KEYS[channel]
        own = self.limits.get(unit, {})
        if key in own:
            return float(own[key])
        value = self.limits.get("all", {}).get(key)
        return None if value is None else float(value)


def _number(value, where: str, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"[{where}] must be a number, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or (positive and v <= 0):
        raise ConfigError(f"[{where}] must be a positive number, got {value!r}")
    return v


def _unknown(table: Mapping, known: Iterable[str], where: str) -> None:
    unknown = set(table) - set(known)
    if unknown:
        raise ConfigError(
            f"[{where}] unknown key(s): {', '.join(sorted(map(str, unknown)))}; "
            f"known: {', '.join(sorted(known))}"
        )


def audit_config(cfg: Config) -> AuditConfig:
    """Validate ``cfg.extra['audit']`` into an :class:`AuditConfig` (ConfigError on any doubt)."""
    table = cfg.extra.get("audit", {})
    if not isinstance(table, dict):
        raise ConfigError(f"[audit] must be a table, got {type(table).__name__}")
    default = AuditConfig()
    known = [f for f in asdict(default)]
    _unknown(table, known, "audit")
    kw: dict = {}
    for key in ("db", "vessel", "pattern"):
        if key in table:
            if not isinstance(table[key], str) or not table[key].strip():
                raise ConfigError(f"[audit] {key} must be a non-empty string, got {table[key]!r}")
            kw[key] = table[key]
    if "pattern" in kw and (Path(kw["pattern"]).is_absolute() or Path(kw["pattern"]).drive):
        raise ConfigError(
            f"[audit] pattern must be a glob relative to the log folder "
            f'(e.g. "*.nmea" or "**/*.nmea"), got {kw["pattern"]!r}'
        )
    for key in (
        "busy_timeout_s",
        "compass_error_max_deg",
        "log_scale_max_pct",
        "rejected_rate_max_pct",
        "accuracy_window_h",
    ):
        if key in table:
            kw[key] = _number(table[key], f"audit.{key}")
    if "dr_containment_min" in table:
        v = _number(table["dr_containment_min"], "audit.dr_containment_min")
        if v > 1:
            raise ConfigError(f"[audit.dr_containment_min] is a fraction in (0, 1], got {v}")
        kw["dr_containment_min"] = v
    if "apriori_raise_is_finding" in table:
        if not isinstance(table["apriori_raise_is_finding"], bool):
            raise ConfigError("[audit.apriori_raise_is_finding] must be true or false")
        kw["apriori_raise_is_finding"] = table["apriori_raise_is_finding"]
    if "required_sources" in table:
        req = table["required_sources"]
        if not isinstance(req, list) or any(r not in ROLES for r in req):
            raise ConfigError(
                f"[audit.required_sources] must be a list of roles "
                f"({', '.join(ROLES)}), got {req!r}"
            )
        kw["required_sources"] = tuple(req)
    if "limits" in table:
        lim = table["limits"]
        if not isinstance(lim, dict):
            raise ConfigError(
                '[audit.limits] must be a table: unit or "all" -> { lat_m, lon_m, course_deg }'
            )
        _unknown(lim, ("all",) + UNITS, "audit.limits")
        merged = {k: dict(v) for k, v in default.limits.items()}
        for unit, values in lim.items():
            if not isinstance(values, dict):
                raise ConfigError(
                    f"[audit.limits.{unit}] must be a table {{ lat_m, lon_m, course_deg }}"
                )
            _unknown(values, CHANNEL_KEYS.values(), f"audit.limits.{unit}")
            merged.setdefault(unit, {}).update(
                {k: _number(v, f"audit.limits.{unit}.{k}") for k, v in values.items()}
            )
        kw["limits"] = merged
    return AuditConfig(**kw)


def apriori_seeds(cfg: Config) -> dict[tuple[str, str], float]:
    """The configured a priori RMS per (unit, channel) from ``[deviation.apriori]``."""
    seeds: dict[tuple[str, str], float] = {}
    for unit, values in cfg.deviation.apriori.items():
        if unit not in UNITS or not isinstance(values, dict):
            raise ConfigError(
                f"[deviation.apriori] {unit!r}: expected one of {', '.join(UNITS)} "
                "= { lat_m, lon_m, course_deg }"
            )
        _unknown(values, CHANNEL_KEYS.values(), f"deviation.apriori.{unit}")
        for key, v in values.items():
            seeds[(unit, KEY_CHANNELS[key])] = _number(v, f"deviation.apriori.{unit}.{key}")
    return seeds


def settings_sha256(cfg: Config) -> str:
    """SHA-256 of the settings that shape an analysis (ingest, dead reckoning, deviation)."""
    doc = {
        "ingest": asdict(cfg.ingest),
        "dead_reckoning": asdict(cfg.dead_reckoning),
        "deviation": asdict(cfg.deviation),
    }
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


# ------------------------------------------------------------------ the a priori rule


@dataclass(frozen=True)
class RuleStep:
    """The monitoring rule applied to one night: ``after = max(before, m_y)``."""

    night: str
    m_y: float | None
    before: float | None
    after: float | None
    verdict: str  #: 'established', 'within', 'raised' or 'no data'


def apriori_chain(seed: float | None, nights: Sequence[tuple[str, float | None]]) -> list[RuleStep]:
    """Apply the monitoring rule night after night (paper's conclusions).

    ``nights``: (night, m_y) in time order; ``m_y`` None or NaN where the night gave no
    estimate (the a priori value then carries over unchanged).
    """
    steps = []
    current = seed
    for night, m_y in nights:
        if m_y is None or not math.isfinite(m_y):
            steps.append(RuleStep(night, None, current, current, "no data"))
            continue
        if current is None:
            steps.append(RuleStep(night, m_y, None, m_y, "established"))  # mandatory by deviation
            current = m_y
        elif m_y > current:
            steps.append(
                RuleStep(night, m_y, current, m_y, "raised")
            )  # the larger becomes a priori
            current = m_y
        else:
            steps.append(RuleStep(night, m_y, current, current, "within"))
    return steps


# --------------------------------------------------------------------- the analysis


def _estimate(x) -> tuple[float | None, float | None]:
    """(value, sigma) from ``{"value": …, "sigma": …}`` or a bare number."""
    if isinstance(x, Mapping):
        return finite_or_none(x.get("value")), finite_or_none(x.get("sigma"))
    return finite_or_none(x), None


@dataclass(frozen=True)
class NightFacts:
    """What the audit reads from one analysis document."""

    period_start_utc: str | None
    period_end_utc: str | None
    inputs: tuple[str, ...]
    lines: int | None
    rejected: int | None
    rejected_rate: float | None  #: fraction
    sources: dict[str, str]  #: role -> source key
    channels: tuple[ChannelRow, ...]
    dr_containment_2m: float | None
    dr_n_scored: int | None
    compass_error_deg: float | None
    compass_error_sigma_deg: float | None
    log_scale: float | None  #: fraction of speed
    log_scale_sigma: float | None
    missing: tuple[str, ...]
    #: the analysis' DR verdict word: 'consistent', 'conservative', 'inconsistent',
    #: 'undetermined', or None (no DR section, or a document without a verdict)
    dr_verdict: str | None = None
    dr_verdict_text: str | None = None  #: the verdict sentence as the analysis wrote it
    dr_consistent: bool | None = None  #: True consistent/conservative, False inconsistent
    dr_nees: float | None = None  #: NEES statistic (chi-square over the scored legs)
    dr_nees_lower: float | None = None
    dr_nees_upper: float | None = None
    dr_dominant_source: str | None = None  #: what the 2M is mostly made of where it fails
    dr_dominant_key: str | None = None  #: the [dead_reckoning] key that sets its prior
    duration_s: float | None = None  #: the period the logs cover
    ignored: Mapping[str, int] = field(default_factory=dict)  #: valid unused input, by type
    #: the analysis' integrity checks (dracc.analysis/1 ``integrity.checks``), as dicts
    integrity_checks: tuple[Mapping, ...] = ()
    integrity_false_alarm: float | None = None  #: per-night bound of its statistical checks


#: reject reasons of older documents that were valid input dracc does not use
VALID_UNUSED = ("unsupported", "comment")

#: the words a ``dead_reckoning.verdict`` sentence starts with (dracc.analysis/1)
DR_VERDICTS = ("consistent", "conservative", "inconsistent", "undetermined")


def dr_verdict_word(text) -> str | None:
    """The verdict word of a DR verdict sentence ("inconsistent (circle too small): …" ->
    'inconsistent'); None for anything else."""
    if not isinstance(text, str):
        return None
    head = text.split(":", 1)[0].strip().lower()
    for word in DR_VERDICTS:  # "inconsistent" is not read as "consistent": whole first word
        if head == word or head.startswith(word + " ") or head.startswith(word + "("):
            return word
    return None


def _bool(x) -> bool | None:
    return x if isinstance(x, bool) else None


def _text(x) -> str | None:
    return x if isinstance(x, str) and x.strip() else None


def _sources_by_role(sources) -> dict[str, str]:
    """role -> source key(s), from ``{role: {"keys": [...], "records": n}}`` (dracc.analysis/1);
    ``{role: key}`` and lists of ``{key, roles}`` rows are read too."""
    out: dict[str, str] = {}
    if isinstance(sources, Mapping):
        for role, v in sources.items():
            if isinstance(v, Mapping) and isinstance(v.get("keys"), list):
                out[str(role)] = ",".join(str(k) for k in v["keys"])
            elif isinstance(v, Mapping):
                out[str(role)] = str(v.get("key", ""))
            else:
                out[str(role)] = str(v)
    elif isinstance(sources, list):
        for row in sources:
            if not isinstance(row, Mapping):
                continue
            roles = row.get("roles", row.get("role"))
            roles = [roles] if isinstance(roles, str) else list(roles or [])
            for role in roles:
                out.setdefault(str(role), str(row.get("key", "")))
    return out


def facts_from_analysis(doc: Mapping) -> NightFacts:
    """Read the figures the audit checks from an analysis document (``dracc.analysis/1``)."""
    if not isinstance(doc, Mapping) or not str(doc.get("schema", "")).startswith("dracc.analysis/"):
        raise InsufficientDataError(
            "not a dracc analysis document (schema 'dracc.analysis/…' expected)"
        )
    inputs = doc.get("inputs") or []
    lines = sum(int(i.get("lines") or 0) for i in inputs) if inputs else None
    # damaged lines only: documents written before 'ignored' counted valid unused
    # sentences as the reasons 'unsupported' and 'comment'
    rejected = (
        sum(
            sum(int(n) for r, n in (i.get("rejected") or {}).items() if r not in VALID_UNUSED)
            for i in inputs
        )
        if inputs
        else None
    )
    ignored: dict[str, int] = {}
    for i in inputs:
        for k, n in {
            **(i.get("ignored") or {}),
            **{r: n for r, n in (i.get("rejected") or {}).items() if r in VALID_UNUSED},
        }.items():
            ignored[str(k)] = ignored.get(str(k), 0) + int(n)
    rate = (rejected / lines) if lines else None
    period = doc.get("period") or {}
    channels: list[ChannelRow] = []
    dev = doc.get("deviation") or {}
    for unit, per in sorted((dev.get("units") or {}).items()):
        if not isinstance(per, Mapping):
            continue
        for ch in CHANNELS:
            st = per.get(ch)
            if not isinstance(st, Mapping):
                continue
            channels.append(
                ChannelRow(
                    unit=str(unit),
                    channel=ch,
                    n=int(st.get("n") or 0),
                    m_u=finite_or_none(st.get("m_u")),
                    m_y=finite_or_none(st.get("m_y")),
                    kurtosis=finite_or_none(st.get("kurtosis")),
                    limit_error=finite_or_none(st.get("limit")),
                )
            )
    dr = doc.get("dead_reckoning") or {}
    cal = doc.get("calibration") or {}
    ce, ce_s = _estimate(cal.get("compass_error_deg"))
    ls, ls_s = _estimate(cal.get("log_scale"))
    missing = doc.get("missing") or []
    if not isinstance(dr, Mapping):
        dr = {}
    nees = dr.get("nees")
    nees = nees if isinstance(nees, Mapping) else {}
    verdict_text = _text(dr.get("verdict"))
    integ = doc.get("integrity") if isinstance(doc.get("integrity"), Mapping) else {}
    return NightFacts(
        period_start_utc=period.get("start_utc"),
        period_end_utc=period.get("end_utc"),
        inputs=tuple(str(i.get("path", "")) for i in inputs),
        lines=lines,
        rejected=rejected,
        rejected_rate=rate,
        sources=_sources_by_role(doc.get("sources")),
        channels=tuple(channels),
        dr_containment_2m=finite_or_none(dr.get("containment_2m")),
        dr_n_scored=(
            int(dr["n_scored"]) if finite_or_none(dr.get("n_scored")) is not None else None
        ),
        compass_error_deg=ce,
        compass_error_sigma_deg=ce_s,
        log_scale=ls,
        log_scale_sigma=ls_s,
        missing=tuple(str(m) for m in missing) if isinstance(missing, list) else (str(missing),),
        dr_verdict=dr_verdict_word(verdict_text),
        dr_verdict_text=verdict_text,
        dr_consistent=_bool(dr.get("consistent")),
        dr_nees=finite_or_none(nees.get("statistic")),
        dr_nees_lower=finite_or_none(nees.get("lower")),
        dr_nees_upper=finite_or_none(nees.get("upper")),
        dr_dominant_source=_text(dr.get("dominant_source")),
        dr_dominant_key=_text(dr.get("dominant_key")),
        duration_s=finite_or_none(period.get("duration_s")),
        ignored=ignored,
        integrity_checks=tuple(c for c in integ.get("checks") or [] if isinstance(c, Mapping)),
        integrity_false_alarm=finite_or_none(integ.get("false_alarm_per_night")),
    )


def analyse_voyage(paths: Sequence[Path], cfg: Config, progress=None):
    """Run the pipeline (:func:`dracc.pipeline.analysis.analyse`) over one voyage's logs."""
    from dracc.pipeline import analysis as pipeline

    return pipeline.analyse([Path(p) for p in paths], cfg, progress=progress)


def analysis_document(paths: Sequence[Path], cfg: Config, progress=None) -> dict:
    """Analyse one voyage's logs and return the JSON-ready analysis document."""
    from dracc.report import json_report

    return json_report.to_dict(analyse_voyage(paths, cfg, progress=progress))


# ---------------------------------------------------------------------- findings


#: the clause each audit-level check cites (the integrity checks carry their own)
AUDIT_CLAUSES = {
    "accuracy": "IMO MSC.252(83) 5.3 accuracy; INS deviations from the mean of three (seed 001, "
    "K3b-K8): limiting error at the probability, over the accuracy window",
    "input": "IEC 61162-1: sentences that fail their checksum or structure are damaged input",
    "availability": "IMO MSC.252(83) 5.1.2: availability of the required sources",
    "consistency": "IMO MSC.252(83) 5.4: consistency of the DR and its 2M with the position fixes",
}


@dataclass(frozen=True)
class Finding:
    """One check that failed.  ``value`` and ``limit`` in the unit named by ``measure``;
    ``check`` is the family of the audit document (validity | plausibility | latency |
    availability | consistency | accuracy | input)."""

    kind: str  #: e.g. 'jump', 'dropout', 'limit', 'dr_inconsistent', 'rejected_rate', ...
    subject: str  #: e.g. 'ins2 lon', 'DR', 'compass', 'GNSS'
    value: float | None
    limit: float | None
    measure: str
    message: str
    check: str = "accuracy"
    source: str | None = None
    role: str | None = None
    clause: str = ""
    statistic: Mapping = field(default_factory=dict)  #: {"name", "value", "unit"}
    threshold: Mapping = field(default_factory=dict)  #: {"value", "unit", "rule"}
    window: Mapping = field(default_factory=dict)  #: {"start_utc", "end_utc", ...}
    evidence: tuple = ()
    false_alarm: float | None = None  #: probability per night that a healthy source fails it


def _finding(
    check: str,
    kind: str,
    subject: str,
    value,
    limit,
    measure: str,
    message: str,
    *,
    source=None,
    role=None,
    statistic_name: str = "",
    rule: str = "",
    window=None,
    evidence=(),
    false_alarm=None,
) -> Finding:
    return Finding(
        kind,
        subject,
        value,
        limit,
        measure,
        message,
        check=check,
        source=source,
        role=role,
        clause=AUDIT_CLAUSES.get(check, ""),
        statistic={"name": statistic_name or kind, "value": value, "unit": measure},
        threshold={"value": limit, "unit": measure, "rule": rule},
        window=dict(window or {}),
        evidence=tuple(evidence),
        false_alarm=false_alarm,
    )


def _not_checked(check: str, name: str, why: str, source=None, role=None) -> dict:
    return {"check": check, "name": name, "source": source, "role": role, "why": why}


def _integrity_finding(c: Mapping) -> Finding:
    st = c.get("statistic") or {}
    th = c.get("threshold") or {}
    src = c.get("source")
    return Finding(
        str(c.get("name")),
        str(src or c.get("role") or ""),
        finite_or_none(st.get("value")),
        finite_or_none(th.get("value")),
        str(st.get("unit") or ""),
        str(c.get("message") or ""),
        check=str(c.get("check")),
        source=src,
        role=c.get("role"),
        clause=str(c.get("clause") or ""),
        statistic=dict(st),
        threshold=dict(th),
        window=dict(c.get("window") or {}),
        evidence=tuple(c.get("evidence") or ()),
        false_alarm=finite_or_none(c.get("false_alarm")),
    )


def evaluate(facts: NightFacts, acfg: AuditConfig) -> tuple[tuple[Finding, ...], tuple[dict, ...]]:
    """Check one night: (findings, checks that could not be made, each with why).

    The integrity checks of the analysis (validity, plausibility, latency, availability,
    consistency of every source) are read as they failed; the audit adds the required
    sources, the DR against the fixes, the compass and log calibration against their
    limits and the damaged input.  The limiting errors are judged over the accuracy
    window by :func:`accuracy_findings`, not one night at a time.
    """
    found: list[Finding] = []
    skipped: list[dict] = []
    window = {"start_utc": facts.period_start_utc, "end_utc": facts.period_end_utc}
    for role in acfg.required_sources:
        if role not in facts.sources:
            found.append(
                _finding(
                    "availability",
                    "missing_source",
                    role,
                    None,
                    None,
                    "",
                    f"required source {role} is missing from the logs",
                    role=role,
                    rule="[audit] required_sources",
                    window=window,
                    false_alarm=0.0,
                )
            )
    for c in facts.integrity_checks:
        if c.get("status") == "fail":
            found.append(_integrity_finding(c))
        elif c.get("status") == "not_checked":
            skipped.append(
                _not_checked(
                    str(c.get("check")),
                    str(c.get("name")),
                    str(c.get("why_not") or c.get("message") or ""),
                    c.get("source"),
                    c.get("role"),
                )
            )
    below = (
        facts.dr_containment_2m is not None and facts.dr_containment_2m < acfg.dr_containment_min
    )
    if facts.dr_verdict == "inconsistent":
        # the analysis' own verdict (what `dracc analyze` says); one finding for one cause:
        # a containment below the audit's minimum is said in the same finding
        found.append(_dr_inconsistent(facts, acfg, below))
    elif facts.dr_containment_2m is None:
        skipped.append(_not_checked("consistency", "dr", "no reference position or no DR track"))
    elif below:
        found.append(
            _finding(
                "consistency",
                "dr_containment",
                "DR",
                facts.dr_containment_2m,
                acfg.dr_containment_min,
                "fraction",
                f"DR: reference inside 2M at {100 * facts.dr_containment_2m:.1f} %"
                f" of epochs < {100 * acfg.dr_containment_min:.1f} %",
                statistic_name="containment_2m",
                rule="[audit] dr_containment_min",
                window=window,
            )
        )
    if facts.dr_verdict == "undetermined":
        skipped.append(_not_checked("consistency", "dr", f"DR verdict: {facts.dr_verdict_text}"))
    if facts.compass_error_deg is None:
        skipped.append(
            _not_checked(
                "accuracy",
                "compass_error",
                "compass error not estimated (no heading or no reference)",
                role="compass",
            )
        )
    elif abs(facts.compass_error_deg) > acfg.compass_error_max_deg:
        found.append(
            _finding(
                "accuracy",
                "compass_error",
                "compass",
                facts.compass_error_deg,
                acfg.compass_error_max_deg,
                "deg",
                f"compass error {facts.compass_error_deg:+.2f}° exceeds "
                f"±{acfg.compass_error_max_deg:.2f}°",
                role="compass",
                rule="[audit] compass_error_max_deg",
                window=window,
            )
        )
    if facts.log_scale is None:
        skipped.append(
            _not_checked(
                "accuracy",
                "log_scale",
                "log scale not estimated (no speed log or no reference)",
                role="log",
            )
        )
    elif 100 * abs(facts.log_scale) > acfg.log_scale_max_pct:
        found.append(
            _finding(
                "accuracy",
                "log_scale",
                "log",
                100 * facts.log_scale,
                acfg.log_scale_max_pct,
                "%",
                f"log scale error {100 * facts.log_scale:+.2f} % exceeds "
                f"±{acfg.log_scale_max_pct:.2f} %",
                role="log",
                rule="[audit] log_scale_max_pct",
                window=window,
            )
        )
    if facts.rejected_rate is not None and 100 * facts.rejected_rate > acfg.rejected_rate_max_pct:
        found.append(
            _finding(
                "input",
                "rejected_rate",
                "inputs",
                100 * facts.rejected_rate,
                acfg.rejected_rate_max_pct,
                "%",
                f"{facts.rejected} of {facts.lines} lines damaged "
                f"({100 * facts.rejected_rate:.2f} % > {acfg.rejected_rate_max_pct:.2f} %)",
                rule="[audit] rejected_rate_max_pct: damaged lines (checksum, "
                "truncated, malformed) as % of all lines; valid sentences dracc "
                "does not use are ignored, not rejected",
                window=window,
                false_alarm=0.0,
            )
        )
    return tuple(found), tuple(skipped)


def _dr_inconsistent(facts: NightFacts, acfg: AuditConfig, below: bool) -> Finding:
    """The analysis called the DR inconsistent: its verdict sentence is the message;
    value/limit are the NEES statistic and its upper chi-square bound where given."""
    msg = f"DR: {facts.dr_verdict_text}"
    if facts.dr_dominant_source and facts.dr_dominant_source not in msg:
        key = f" (key [dead_reckoning] {facts.dr_dominant_key})" if facts.dr_dominant_key else ""
        msg += f"; the circle is dominated by {facts.dr_dominant_source}{key}"
    if below:
        msg += (
            f"; {100 * facts.dr_containment_2m:.1f} % inside 2M is below the audit's minimum "
            f"of {100 * acfg.dr_containment_min:.1f} %"
        )
    return _finding(
        "consistency",
        "dr_inconsistent",
        "DR",
        facts.dr_nees,
        facts.dr_nees_upper,
        "NEES" if facts.dr_nees is not None else "",
        msg,
        statistic_name="nees",
        rule="chi-square bounds of the NEES over the scored legs (alpha 0.01)",
        window={"start_utc": facts.period_start_utc, "end_utc": facts.period_end_utc},
        false_alarm=DR_FALSE_ALARM,
    )


#: the NEES test of dracc.math.deadreckoning.dr_consistency: two-sided at alpha = 0.01
DR_FALSE_ALARM = 0.01


# ------------------------------------------------------------------ the accuracy window


@dataclass(frozen=True)
class PooledChannel:
    """One unit channel over the accuracy window: the nights' deviations pooled."""

    unit: str
    channel: str
    nights: tuple[str, ...]
    hours: float
    n: int
    m_u: float
    m_y: float
    kurtosis: float
    n_eff: float
    limit_error: float  #: (K8) K_PIE K_hm m_y over the window
    limit: float | None  #: the configured limit
    measure: str


def _usable(c: ChannelRow) -> bool:
    return c.m_u is not None and math.isfinite(c.m_u) and c.n > 0


def pool_channels(
    nights: Sequence[tuple[str, float, Sequence[ChannelRow]]], dev_cfg
) -> list[PooledChannel]:
    """Pool (night, hours, channel rows) per unit and channel: m_u^2 weighted by n (K3b over
    the union of the nights' deviations), kurtosis weighted by n, independent samples
    summed; the limiting error (K8) from those."""
    from dracc.math.deviation import stats

    acc: dict[tuple[str, str], dict] = {}
    for night, hours, rows in nights:
        for c in rows:
            if not _usable(c):
                continue
            a = acc.setdefault(
                (c.unit, c.channel),
                {
                    "nights": [],
                    "hours": 0.0,
                    "n": 0,
                    "ss": 0.0,
                    "kn": 0.0,
                    "neff": 0.0,
                    "k": None,
                    "measure": c.measure,
                },
            )
            a["nights"].append(night)
            a["hours"] += hours
            a["n"] += c.n
            a["ss"] += c.n * c.m_u**2
            if c.kurtosis is not None and math.isfinite(c.kurtosis):
                a["kn"] += c.n * c.kurtosis
            a["neff"] += float(
                stats.effective_samples(c.n, dev_cfg.interval_s, dev_cfg.correlation_time_s)
            )
            if c.m_y is not None and c.m_u and math.isfinite(c.m_y):
                a["k"] = c.m_y / c.m_u
    out = []
    for (unit, channel), a in sorted(acc.items()):
        m_u = math.sqrt(a["ss"] / a["n"])
        k = a["k"] if a["k"] is not None else stats.K_FIRST_APPROX_THREE
        m_y = k * m_u
        e = a["kn"] / a["n"]
        kp = 1.0 if e <= stats.KURTOSIS_MIN else float(stats.k_pie(dev_cfg.probability, e))
        kh = float(stats.k_hm(dev_cfg.confidence, a["neff"])) if a["neff"] >= 1 else math.nan
        out.append(
            PooledChannel(
                unit,
                channel,
                tuple(a["nights"]),
                a["hours"],
                a["n"],
                m_u,
                m_y,
                e,
                a["neff"],
                kp * kh * m_y,
                None,
                a["measure"],
            )
        )
    return out


def accuracy_findings(
    store: StateStore,
    vessel: str,
    night: str,
    acfg: AuditConfig,
    dev_cfg,
    tonight: tuple[float, Sequence[ChannelRow]] | None = None,
) -> tuple[tuple[Finding, ...], tuple[dict, ...], dict]:
    """The limiting errors over the accuracy window ending with ``night``: the stored
    nights up to it, newest first, until they cover ``accuracy_window_h``.  Findings
    where a pooled limiting error exceeds its limit; not checked while the window is short.
    ``tonight``: (hours, channel rows) of ``night`` not yet stored (it replaces a stored one).
    Returns (findings, not_checked, the window as a JSON-ready dict)."""
    candidates = [
        (r.night, _hours(r), r.channels)
        for r in store.nights(vessel)
        if r.night < night or (r.night == night and tonight is None)
    ]
    if tonight is not None:
        candidates.append((night, float(tonight[0]), tuple(tonight[1])))
    chosen, hours = [], 0.0
    for n, h, rows in sorted(candidates, key=lambda c: c[0], reverse=True):
        if h <= 0 or not any(_usable(c) for c in rows):  # no INS statistics: no hours to add
            continue
        chosen.append((n, h, rows))
        hours += h
        if hours >= acfg.accuracy_window_h:
            break
    doc = {
        "window_h": acfg.accuracy_window_h,
        "hours": hours,
        "nights": [n for n, _, _ in reversed(chosen)],
        "channels": [],
    }
    if not chosen:
        return (
            (),
            (
                _not_checked(
                    "accuracy", "limit", "no INS deviation statistics in the stored nights"
                ),
            ),
            doc,
        )
    pooled = pool_channels(list(reversed(chosen)), dev_cfg)
    found, skipped = [], []
    complete = hours >= acfg.accuracy_window_h
    for p in pooled:
        lim = acfg.limit_for(p.unit, p.channel)
        doc["channels"].append(
            {
                "unit": p.unit,
                "channel": p.channel,
                "measure": p.measure,
                "n": p.n,
                "n_eff": finite_or_none(p.n_eff),
                "m_u": finite_or_none(p.m_u),
                "m_y": finite_or_none(p.m_y),
                "kurtosis": finite_or_none(p.kurtosis),
                "limit_error": finite_or_none(p.limit_error),
                "limit": lim,
            }
        )
        if lim is None:
            continue
        if not complete:
            continue
        if not math.isfinite(p.limit_error):
            skipped.append(
                _not_checked(
                    "accuracy",
                    "limit",
                    f"{p.unit} {p.channel}: no limiting "
                    f"error over the window (N_eff {p.n_eff:.2f})",
                    role=p.unit,
                )
            )
        elif p.limit_error > lim:
            found.append(
                _finding(
                    "accuracy",
                    "limit",
                    f"{p.unit} {p.channel}",
                    p.limit_error,
                    lim,
                    p.measure,
                    f"{p.unit} {p.channel}: limiting error {p.limit_error:.4g} {p.measure} over "
                    f"{hours:.0f} h ({len(p.nights)} nights) > {lim:.4g} {p.measure}",
                    role=p.unit,
                    statistic_name="limiting_error",
                    rule="[audit.limits]: K8 limiting error at the "
                    "configured probability, pooled over the accuracy window",
                    window={"nights": list(p.nights), "hours": p.hours},
                    evidence=(
                        {
                            "m_y": p.m_y,
                            "m_u": p.m_u,
                            "n": p.n,
                            "n_eff": p.n_eff,
                            "kurtosis": p.kurtosis,
                        },
                    ),
                )
            )
    if not complete:
        skipped.append(
            _not_checked(
                "accuracy",
                "limit",
                f"the limiting errors are judged over "
                f"{acfg.accuracy_window_h:g} h of logs; {hours:.1f} h over "
                f"{len(chosen)} night(s) so far ([audit] accuracy_window_h)",
            )
        )
    doc["complete"] = complete
    return tuple(found), tuple(skipped), doc


def _hours(rec: NightRecord) -> float:
    return _period_hours(rec.period_start_utc, rec.period_end_utc)


def _period_hours(start_utc: str | None, end_utc: str | None) -> float:
    if not start_utc or not end_utc:
        return 0.0
    return (parse_utc(end_utc) - parse_utc(start_utc)).total_seconds() / 3600.0


# --------------------------------------------------------------- choosing the logs


_DATE_FORMS = ("%Y-%m-%d", "%Y%m%d", "%Y_%m_%d")


def parse_night(text: str) -> str:
    """Validate ``YYYY-MM-DD``; returns it normalised."""
    try:
        return dt.date.fromisoformat(text).isoformat()
    except ValueError as err:
        raise IngestError(f"--date {text!r}: expected YYYY-MM-DD") from err


def yesterday_utc(now: dt.datetime | None = None) -> str:
    now = now or dt.datetime.now(dt.timezone.utc)
    return (now.date() - dt.timedelta(days=1)).isoformat()


def input_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot be read as a log, or None for a regular file that can be read.

    Decided from ``stat`` alone for everything but a regular file, so nothing that could
    block is opened: opening a FIFO blocks until a writer comes, a device may never end.
    A regular file is opened without blocking (``O_NONBLOCK``), checked to still be a
    regular file and read for one byte.
    """
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            try:
                target = os.readlink(path)
            except OSError:
                target = "?"
            return f"is a dangling symbolic link (to {target}), not a log file"
        return "no such file"
    except OSError as err:  # a symbolic link loop, a folder on the way we may not enter
        return f"cannot read: {err.strerror or err}"
    kind = _not_regular(st.st_mode)
    if kind:
        return kind
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0))
    except OSError as err:
        return f"cannot read: {err.strerror or err}"
    try:
        kind = _not_regular(os.fstat(fd).st_mode)  # swapped for a FIFO since the stat?
        if kind:
            return kind
        os.read(fd, 1)
    except OSError as err:
        return f"cannot read: {err.strerror or err}"
    finally:
        os.close(fd)
    return None


def _not_regular(mode: int) -> str | None:
    """What a file of ``mode`` is, when it is not a regular file (None if it is one)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "is a directory, not a log file"
    what = (
        "a FIFO (named pipe)"
        if stat.S_ISFIFO(mode)
        else "a socket"
        if stat.S_ISSOCK(mode)
        else "a device"
        if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
        else "not a regular file"
    )
    return f"is {what}, not a log file; save the log to a file first"


def outside_link(path: Path, root: Path) -> str | None:
    """If ``path`` (found inside the folder ``root``) leads out of ``root`` through a
    symbolic link (its own, or a linked folder on the way), what it points to; else None.

    A log folder may hold links between its own files; a link to ``/etc/passwd`` or to
    another ship's folder is not followed (its first lines would be copied into the
    report as examples of rejected lines)."""
    real_root = os.path.realpath(root)
    real = os.path.realpath(path)  # never raises, not even on a loop
    if real == real_root or real.startswith(real_root.rstrip(os.sep) + os.sep):
        return None
    return real


@dataclass(frozen=True)
class LogChoice:
    """The logs chosen for a night, and the files of the folders that were left out."""

    paths: tuple[Path, ...]
    #: (path, why) per file matching the pattern that was not taken: a symbolic link
    #: leading out of its folder, a FIFO, socket or device, a dangling link
    skipped: tuple[tuple[Path, str], ...] = ()


def select_logs(inputs: Sequence[Path], night: str | None, pattern: str) -> list[Path]:
    """The log files to audit (see :func:`choose_logs`, which also says what was skipped)."""
    return list(choose_logs(inputs, night, pattern).paths)


def choose_logs(inputs: Sequence[Path], night: str | None, pattern: str) -> LogChoice:
    """The log files to audit.

    A file is taken as given.  In a folder, files matching ``pattern`` (relative glob,
    ``**`` recurses; hidden files skipped) whose path contains ``night`` as
    ``YYYY-MM-DD``, ``YYYYMMDD`` or ``YYYY_MM_DD`` (when a night is given).  Entries of a
    folder that are not regular files (FIFOs, sockets, devices, dangling links) and
    symbolic links that lead out of the folder are skipped, each with why, in
    ``skipped``; a folder entry is never opened before it is known to be a regular file.
    """
    forms = []
    if night is not None:
        d = dt.date.fromisoformat(night)
        forms = [d.strftime(f) for f in _DATE_FORMS]
    chosen: list[Path] = []
    skipped: list[tuple[Path, str]] = []
    for p in inputs:
        p = Path(p)
        if p.is_file():
            chosen.append(p)
        elif p.is_dir():
            found = []
            left_out = []
            for f in sorted(p.glob(pattern)):
                rel = f.relative_to(p)
                if any(part.startswith(".") for part in rel.parts):
                    continue
                if forms and not any(form in str(rel) for form in forms):
                    continue
                target = outside_link(f, p)
                if target is not None:
                    left_out.append(
                        (f, f"symbolic link to {target}, outside the folder {p}: not followed")
                    )
                    continue
                if f.is_dir():
                    continue
                problem = input_problem(f) if not f.is_file() else None
                if problem:
                    left_out.append((f, problem))
                    continue
                found.append(f)
            skipped.extend(left_out)
            if not found:
                what = f" for {night}" if night else ""
                also = (
                    (
                        f" ({len(left_out)} skipped: "
                        + "; ".join(f"{f.relative_to(p)}: {why}" for f, why in left_out[:3])
                        + ("; ..." if len(left_out) > 3 else "")
                        + ")"
                    )
                    if left_out
                    else ""
                )
                raise NoLogsError(f"no logs{what} matching {pattern!r} in {p}{also}")
            chosen.extend(found)
        elif os.path.lexists(p):  # a FIFO, a socket, a device, a dangling link
            raise IngestError(f"{p}: {input_problem(p) or 'not a log file'}")
        else:
            raise IngestError(f"{p}: no such file or folder")
    unique = list(dict.fromkeys(c.resolve() for c in chosen))
    if not unique:
        raise IngestError("no log files given")
    return LogChoice(tuple(unique), tuple(skipped))


def content_sha256(paths: Sequence[Path]) -> str:
    """SHA-256 over the sorted SHA-256 digests of the files: independent of names and order."""
    digests = sorted(file_sha256(p) for p in paths)
    return hashlib.sha256("\n".join(digests).encode()).hexdigest()


def file_sha256(path: Path, chunk: int = 1 << 20) -> str:
    """SHA-256 of a regular file's bytes.  Opened without blocking and checked to be a
    regular file first: a FIFO put in a log's place raises IngestError, never hangs."""
    h = hashlib.sha256()
    try:
        fd = os.open(
            os.fspath(path), os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0)
        )
    except OSError as err:
        raise IngestError(f"{path}: cannot read: {err.strerror or err}") from err
    try:
        kind = _not_regular(os.fstat(fd).st_mode)
        if kind:
            raise IngestError(f"{path}: {kind}")
        with os.fdopen(fd, "rb", closefd=False) as fh:
            while block := fh.read(chunk):
                h.update(block)
    except OSError as err:
        raise IngestError(f"{path}: cannot read: {err.strerror or err}") from err
    finally:
        os.close(fd)
    return h.hexdigest()


def night_of(facts: NightFacts) -> str:
    """The night a log belongs to when no --date is given: the UTC date of the period's middle."""
    if not facts.period_start_utc or not facts.period_end_utc:
        raise InsufficientDataError("the logs carry no dated records; give the night with --date")
    t0 = parse_utc(facts.period_start_utc)
    t1 = parse_utc(facts.period_end_utc)
    return (t0 + (t1 - t0) / 2).date().isoformat()


# -------------------------------------------------------------------- the audit


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

    @property
    def verdict(self) -> str:
        """'no data', 'findings' or 'ok'."""
        return "no data" if self.no_data else ("findings" if self.findings else "ok")

    @property
    def exit_code(self) -> ExitCode:
        if self.no_data:
            return ExitCode.INPUT
        return ExitCode.FINDINGS if self.findings else ExitCode.OK


def audit_document(
    doc: Mapping,
    *,
    store: StateStore,
    acfg: AuditConfig,
    seeds: Mapping[tuple[str, str], float],
    vessel: str,
    night: str | None,
    content_hash: str,
    settings_hash: str,
    now: Callable[[], dt.datetime] | None = None,
    dev_cfg=None,
) -> AuditOutcome:
    """Audit one night given its analysis document, and record it in ``store``.

    Idempotent on (vessel, night, content hash, settings hash): the same night with the
    same content is recorded once (``status='unchanged'``, nothing written); a night
    whose content changed replaces the stored one in the same transaction
    (``'replaced'``).  The a priori chain of the vessel is recomputed in that transaction.
    """
    from dracc.core.config import DeviationConfig

    dev_cfg = dev_cfg or DeviationConfig()
    facts = facts_from_analysis(doc)
    night = night or night_of(facts)
    findings, not_checked = evaluate(facts, acfg)
    clock = now or (lambda: dt.datetime.now(dt.timezone.utc))
    # the hours tonight adds to the accuracy window: as a stored night is counted (its
    # period), from the period where the document gives no duration
    hours = (
        facts.duration_s / 3600.0
        if facts.duration_s is not None
        else _period_hours(facts.period_start_utc, facts.period_end_utc)
    )
    with store.transaction():
        acc_found, acc_skipped, acc_doc = accuracy_findings(
            store, vessel, night, acfg, dev_cfg, tonight=(hours, facts.channels)
        )
        findings += acc_found
        not_checked += acc_skipped
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
                    _finding(
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
    return AuditOutcome(
        stored,
        findings + tuple(extra),
        not_checked,
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
    f = _finding(
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
                row = next(
                    c
                    for c in store.night(vessel, step.night).channels
                    if c.unit == unit and c.channel == channel
                )
                events.append(
                    AprioriEvent(
                        vessel,
                        unit,
                        channel,
                        step.night,
                        float(step.after),
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


def vessel_name(cfg: Config, acfg: AuditConfig, option: str | None) -> str:
    """--vessel, else [audit] vessel, else [vessel] name, else 'default'."""
    if option:
        return option
    if acfg.vessel:
        return acfg.vessel
    v = cfg.extra.get("vessel", {})
    if not isinstance(v, dict):
        raise ConfigError(f"[vessel] must be a table, got {type(v).__name__}")
    _unknown(v, ("name",), "vessel")
    if "name" in v:
        if not isinstance(v["name"], str) or not v["name"].strip():
            raise ConfigError(f"[vessel] name must be a non-empty string, got {v['name']!r}")
        return v["name"]
    return "default"


def run_audit(
    inputs: Sequence[Path],
    cfg: Config,
    *,
    db: str | Path | None = None,
    vessel: str | None = None,
    night: str | None = None,
    pattern: str | None = None,
    progress=None,
    now: dt.datetime | None = None,
):
    """The whole nightly audit: choose the logs, analyse them, check, record.

    Returns ``(outcome, analysis)``, the analysis for the reports (None for a night
    without logs: a folder holding no log for the night is recorded as a night without
    data, ``outcome.no_data``, exit 3).  Raises IngestError/InsufficientDataError (exit 3)
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
        return outcome, None
    paths = list(choice.paths)
    content_hash = content_sha256(paths)
    analysis = analyse_voyage(paths, cfg, progress=progress)
    from dracc.report import json_report

    doc = json_report.to_dict(analysis)
    with StateStore(db_path, busy_timeout_s=acfg.busy_timeout_s) as store:
        outcome = audit_document(
            doc,
            store=store,
            acfg=acfg,
            seeds=seeds,
            vessel=name,
            night=night,
            content_hash=content_hash,
            settings_hash=settings_sha256(cfg),
            dev_cfg=cfg.deviation,
        )
    if choice.skipped:  # files of the folder not read: said in the summary and the JSON
        outcome = replace(
            outcome,
            not_checked=outcome.not_checked
            + tuple(_not_checked("logs", str(f), why) for f, why in choice.skipped),
        )
    return outcome, analysis
