"""The nightly shipboard audit: thresholds, the a priori rule, findings.

``dracc audit`` runs after midnight over the last day's logs, analyses them with
:func:`dracc.pipeline.analyse`, checks the results against the limits in the
``[audit]`` section of the configuration and keeps the state between nights in SQLite
(:mod:`dracc.state`).

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
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .config import Config
from .errors import ConfigError, ExitCode, IngestError, InsufficientDataError
from .state import AprioriEvent, ChannelRow, NightRecord, StateStore

UNITS = ("ins1", "ins2", "ins3")
CHANNELS = ("lat", "lon", "course")
#: the config key of each channel's value (a priori and limits), with its unit
CHANNEL_KEYS = {"lat": "lat_m", "lon": "lon_m", "course": "course_deg"}
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
    limits: Mapping[str, Mapping[str, float]] = field(default_factory=lambda: {
        "all": {"lat_m": 1852.0, "lon_m": 1852.0, "course_deg": 0.75}})
    dr_containment_min: float = 0.90  #: fraction of DR epochs with the reference inside 2M
    compass_error_max_deg: float = 1.0  #: |compass error| estimated against the reference
    log_scale_max_pct: float = 2.0  #: |log scale error|, % of speed (IMO: 2 %)
    rejected_rate_max_pct: float = 1.0  #: rejected lines, % of all lines
    required_sources: tuple[str, ...] = UNITS  #: roles that must be present in the logs
    apriori_raise_is_finding: bool = False  #: a raised a priori value is a finding (exit 1)

    def limit_for(self, unit: str, channel: str) -> float | None:
        key = CHANNEL_KEYS[channel]
        own = self.limits.get(unit, {})
        if key in own:
            return float(own[key])
        value = self.limits.get("all", {}).get(key)
        return None if value is None else float(value)


_ROLES = ("compass", "log", "ins1", "ins2", "ins3", "gnss")


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
        raise ConfigError(f"[{where}] unknown key(s): {', '.join(sorted(map(str, unknown)))}; "
                          f"known: {', '.join(sorted(known))}")


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
    for key in ("busy_timeout_s", "compass_error_max_deg", "log_scale_max_pct",
                "rejected_rate_max_pct"):
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
        if not isinstance(req, list) or any(r not in _ROLES for r in req):
            raise ConfigError(f"[audit.required_sources] must be a list of roles "
                              f"({', '.join(_ROLES)}), got {req!r}")
        kw["required_sources"] = tuple(req)
    if "limits" in table:
        lim = table["limits"]
        if not isinstance(lim, dict):
            raise ConfigError("[audit.limits] must be a table: unit or \"all\" -> "
                              "{ lat_m, lon_m, course_deg }")
        _unknown(lim, ("all",) + UNITS, "audit.limits")
        merged = {k: dict(v) for k, v in default.limits.items()}
        for unit, values in lim.items():
            if not isinstance(values, dict):
                raise ConfigError(f"[audit.limits.{unit}] must be a table {{ lat_m, lon_m, course_deg }}")
            _unknown(values, CHANNEL_KEYS.values(), f"audit.limits.{unit}")
            merged.setdefault(unit, {}).update(
                {k: _number(v, f"audit.limits.{unit}.{k}") for k, v in values.items()})
        kw["limits"] = merged
    return AuditConfig(**kw)


def apriori_seeds(cfg: Config) -> dict[tuple[str, str], float]:
    """The configured a priori RMS per (unit, channel) from ``[deviation.apriori]``."""
    seeds: dict[tuple[str, str], float] = {}
    for unit, values in cfg.deviation.apriori.items():
        if unit not in UNITS or not isinstance(values, dict):
            raise ConfigError(f"[deviation.apriori] {unit!r}: expected one of {', '.join(UNITS)} "
                              "= { lat_m, lon_m, course_deg }")
        _unknown(values, CHANNEL_KEYS.values(), f"deviation.apriori.{unit}")
        for key, v in values.items():
            seeds[(unit, KEY_CHANNELS[key])] = _number(v, f"deviation.apriori.{unit}.{key}")
    return seeds


def settings_sha256(cfg: Config) -> str:
    """SHA-256 of the settings that shape an analysis (ingest, dead reckoning, deviation)."""
    doc = {"ingest": asdict(cfg.ingest), "dead_reckoning": asdict(cfg.dead_reckoning),
           "deviation": asdict(cfg.deviation)}
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
            steps.append(RuleStep(night, m_y, current, m_y, "raised"))  # the larger becomes a priori
            current = m_y
        else:
            steps.append(RuleStep(night, m_y, current, current, "within"))
    return steps


# --------------------------------------------------------------------- the analysis


def _num(x) -> float | None:
    """A finite float, or None for null/NaN/absent."""
    if x is None or isinstance(x, bool):
        return None
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _estimate(x) -> tuple[float | None, float | None]:
    """(value, sigma) from ``{"value": …, "sigma": …}`` or a bare number."""
    if isinstance(x, Mapping):
        return _num(x.get("value")), _num(x.get("sigma"))
    return _num(x), None


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
        raise InsufficientDataError("not a dracc analysis document (schema 'dracc.analysis/…' expected)")
    inputs = doc.get("inputs") or []
    lines = sum(int(i.get("lines") or 0) for i in inputs) if inputs else None
    rejected = sum(sum(int(n) for n in (i.get("rejected") or {}).values()) for i in inputs) if inputs else None
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
            channels.append(ChannelRow(unit=str(unit), channel=ch, n=int(st.get("n") or 0),
                                       m_u=_num(st.get("m_u")), m_y=_num(st.get("m_y")),
                                       kurtosis=_num(st.get("kurtosis")),
                                       limit_error=_num(st.get("limit"))))
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
    return NightFacts(
        period_start_utc=period.get("start_utc"), period_end_utc=period.get("end_utc"),
        inputs=tuple(str(i.get("path", "")) for i in inputs), lines=lines, rejected=rejected,
        rejected_rate=rate, sources=_sources_by_role(doc.get("sources")),
        channels=tuple(channels), dr_containment_2m=_num(dr.get("containment_2m")),
        dr_n_scored=(int(dr["n_scored"]) if _num(dr.get("n_scored")) is not None else None),
        compass_error_deg=ce, compass_error_sigma_deg=ce_s, log_scale=ls, log_scale_sigma=ls_s,
        missing=tuple(str(m) for m in missing) if isinstance(missing, list) else (str(missing),),
        dr_verdict=dr_verdict_word(verdict_text), dr_verdict_text=verdict_text,
        dr_consistent=_bool(dr.get("consistent")), dr_nees=_num(nees.get("statistic")),
        dr_nees_lower=_num(nees.get("lower")), dr_nees_upper=_num(nees.get("upper")),
        dr_dominant_source=_text(dr.get("dominant_source")),
        dr_dominant_key=_text(dr.get("dominant_key")))


def analyse_voyage(paths: Sequence[Path], cfg: Config, progress=None):
    """Run the pipeline (:func:`dracc.pipeline.analyse`) over one voyage's logs."""
    from . import pipeline

    return pipeline.analyse([Path(p) for p in paths], cfg, progress=progress)


def analysis_document(paths: Sequence[Path], cfg: Config, progress=None) -> dict:
    """Analyse one voyage's logs and return the JSON-ready analysis document."""
    from .report import json_report

    return json_report.to_dict(analyse_voyage(paths, cfg, progress=progress))


# ---------------------------------------------------------------------- findings


@dataclass(frozen=True)
class Finding:
    """One value outside its limit.  ``value`` and ``limit`` in the unit named by ``measure``."""

    kind: str  #: 'limit', 'dr_inconsistent', 'dr_containment', 'compass_error', 'log_scale',
    #: 'rejected_rate', 'missing_source', 'apriori_raised'
    subject: str  #: e.g. 'ins2 lon', 'DR', 'compass', 'log', 'inputs', 'gnss'
    value: float | None
    limit: float | None
    measure: str
    message: str


def evaluate(facts: NightFacts, acfg: AuditConfig) -> tuple[tuple[Finding, ...], tuple[str, ...]]:
    """Check one night against the limits: (findings, checks that could not be made)."""
    found: list[Finding] = []
    skipped: list[str] = []
    for role in acfg.required_sources:
        if role not in facts.sources:
            found.append(Finding("missing_source", role, None, None, "",
                                 f"required source {role} is missing from the logs"))
    for c in facts.channels:
        lim = acfg.limit_for(c.unit, c.channel)
        if lim is None:
            continue
        if c.limit_error is None:
            skipped.append(f"{c.unit} {c.channel}: no limiting error (n = {c.n})")
        elif c.limit_error > lim:
            found.append(Finding("limit", f"{c.unit} {c.channel}", c.limit_error, lim, c.measure,
                                 f"{c.unit} {c.channel}: limiting error {c.limit_error:.4g} {c.measure}"
                                 f" > {lim:.4g} {c.measure}"))
    below = (facts.dr_containment_2m is not None
             and facts.dr_containment_2m < acfg.dr_containment_min)
    if facts.dr_verdict == "inconsistent":
        # the analysis' own verdict (what `dracc analyze` says); one finding for one cause:
        # a containment below the audit's minimum is said in the same finding
        found.append(_dr_inconsistent(facts, acfg, below))
    elif facts.dr_containment_2m is None:
        skipped.append("DR consistency: no reference position or no DR track")
    elif below:
        found.append(Finding("dr_containment", "DR", facts.dr_containment_2m, acfg.dr_containment_min,
                             "fraction", f"DR: reference inside 2M at {100 * facts.dr_containment_2m:.1f} %"
                             f" of epochs < {100 * acfg.dr_containment_min:.1f} %"))
    if facts.dr_verdict == "undetermined":
        skipped.append(f"DR verdict: {facts.dr_verdict_text}")
    if facts.compass_error_deg is None:
        skipped.append("compass error: not estimated (no heading or no reference)")
    elif abs(facts.compass_error_deg) > acfg.compass_error_max_deg:
        found.append(Finding("compass_error", "compass", facts.compass_error_deg,
                             acfg.compass_error_max_deg, "deg",
                             f"compass error {facts.compass_error_deg:+.2f}° exceeds "
                             f"±{acfg.compass_error_max_deg:.2f}°"))
    if facts.log_scale is None:
        skipped.append("log scale: not estimated (no speed log or no reference)")
    elif 100 * abs(facts.log_scale) > acfg.log_scale_max_pct:
        found.append(Finding("log_scale", "log", 100 * facts.log_scale, acfg.log_scale_max_pct, "%",
                             f"log scale error {100 * facts.log_scale:+.2f} % exceeds "
                             f"±{acfg.log_scale_max_pct:.2f} %"))
    if facts.rejected_rate is not None and 100 * facts.rejected_rate > acfg.rejected_rate_max_pct:
        found.append(Finding("rejected_rate", "inputs", 100 * facts.rejected_rate,
                             acfg.rejected_rate_max_pct, "%",
                             f"{facts.rejected} of {facts.lines} lines rejected "
                             f"({100 * facts.rejected_rate:.2f} % > {acfg.rejected_rate_max_pct:.2f} %)"))
    return tuple(found), tuple(skipped)


def _dr_inconsistent(facts: NightFacts, acfg: AuditConfig, below: bool) -> Finding:
    """The analysis called the DR inconsistent: its verdict sentence is the message;
    value/limit are the NEES statistic and its upper chi-square bound where given."""
    msg = f"DR: {facts.dr_verdict_text}"
    if facts.dr_dominant_source and facts.dr_dominant_source not in msg:
        key = f" (key [dead_reckoning] {facts.dr_dominant_key})" if facts.dr_dominant_key else ""
        msg += f"; the circle is dominated by {facts.dr_dominant_source}{key}"
    if below:
        msg += (f"; {100 * facts.dr_containment_2m:.1f} % inside 2M is below the audit's minimum "
                f"of {100 * acfg.dr_containment_min:.1f} %")
    return Finding("dr_inconsistent", "DR", facts.dr_nees, facts.dr_nees_upper,
                   "NEES" if facts.dr_nees is not None else "", msg)


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


def select_logs(inputs: Sequence[Path], night: str | None, pattern: str) -> list[Path]:
    """The log files to audit.

    A file is taken as given.  In a folder, files matching ``pattern`` (relative glob,
    ``**`` recurses; hidden files skipped) whose path contains ``night`` as
    ``YYYY-MM-DD``, ``YYYYMMDD`` or ``YYYY_MM_DD`` (when a night is given).
    """
    forms = []
    if night is not None:
        d = dt.date.fromisoformat(night)
        forms = [d.strftime(f) for f in _DATE_FORMS]
    chosen: list[Path] = []
    for p in inputs:
        p = Path(p)
        if p.is_file():
            chosen.append(p)
        elif p.is_dir():
            found = []
            for f in sorted(p.glob(pattern)):
                rel = f.relative_to(p)
                if not f.is_file() or any(part.startswith(".") for part in rel.parts):
                    continue
                if forms and not any(form in str(rel) for form in forms):
                    continue
                found.append(f)
            if not found:
                what = f" for {night}" if night else ""
                raise IngestError(f"{p}: no log files{what} matching {pattern!r}")
            chosen.extend(found)
        else:
            raise IngestError(f"{p}: no such file or folder")
    unique = list(dict.fromkeys(c.resolve() for c in chosen))
    if not unique:
        raise IngestError("no log files given")
    return unique


def content_sha256(paths: Sequence[Path]) -> str:
    """SHA-256 over the sorted SHA-256 digests of the files: independent of names and order."""
    digests = sorted(file_sha256(p) for p in paths)
    return hashlib.sha256("\n".join(digests).encode()).hexdigest()


def file_sha256(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            while block := fh.read(chunk):
                h.update(block)
    except OSError as err:
        raise IngestError(f"{path}: cannot read: {err.strerror or err}") from err
    return h.hexdigest()


def night_of(facts: NightFacts) -> str:
    """The night a log belongs to when no --date is given: the UTC date of the period's middle."""
    if not facts.period_start_utc or not facts.period_end_utc:
        raise InsufficientDataError("the logs carry no dated records; give the night with --date")
    t0 = _parse_utc(facts.period_start_utc)
    t1 = _parse_utc(facts.period_end_utc)
    return (t0 + (t1 - t0) / 2).date().isoformat()


def _parse_utc(text: str) -> dt.datetime:
    t = dt.datetime.fromisoformat(text.replace("Z", "+00:00"))
    return t if t.tzinfo else t.replace(tzinfo=dt.timezone.utc)


# -------------------------------------------------------------------- the audit


@dataclass(frozen=True)
class AuditOutcome:
    """The result of auditing one night."""

    record: NightRecord  #: as stored (with the a priori verdicts of this night)
    findings: tuple[Finding, ...]
    not_checked: tuple[str, ...]
    status: str  #: 'recorded' (new night), 'unchanged' (same content: nothing written), 'replaced'
    apriori_events: tuple[AprioriEvent, ...]  #: established or raised on this night

    @property
    def exit_code(self) -> ExitCode:
        return ExitCode.FINDINGS if self.findings else ExitCode.OK


def audit_document(doc: Mapping, *, store: StateStore, acfg: AuditConfig,
                   seeds: Mapping[tuple[str, str], float], vessel: str, night: str | None,
                   content_hash: str, settings_hash: str,
                   now: Callable[[], dt.datetime] | None = None) -> AuditOutcome:
    """Audit one night given its analysis document, and record it in ``store``.

    Idempotent on (vessel, night, content hash, settings hash): the same night with the
    same content is recorded once (``status='unchanged'``, nothing written); a night
    whose content changed replaces the stored one in the same transaction
    (``'replaced'``).  The a priori chain of the vessel is recomputed in that transaction.
    """
    facts = facts_from_analysis(doc)
    night = night or night_of(facts)
    findings, not_checked = evaluate(facts, acfg)
    clock = now or (lambda: dt.datetime.now(dt.timezone.utc))
    record = NightRecord(
        vessel=vessel, night=night, content_sha256=content_hash, settings_sha256=settings_hash,
        audited_utc=clock().strftime("%Y-%m-%dT%H:%M:%SZ"),
        period_start_utc=facts.period_start_utc, period_end_utc=facts.period_end_utc,
        inputs=facts.inputs, sources=facts.sources, lines=facts.lines, rejected=facts.rejected,
        rejected_rate=facts.rejected_rate, dr_containment_2m=facts.dr_containment_2m,
        dr_n_scored=facts.dr_n_scored, compass_error_deg=facts.compass_error_deg,
        compass_error_sigma_deg=facts.compass_error_sigma_deg, log_scale=facts.log_scale,
        log_scale_sigma=facts.log_scale_sigma, findings=tuple(asdict(f) for f in findings),
        missing=facts.missing, channels=facts.channels, dr_verdict=facts.dr_verdict,
        dr_verdict_text=facts.dr_verdict_text, dr_consistent=facts.dr_consistent,
        dr_nees=facts.dr_nees)
    with store.transaction():
        old = store.night(vessel, night)
        if (old is not None and old.content_sha256 == content_hash
                and old.settings_sha256 == settings_hash):
            status = "unchanged"
        else:
            status = "replaced" if old is not None else "recorded"
            store.delete_night(vessel, night)
            store.insert_night(record)
            _recompute_chain(store, vessel, seeds)
            sleep_s = os.environ.get(TEST_SLEEP_ENV)
            if sleep_s:  # test hook: a run killed here must leave no partial night
                print(f"dracc audit: test hook: sleeping {sleep_s} s inside the transaction",
                      file=sys.stderr, flush=True)
                time.sleep(float(sleep_s))
        stored = store.night(vessel, night)
        events = tuple(e for e in store.apriori_events(vessel) if e.night == night)
    assert stored is not None
    extra = []
    if acfg.apriori_raise_is_finding:
        for e in events:
            if e.reason == "raised":
                measure = CHANNEL_KEYS[e.channel].rsplit("_", 1)[1]
                extra.append(Finding("apriori_raised", f"{e.unit} {e.channel}", e.value, e.previous,
                                     measure, f"{e.unit} {e.channel}: a priori RMS raised from "
                                     f"{e.previous:.4g} to {e.value:.4g} {measure}"))
    return AuditOutcome(stored, findings + tuple(extra), not_checked, status, events)


def _recompute_chain(store: StateStore, vessel: str, seeds: Mapping[tuple[str, str], float]) -> None:
    """Re-apply the monitoring rule over every stored night of ``vessel`` (in the transaction)."""
    series: dict[tuple[str, str], list[tuple[str, float | None]]] = {}
    for rec in store.nights(vessel):
        for c in rec.channels:
            series.setdefault((c.unit, c.channel), []).append((rec.night, c.m_y))
    events = []
    for (unit, channel), nights in sorted(series.items()):
        rec_by_night = dict(nights)
        for step in apriori_chain(seeds.get((unit, channel)), nights):
            store.set_channel_apriori(vessel, step.night, unit, channel, step.before, step.after,
                                      step.verdict)
            if step.verdict in ("established", "raised"):
                row = next(c for c in store.night(vessel, step.night).channels
                           if c.unit == unit and c.channel == channel)
                events.append(AprioriEvent(
                    vessel, unit, channel, step.night, float(step.after), step.before, step.verdict,
                    {"night": step.night, "m_y": rec_by_night[step.night], "m_u": row.m_u,
                     "n": row.n, "kurtosis": row.kurtosis, "limit": row.limit_error,
                     "previous": step.before,
                     "seed": "config" if (unit, channel) in seeds else None}))
    store.replace_apriori_events(vessel, events)


def vessel_name(cfg: Config, acfg: AuditConfig, option: str | None) -> str:
    """--vessel, else [audit] vessel, else [vessel] name, else 'default'."""
    if option:
        return option
    if acfg.vessel:
        return acfg.vessel
    v = cfg.extra.get("vessel")
    if isinstance(v, dict) and isinstance(v.get("name"), str) and v["name"].strip():
        return v["name"]
    return "default"


def run_audit(inputs: Sequence[Path], cfg: Config, *, db: str | Path | None = None,
              vessel: str | None = None, night: str | None = None, pattern: str | None = None,
              progress=None, now: dt.datetime | None = None):
    """The whole nightly audit: choose the logs, analyse them, check, record.

    Returns ``(outcome, analysis)``, the analysis for the JSON and HTML reports.
    Raises IngestError/InsufficientDataError (exit 3) when no usable logs are found and
    ConfigError (exit 4) for a bad ``[audit]`` section or no database path.  Without
    ``night`` and with a folder among the inputs, the night is
    yesterday (UTC): cron runs the audit after midnight.
    """
    acfg = audit_config(cfg)
    seeds = apriori_seeds(cfg)
    db_path = db or acfg.db
    if not db_path:
        raise ConfigError("no audit database: give --db PATH or [audit] db = \"PATH\"")
    has_dir = any(Path(p).is_dir() for p in inputs)
    if night is not None:
        night = parse_night(night)
    elif has_dir:
        night = yesterday_utc(now)
    paths = select_logs(inputs, night, pattern or acfg.pattern)
    content_hash = content_sha256(paths)
    analysis = analyse_voyage(paths, cfg, progress=progress)
    from .report import json_report

    doc = json_report.to_dict(analysis)
    with StateStore(db_path, busy_timeout_s=acfg.busy_timeout_s) as store:
        outcome = audit_document(doc, store=store, acfg=acfg, seeds=seeds,
                                 vessel=vessel_name(cfg, acfg, vessel), night=night,
                                 content_hash=content_hash, settings_hash=settings_sha256(cfg))
    return outcome, analysis
